"""The dashboard's points page counts points as they finish inside a batch (cosim.parallel.dashboard.points).

Real `cosim sweep` processes on a local cluster, a cluster file and a `dask
scheduler` that cannot import cosim; the page is read with real HTTP requests.
The unit holds the last three points of every batch of six until the test
creates a release file, so while no task has finished the page must already
count the first three points of each batch (one of them failed on purpose).
"""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

import pytest

from tests.helpers.paths import HELPERS, REPO
from tests.helpers.sweep_fixtures import free_port, kill_group, wait_for_workers

ROOT = REPO

GATE_UNIT = '''
import os
import time

from cosim import PythonUnit, Variable


class Gate(PythonUnit):
    """y = k; point k = 1 fails; points with k % 6 >= 3 wait until the file 'release' exists."""

    variables = (Variable("k", "parameter", start=0.0), Variable("release", "parameter", type="String", start=""),
                 Variable("y", "output", start=0.0))

    def initialize(self):
        if int(self.k) == 1:
            raise RuntimeError("point 1 fails on purpose")
        while int(self.k) % 6 >= 3 and not os.path.exists(self.release):
            time.sleep(0.05)

    def do_step(self, t, h):
        self.y = self.k
'''


def _gate_spec(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "gate.py").write_text(GATE_UNIT)
    spec = {"name": "gated", "units": {"g": {"python": "gate.py:Gate",
                                             "parameters": {"release": str(folder / "release")}}},
            "experiment": {"stop": 0.2, "step": 0.1}, "objectives": {"y": {"signal": "g.y", "reduce": "final"}},
            "design": {"parameters": {"g.k": {"values": [float(k) for k in range(12)]}}}}
    (folder / "spec.json").write_text(json.dumps(spec))
    return folder / "spec.json"


def _get(url: str) -> str:
    with urllib.request.urlopen(url, timeout=10) as response:
        assert response.status == 200
        return response.read().decode()


def _study(points_url: str, predicate, seconds: float = 90) -> dict:
    """The newest study of the page's JSON once ``predicate`` holds for it (fails after ``seconds``)."""
    deadline = time.monotonic() + seconds
    while True:
        studies = json.loads(_get(points_url + "/points.json"))["studies"]
        if studies and predicate(studies[0]):
            return studies[0]
        assert time.monotonic() < deadline, f"the page never showed it: {studies}"
        time.sleep(0.2)


class CosimProcess:
    """`cosim sweep` as a process; its stderr is read as it comes (the start line names the pages)."""

    def __init__(self, args: list[str], env: dict[str, str] | None = None):
        self.proc = subprocess.Popen([sys.executable, "-m", "cosim.cli.main", "sweep", *args], text=True,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True,
                                     env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})})
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.proc.stderr:
            self.lines.append(line)

    def start_line(self, seconds: float = 120) -> str:
        deadline = time.monotonic() + seconds
        while not any("dashboard:" in line for line in self.lines):
            assert self.proc.poll() is None and time.monotonic() < deadline, "".join(self.lines)
            time.sleep(0.1)
        return next(line for line in self.lines if "dashboard:" in line)

    def finish(self, seconds: float = 120) -> str:
        self.proc.wait(timeout=seconds)
        self._reader.join(timeout=10)
        return "".join(self.lines)

    def kill(self) -> None:
        if self.proc.poll() is None:
            kill_group(self.proc)


def _points_url(start_line: str) -> str:
    assert "points: http://" in start_line, start_line
    return start_line.split("points: ")[1].split(")")[0].strip()


def _check_mid_run_and_finish(points_url: str, folder: Path, cosim: CosimProcess) -> str:
    # no task has finished: the last three points of each batch of six wait for the release file
    mid = _study(points_url, lambda s: s["done"] == 6)
    assert (mid["done"], mid["total"], mid["failed"], mid["running_tasks"], mid["state"]) == (6, 12, 1, 2, "running")
    page = _get(points_url)
    assert "6 / 12" in page and "sweep gated" in page
    (folder / "release").write_text("")
    return cosim.finish()


