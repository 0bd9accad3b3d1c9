"""The sweep's fixed cost and per-point overhead: the cluster started early, tasks sized to the points' cost,
and the command's exit (issue 16). The speed itself is measured in benchmarks/sweep_startup.py and
benchmarks/sweep_memory.py; here, that these means keep every result and leave nothing running."""

from __future__ import annotations

import subprocess
import sys

import psutil
import pytest

from cosim.execution.point_row import PointRow
from cosim.studies.sweep import BatchSizer, Sweep, SweepError
from tests.helpers.paths import HELPERS

UNIT = f"{HELPERS / 'units_for_cluster.py'}:SlowSquare"


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
    sizer.observe([PointRow("p", "ok", run_time=0.001)] * 10 + [PointRow("q", "failed", run_time=5.0)])
    assert sizer.point_seconds == pytest.approx(0.001)  # failed points do not count
    assert sizer.next() == 500  # 0.5 s of 1 ms points
    sizer.observe([PointRow("p", "ok", run_time=1e-7)] * 1000)  # now nearly free: capped
    assert sizer.next() == BatchSizer.MAX_BATCH
    sizer.remaining = 1000
    assert sizer.next() == 125  # the last 1000 points in tasks of 1000 / (4 x 2 workers)
    sizer.remaining = 10
    assert sizer.next() == 64  # never below the first size


def test_the_first_tasks_of_a_small_sweep_are_a_quarter_of_each_workers_share():
    assert BatchSizer(todo=273, n_workers=2).next() == 35  # the README's main job: 8 tasks before times are known
    assert BatchSizer(todo=5, n_workers=4).next() == 1


def test_a_given_batch_size_is_kept_and_take_counts_down():
    sizer = BatchSizer(todo=10, n_workers=2, size=4)
    sizer.observe([PointRow("p", "ok", run_time=1e-6)] * 4)
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


def test_a_sweep_that_cannot_start_closes_its_early_cluster(write_spec, tmp_path):
    from distributed.deploy.spec import SpecCluster

    spec = write_spec(square_spec([1.0, 2.0]))
    Sweep(spec, workers=1, out=tmp_path / "out", quiet=True).run()  # the folder now holds results
    before = set(SpecCluster._instances)
    with pytest.raises(SweepError, match="already holds results"):
        Sweep(spec, workers=2, out=tmp_path / "out", quiet=True, start_early=True)
    started = set(SpecCluster._instances) - before
    assert len(started) <= 1 and all(c.status.name == "closed" for c in started)  # started for it, closed again


def test_the_command_skips_the_final_collections_only_as_a_program(write_spec, tmp_path):
    spec = write_spec(square_spec([1.0]))
    code = ("import gc, sys; from cosim.cli.main import main; how, args = sys.argv[1], sys.argv[2:]; "
            "sys.argv = ['cosim', *args]; code = main(args) if how == 'given' else main(); "
            "print(code, gc.get_freeze_count() > 0)")
    for how, frozen in (("given", False), ("program", True)):
        out = subprocess.run([sys.executable, "-c", code, how, "validate", str(spec)], capture_output=True,
                             text=True, check=True)
        assert out.stdout.split()[-2:] == ["0", str(frozen)], out.stdout + out.stderr


def test_the_local_clusters_workers_run_in_this_process_and_serve_only_127_0_0_1():
    """Points never run in a Dask worker but in its child process (cosim.parallel.isolation): cosim's local
    cluster keeps its workers in the client's process, without their bokeh pages."""
    from distributed import Client

    from cosim.parallel.cluster.local import local_cluster

    me = psutil.Process()
    connections = getattr(me, "net_connections", None) or me.connections  # psutil >= 6 / the declared 5.9

    def listening_now() -> set:
        return {c.laddr for c in connections(kind="inet") if c.status == psutil.CONN_LISTEN}

    before = listening_now()
    with local_cluster(2) as cluster, Client(cluster) as client:
        pids = client.run(lambda: __import__("os").getpid())
        listening = listening_now() - before
        pages = client.run(lambda dask_worker: sorted(dask_worker.http_application.applications or []))
    assert len(pids) == 2 and set(pids.values()) == {me.pid}
    assert listening and all(address.ip == "127.0.0.1" for address in listening)  # dashboard, workers' health
    assert all(not p for p in pages.values())  # no worker pages


def test_a_point_that_kills_its_process_is_one_crashed_row_on_the_local_cluster(write_spec, tmp_path):
    """The local cluster's isolation is the points' child processes: a unit killing its process (a segfault,
    os._exit) costs its own point, never the client running the workers."""
    unit = tmp_path / "killer.py"
    unit.write_text("import os\nfrom cosim import PythonUnit, Variable\n\n"
                    "class Killer(PythonUnit):\n"
                    "    variables = (Variable('x', 'parameter', start=0.0), Variable('y', 'output', start=0.0))\n\n"
                    "    def do_step(self, t, h):\n"
                    "        if self.x == 2.0:\n"
                    "            os._exit(9)\n"
                    "        self.y = 10.0 * self.x\n")
    spec = {"name": "killer", "units": {"k": {"python": f"{unit}:Killer"}},
            "experiment": {"stop": 0.2, "step": 0.1},
            "objectives": {"y_end": {"signal": "k.y", "reduce": "final"}},
            "design": {"parameters": {"k.x": {"values": [0.0, 1.0, 2.0, 3.0, 4.0]}}}}
    df = Sweep(write_spec(spec), workers=2, out=tmp_path / "out", quiet=True, start_early=True).run()
    assert list(df["status"]) == ["ok", "ok", "crashed", "ok", "ok"]
    assert "exit code 9" in df["message"][2]
    assert list(df["y_end"][df["status"] == "ok"]) == [0.0, 10.0, 30.0, 40.0]
