"""Lost workers cost nothing: a Dask worker process killed mid-sweep (kill -9, as the OOM killer or a lost node
would) loses no point and gives no innocent point a wrong status; a point that kills its workers is `crashed`.

Real LocalCluster worker processes (a cluster of worker processes whose scheduler allows one failure, as the
clusters cosim starts do: sweep_fixtures.worker_processes; cosim's own local cluster runs its workers inside the
client) and a real SIGKILL; the units are tests/helpers/units_for_cluster.py.
"""

from __future__ import annotations

import os
import signal
import threading
import time

import pytest

import cosim
from tests.helpers.paths import HELPERS
from tests.helpers.sweep_fixtures import worker_process_cluster

UNIT = f"{HELPERS / 'units_for_cluster.py'}:SlowSquare"


def square_spec(n: int, delay: float, kill_at: float = -1.0) -> dict:
    return {
        "name": "lost_workers",
        "units": {"sq": {"python": UNIT, "parameters": {"delay": delay, "kill_at": kill_at}}},
        "experiment": {"stop": 0.5, "step": 0.1},
        "objectives": {"y_end": {"signal": "sq.y", "reduce": "final"}},
        "design": {"parameters": {"sq.x": {"values": [float(i) for i in range(n)]}}},
    }


def test_kill_9_of_a_worker_mid_sweep_loses_nothing(write_spec, tmp_path, monkeypatch):
    markers = tmp_path / "markers"
    markers.mkdir()
    monkeypatch.setenv("SLOW_SQUARE_MARKERS", str(markers))
    killed: list[int] = []

    def kill_a_busy_worker() -> None:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            busy = list(markers.iterdir())
            if busy:  # a point is running on this worker right now (its step wrote the marker)
                pid = int(busy[0].name)
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
                return
            time.sleep(0.05)

    killer = threading.Thread(target=kill_a_busy_worker, daemon=True)
    killer.start()
    # 5 steps of 0.1 s: each point runs 0.5 s, so the kill lands inside a batch of 3 points
    with worker_process_cluster() as address:  # started now: its workers see SLOW_SQUARE_MARKERS
        df = cosim.sweep(str(write_spec(square_spec(8, 0.1))), scheduler=address, batch_size=3, quiet=True)
    killer.join(timeout=5)
    assert len(killed) == 1
    with pytest.raises(ProcessLookupError):
        os.kill(killed[0], 0)  # the worker really died
    assert len(df) == 8 and df["point_id"].is_unique  # rows in = rows out
    assert (df["status"] == "ok").all(), df[["status", "message"]]
    assert (df["y_end"] == df["sq.x"] ** 2).all()


@pytest.mark.parametrize("batch_size", [3, 1])
def test_a_point_that_kills_its_workers_is_crashed_and_the_others_are_ok(write_spec, batch_size, worker_processes):
    # Dask counts a worker's death against every task queued on it, not only the one running: innocent tasks
    # waiting behind the killer were crashed in about half the runs before points were blamed only when alone.
    df = cosim.sweep(str(write_spec(square_spec(6, 0.0, kill_at=3.0))), scheduler=worker_processes,
                            batch_size=batch_size, quiet=True)
    assert len(df) == 6 and df["point_id"].is_unique
    killer = df[df["sq.x"] == 3.0].iloc[0]
    assert killer["status"] == "crashed"
    assert "every Dask worker process that ran this point died, also while it ran alone" in killer["message"]
    assert "KilledWorker" in killer["message"] or "workers died" in killer["message"]
    innocent = df[df["sq.x"] != 3.0]
    assert (innocent["status"] == "ok").all(), innocent[["status", "message"]]
    assert (innocent["y_end"] == innocent["sq.x"] ** 2).all()


def test_the_optimizers_evaluator_blames_only_the_killer(write_spec, worker_processes):
    """cosim optimize evaluates through point_stream.Evaluator (the loop the sweep streams through): the same rule
    holds there."""
    from cosim.parallel.cluster.choice import choose_cluster
    from cosim.parallel.cluster.client import dask_client
    from cosim.parallel.isolation.payload import make_payload
    from cosim.parallel.point_stream import Evaluator
    from cosim.system.validate import check_spec

    system = check_spec(write_spec(square_spec(6, 0.0, kill_at=3.0)))
    points = [(f"p{i}", {"sq.x": float(i)}) for i in range(6)]
    with dask_client(choose_cluster(2, scheduler=worker_processes)) as (client, n_workers, _):
        with Evaluator(client, make_payload(system), n_workers) as evaluator:
            rows = evaluator.evaluate(points)
    assert [r.point_id for r in rows] == [pid for pid, _ in points]  # every point once, in order
    assert rows[3].status == "crashed" and "while it ran alone" in rows[3].message
    for i, row in enumerate(rows):
        if i != 3:
            assert row.status == "ok", row
            assert row.objectives["y_end"] == float(i) ** 2