@pytest.mark.parametrize("how", ["local cluster", "cluster file"])
def test_the_points_page_counts_points_inside_running_batches(tmp_path, how):
    spec = _gate_spec(tmp_path / "project")
    args = [str(spec), "--out", str(tmp_path / "out"), "--batch-size", "6"]
    if how == "local cluster":
        args += ["--workers", "2"]
    else:  # a SpecCluster whose scheduler and workers are subprocesses of their own
        (tmp_path / "cluster.json").write_text(json.dumps({
            "type": "distributed.deploy.subprocess.SubprocessCluster",
            "kwargs": {"n_workers": 2, "worker_kwargs": {"nthreads": 1}, "dashboard_address": "127.0.0.1:0"}}))
        args += ["--cluster", str(tmp_path / "cluster.json")]
    cosim = CosimProcess(args)
    try:
        points_url = _points_url(cosim.start_line())
        err = _check_mid_run_and_finish(points_url, tmp_path / "project", cosim)
    finally:
        cosim.kill()
    assert cosim.proc.returncode == 1, err  # point 1 failed
    assert "Traceback" not in err
    import pandas as pd

    df = pd.read_parquet(tmp_path / "out" / "results.parquet")
    assert len(df) == 12 and list(df["status"] != "ok") == [k == 1 for k in range(12)]


BLOCKER = '''
import sys


class NoCosim:
    """This scheduler cannot import cosim (as on a machine where it is not installed)."""

    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("cosim", "orchestrator", "models", "fmus"):
            raise ModuleNotFoundError(f"No module named {name!r} (blocked by the test)")
        return None


sys.meta_path.insert(0, NoCosim())
sys.argv = ["dask-scheduler", *sys.argv[1:]]
from distributed.cli.dask_scheduler import main

main()
'''


@pytest.fixture
def dask_commands(tmp_path):
    """Starts `dask scheduler` (optionally unable to import cosim) and two `dask worker` processes; returns
    (scheduler address, dashboard URL)."""
    procs = []

    def start(without_cosim: bool = False) -> tuple[str, str]:
        port, http = free_port(), free_port()
        (tmp_path / "blocked_scheduler.py").write_text(BLOCKER)
        program = [str(tmp_path / "blocked_scheduler.py")] if without_cosim else ["-m", "distributed.cli.dask_scheduler"]
        env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        if not without_cosim:
            env["PYTHONPATH"] = str(ROOT)
        web = ["--dashboard-address", f"127.0.0.1:{http}"]
        procs.append(subprocess.Popen([sys.executable, *program, "--host", "127.0.0.1", "--port", str(port), *web],
                                      cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                      start_new_session=True))
        address = f"tcp://127.0.0.1:{port}"
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nworkers", "2", "--nthreads", "1",
             "--no-dashboard", "--host", "127.0.0.1"], env={**os.environ, "PYTHONPATH": str(ROOT)},
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True))
        wait_for_workers(address, 2, seconds=90)
        return address, f"http://127.0.0.1:{http}"

    try:
        yield start
    finally:
        for proc in reversed(procs):
            kill_group(proc)


def test_the_points_page_of_a_running_scheduler_keeps_the_final_counts(tmp_path, dask_commands):
    address, dashboard = dask_commands()
    spec = _gate_spec(tmp_path / "project")
    cosim = CosimProcess([str(spec), "--out", str(tmp_path / "out"), "--batch-size", "6", "--scheduler", address])
    try:
        points_url = _points_url(cosim.start_line())
        assert points_url == f"{dashboard}/cosim"
        err = _check_mid_run_and_finish(points_url, tmp_path / "project", cosim)
    finally:
        cosim.kill()
    assert cosim.proc.returncode == 1 and "Traceback" not in err, err
    # the scheduler outlives the sweep: the page keeps its final counts
    final = _study(points_url, lambda s: s["state"] == "finished")
    assert (final["done"], final["total"], final["failed"], final["running_tasks"]) == (12, 12, 1, 0)
    # the dashboard's navigation bar links to the page
    assert 'href="cosim"' in _get(f"{dashboard}/status")


