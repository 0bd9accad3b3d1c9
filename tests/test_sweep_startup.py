"""The sweep's fixed cost and per-point overhead: the cluster started early, tasks sized to the points' cost,
and the command's exit (issue 16). The speed itself is measured in benchmarks/sweep_startup.py and
benchmarks/sweep_memory.py; here, that these means keep every result and leave nothing running."""

from __future__ import annotations

import multiprocessing
import subprocess
import sys

import psutil
import pytest

from orchestrator.sweep import BatchSizer, Sweep, SweepError

from .conftest import TESTS

UNIT = f"{TESTS / 'units_for_cluster.py'}:SlowSquare"


def square_spec(values: list[float]) -> dict:
    return {
        "name": "early",
        "units": {"sq": {"python": UNIT, "parameters": {"delay": 0.0, "kill_at": -1e9}}},  # no point kills
        "experiment": {"stop": 0.2, "step": 0.1},
        "objectives": {"y_end": {"signal": "sq.y", "reduce": "final"}},
        "design": {"parameters": {"sq.x": {"values": values}}},
    }


def test_tasks_of_cheap_points_grow_and_shrink_again_towards_the_end():
    sizer = BatchSizer(todo=100_000, n_workers=2)
    assert sizer.next() == 64  # before any point time is known: small tasks spread over both workers
    sizer.observe([{"status": "ok", "run_time": 0.001}] * 10 + [{"status": "failed", "run_time": 5.0}])
    assert sizer.point_seconds == pytest.approx(0.001)  # failed points do not count
    assert sizer.next() == 500  # 0.5 s of 1 ms points
    sizer.observe([{"status": "ok", "run_time": 1e-7}] * 1000)  # now nearly free: capped
    assert sizer.next() == BatchSizer.MAX_BATCH
    sizer.remaining = 1000
    assert sizer.next() == 125  # the last 1000 points in tasks of 1000 / (4 x 2 workers)
    sizer.remaining = 10
    assert sizer.next() == 64  # never below the first size


def test_a_given_batch_size_is_kept_and_take_counts_down():
    sizer = BatchSizer(todo=10, n_workers=2, size=4)
    sizer.observe([{"status": "ok", "run_time": 1e-6}] * 4)
    points = iter(range(10))
    assert [len(sizer.take(points)) for _ in range(4)] == [4, 4, 2, 0]
    assert sizer.remaining == 0


def test_an_early_started_cluster_runs_the_sweep_and_gives_every_point(write_spec, tmp_path):
    values = [float(v) for v in range(-5, 45)]
    sweep = Sweep(write_spec(square_spec(values)), workers=2, out=tmp_path / "out", quiet=True, start_early=True)
    df = sweep.run()
    assert list(df["sq.x"]) == values and (df["status"] == "ok").all()
    assert list(df["y_end"]) == [v * v for v in values]
    assert "__design_index" not in df.columns


def _dask_workers() -> set[int]:
    """Worker processes: spawned, or forked by the fork server (a child of this process that lives on, see
    orchestrator.worker_setup; its forks have its command line)."""
    me = psutil.Process()
    found = set()
    for p in me.children(recursive=True):
        line = " ".join(p.cmdline())
        if ("spawn_main" in line or ("forkserver import main" in line and p.ppid() != me.pid)) and p.is_running():
            found.add(p.pid)
    return found


def test_a_sweep_that_cannot_start_closes_its_early_cluster(write_spec, tmp_path):
    spec = write_spec(square_spec([1.0, 2.0]))
    Sweep(spec, workers=1, out=tmp_path / "out", quiet=True).run()  # the folder now holds results
    before = _dask_workers()
    with pytest.raises(SweepError, match="already holds results"):
        Sweep(spec, workers=2, out=tmp_path / "out", quiet=True, start_early=True)
    assert _dask_workers() <= before  # the cluster started for it is gone again


def test_the_command_skips_the_final_collections_only_as_a_program(write_spec, tmp_path):
    spec = write_spec(square_spec([1.0]))
    code = ("import gc, sys; from orchestrator.cli import main; how, args = sys.argv[1], sys.argv[2:]; "
            "sys.argv = ['cosim', *args]; code = main(args) if how == 'given' else main(); "
            "print(code, gc.get_freeze_count() > 0)")
    for how, frozen in (("given", False), ("program", True)):
        out = subprocess.run([sys.executable, "-c", code, how, "validate", str(spec)], capture_output=True,
                             text=True, check=True)
        assert out.stdout.split()[-2:] == ["0", str(frozen)], out.stdout + out.stderr


def test_the_local_cluster_workers_run_cosims_set_up():
    from distributed import Client

    from orchestrator.evaluator import local_cluster

    with local_cluster(1) as cluster, Client(cluster) as client:
        loaded = client.run(lambda: __import__("sys").modules.get("orchestrator.worker_setup") is not None)
    assert list(loaded.values()) == [True]


def test_the_local_cluster_workers_are_forked_and_get_the_environment_of_their_start(monkeypatch):
    """Forked by a fork server that imported Dask and cosim's worker modules once (orchestrator.worker_setup),
    a worker still sees this process's environment as it is when its cluster starts, not the fork server's."""
    from distributed import Client

    from orchestrator.evaluator import local_cluster

    with local_cluster(1):
        pass  # the fork server runs from now on (if no earlier test started it)
    monkeypatch.setenv("COSIM_TEST_WORKER_ENV", "set after the fork server started")

    def seen() -> tuple[str | None, str, bool]:
        import os
        import sys

        return (os.environ.get("COSIM_TEST_WORKER_ENV"), " ".join(psutil.Process().parent().cmdline()),
                "orchestrator.sweep" in sys.modules)

    with local_cluster(1) as cluster, Client(cluster) as client:
        [(value, parent, imported)] = client.run(seen).values()
    assert value == "set after the fork server started"
    if "forkserver" in multiprocessing.get_all_start_methods():
        assert "forkserver import main" in parent  # forked by the fork server, with run_batch's module loaded
        assert imported
