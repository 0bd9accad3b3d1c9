"""Points of a task lost with its workers are rerun alone: one by one for a small task, in groups for a large one.

A sweep's task may hold up to 2048 cheap points (sweep.BatchSizer). Rerunning each of them alone, one task at
a time, would cost a scheduler round trip each, so a task of more than RERUN_GROUP points is rerun in groups
first and only a group lost again is rerun point by point. Only a single point lost while alone is blamed.
The end-to-end test uses real LocalCluster worker processes killed by a real point (tests/helpers/units_for_cluster.py).
"""

from __future__ import annotations

from concurrent.futures import CancelledError

from distributed import KilledWorker

import cosim
from cosim.parallel.reruns import RERUN_GROUP, Reruns
from tests.parallel.test_lost_workers import square_spec


def killed() -> KilledWorker:
    return KilledWorker("task", "tcp://127.0.0.1:1", 1)


def test_a_small_lost_task_is_rerun_point_by_point():
    reruns = Reruns()
    assert reruns.after_failure(list(range(RERUN_GROUP)), killed(), alone=False)
    assert list(reruns.suspects) == [[i] for i in range(RERUN_GROUP)]


def test_a_large_lost_task_is_rerun_in_groups_and_a_group_lost_alone_point_by_point():
    reruns = Reruns(group=4)
    assert reruns.after_failure(list(range(10)), CancelledError(), alone=False)
    assert list(reruns.suspects) == [[0, 1, 2, 3], [4, 5, 6, 7], [8, 9]]
    group = reruns.suspects.popleft()
    assert reruns.after_failure(group, killed(), alone=True)  # the group holds a killer: find it
    assert list(reruns.suspects) == [[4, 5, 6, 7], [8, 9], [0], [1], [2], [3]]


def test_only_a_single_point_lost_alone_is_blamed_and_other_errors_are_rows():
    reruns = Reruns()
    assert not reruns.after_failure([7], killed(), alone=True)
    assert not reruns.after_failure([1, 2], ValueError("unpicklable"), alone=False)
    assert not reruns.suspects


def test_a_killer_in_a_task_of_many_points_is_crashed_and_the_others_are_ok(write_spec, worker_processes):
    n = 2 * RERUN_GROUP + 2  # one task of three groups
    df = cosim.sweep(str(write_spec(square_spec(n, 0.0, kill_at=70.0))), scheduler=worker_processes,
                            batch_size=n, quiet=True)
    assert len(df) == n and df["point_id"].is_unique
    killer = df[df["sq.x"] == 70.0].iloc[0]
    assert killer["status"] == "crashed"
    assert "also while it ran alone" in killer["message"]
    innocent = df[df["sq.x"] != 70.0]
    assert (innocent["status"] == "ok").all(), innocent[["status", "message"]]
    assert (innocent["y_end"] == innocent["sq.x"] ** 2).all()