def test_a_scheduler_that_cannot_import_cosim_is_refused_before_any_work(tmp_path, dask_commands):
    """Dask's scheduler unpickles every task: without cosim it could run none (exit 2, the fix, no rows)."""
    from distributed import Client

    address, _ = dask_commands(without_cosim=True)
    with Client(address, timeout=10) as client, pytest.raises(ModuleNotFoundError, match="cosim"):
        client.run_on_scheduler(importlib.import_module, "cosim")
    spec = _gate_spec(tmp_path / "project")
    cosim = CosimProcess([str(spec), "--out", str(tmp_path / "out"), "--scheduler", address])
    try:
        err = cosim.finish()
    finally:
        cosim.kill()
    assert cosim.proc.returncode == 2, err
    assert f"the Dask scheduler at {address} cannot import cosim (ModuleNotFoundError" in err
    assert "install cosim (the version of this client) where the scheduler runs" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "out" / "results.parquet").exists() and not list((tmp_path / "out").glob("parts/*"))


def test_an_optimization_counts_its_evaluations_on_the_page(write_spec, tmp_path, local_cluster):
    from urllib.parse import urljoin

    from distributed import Client

    from cosim.studies.optimize import Optimization
    from tests.helpers.tools import python_unit

    spec = write_spec({
        "name": "bowls_page", "units": {"b": {"python": python_unit("TwoBowls")}},
        "experiment": {"stop": 1.0, "step": 1.0},
        "objectives": {"f1": {"signal": "b.f1", "reduce": "final", "sense": "minimize"},
                       "f2": {"signal": "b.f2", "reduce": "final", "sense": "minimize"}},
        "design": {"parameters": {"b.x": {"min": -1.0, "max": 3.0}, "b.y": {"min": -2.0, "max": 2.0}}},
        "optimize": {"budget": 8, "batch": 4, "seed": 3, "sampler": "random"}})
    Optimization(spec, tmp_path / "out", scheduler=local_cluster, quiet=True).run()
    with Client(local_cluster, timeout=10) as client:
        points_url = urljoin(client.dashboard_link, "cosim")
    final = _study(points_url, lambda s: s["name"] == "bowls_page" and s["state"] == "finished")
    assert (final["kind"], final["done"], final["total"], final["failed"], final["running_tasks"]) == \
        ("optimize", 8, 8, 0, 0)


def test_points_of_a_task_lost_with_its_workers_are_counted_once(write_spec, tmp_path):
    """A point that kills its workers (the second of a batch of three, after the first was counted): the batch
    runs again (same task), is lost again (KilledWorker), its points run again alone: each counted once, the
    killer's row (made by the client) too."""
    from urllib.parse import urljoin

    import dask
    from distributed import LocalCluster

    import cosim

    with dask.config.set({"distributed.scheduler.allowed-failures": 1}):  # as on the clusters cosim starts
        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address="127.0.0.1:0", silence_logs=40)
    try:
        spec = {"name": "lost_once", "units": {"sq": {"python": f"{HELPERS / 'units_for_cluster.py'}:SlowSquare",
                                                      "parameters": {"delay": 0.1, "kill_at": 4.0}}},
                "experiment": {"stop": 0.5, "step": 0.1},
                "objectives": {"y_end": {"signal": "sq.y", "reduce": "final"}},
                "design": {"parameters": {"sq.x": {"values": [float(i) for i in range(8)]}}}}
        df = cosim.sweep(str(write_spec(spec)), scheduler=cluster.scheduler_address, batch_size=3,
                                quiet=True)
        assert len(df) == 8 and list(df["status"] != "ok") == [x == 4.0 for x in df["sq.x"]]
        final = _study(urljoin(cluster.dashboard_link, "cosim"),
                       lambda s: s["name"] == "lost_once" and s["state"] == "finished")
        assert (final["done"], final["total"], final["failed"], final["running_tasks"]) == (8, 8, 1, 0)
    finally:
        cluster.close()


def test_the_rate_is_that_of_the_last_half_minute_and_the_time_left_follows_from_it(monkeypatch):
    """Issue 39: the page says how fast a study goes and how long it has left (cosim.parallel.dashboard.points)."""
    from cosim.parallel.dashboard import points as P

    clock = [1000.0]
    monkeypatch.setattr(P.time, "time", lambda: clock[0])
    plugin = P.PointsPlugin()
    plugin.log_event(P.TOPIC, {"op": "start", "study": "s1", "kind": "sweep", "name": "demo", "total": 100,
                               "before": 10, "client": "c"})
    key = "cosim sweep demo-points 1..50 of 100-s1.abc"
    assert plugin.summary()[0]["rate"] is None and plugin.summary()[0]["left_s"] is None  # nothing done yet
    for t, done in ((1010.0, 5), (1020.0, 10), (1040.0, 20), (1060.0, 30)):
        clock[0] = t
        plugin.log_event(P.TOPIC, {"key": key, "done": done, "failed": 1})
    study = plugin.summary()[0]
    # the window keeps one count from before the last 30 s: (1020, 10) .. (1060, 30): 20 points in 40 s
    assert study["rate"] == pytest.approx(0.5) and study["done"] == 40 and study["failed"] == 1
    assert study["left_s"] == pytest.approx(60 / 0.5)
    clock[0] = 1080.0  # no point for 20 s: the rate falls as time passes without one
    assert plugin.summary()[0]["rate"] == pytest.approx(20 / 60)
    plugin.log_event(P.TOPIC, {"op": "end", "study": "s1", "state": "finished"})
    clock[0] = 2000.0
    ended = plugin.summary()[0]
    assert ended["left_s"] is None and ended["rate"] == pytest.approx(20 / 60)  # measured up to the end
    assert (P.rate_text(0.5), P.rate_text(120.4), P.rate_text(None)) == ("0.50 /s", "120 /s", "\u2013")
    assert (P.duration_text(42), P.duration_text(600), P.duration_text(9000)) == ("42 s", "10 min", "2.5 h")


def test_the_points_page_is_live_in_a_browser_without_reloading(tmp_path, dask_commands):
    """Issue 39: the Cosim page was an HTML page reloaded every 2 s. Now its script redraws the counts in place:
    in chromium, a mark set on the page's window survives while the counts go from 6 to 12 of 12 (on a
    scheduler that outlives the sweep, so the page is still there when it has finished)."""
    from cosim.analysis.room import browser as B
    from tests.helpers.tools import require_tool

    require_tool("chromium", "chromium")
    require_tool("chromedriver", "chromium-driver")
    address, _ = dask_commands()
    spec = _gate_spec(tmp_path / "project")
    env = {"PYTHONPATH": os.pathsep.join([str(ROOT / "src"), str(ROOT)])}
    cosim = CosimProcess([str(spec), "--out", str(tmp_path / "out"), "--batch-size", "6", "--scheduler", address],
                         env)
    driver = B.chromium()
    try:
        points_url = _points_url(cosim.start_line())
        _study(points_url, lambda s: s["done"] == 6)
        driver.get(points_url)
        driver.execute_script("window.__same_page = 'yes'")

        def cells() -> dict:
            return driver.execute_script(
                "const r = document.querySelector('#studies tr'); const out = {};"
                "for (const td of r.querySelectorAll('td')) { if (td.className) out[td.className] = td.textContent; }"
                "return out;")

        deadline = time.monotonic() + 30
        while cells().get("rate", "\u2013") == "\u2013":  # the rate needs two counts, from the page's script
            assert time.monotonic() < deadline, cells()
            time.sleep(0.2)
        running = cells()
        assert running["points"] == "6 / 12" and running["failed"] == "1" and running["state"] == "running"
        assert running["rate"].endswith(" /s") and running["name"] == "sweep gated"
        assert running["left"] != "\u2013" and "updated" in driver.find_element("id", "updated").text
        (tmp_path / "project" / "release").write_text("")
        deadline = time.monotonic() + 90
        while cells().get("state") != "finished":
            assert time.monotonic() < deadline, (cells(), _get(points_url + "/points.json"), cosim.lines[-5:])
            time.sleep(0.2)
        done = cells()
        assert done["points"] == "12 / 12" and done["left"] == "\u2013"
        assert driver.execute_script("return window.__same_page") == "yes"  # redrawn in place, never reloaded
        assert B.console_errors(driver) == []
    finally:
        driver.quit()
        cosim.kill()
    cosim.finish()
