"""A stopped study keeps every point that finished before the stop (issue 29 item 3): rows stream back per point.

Before: rows came back per batch, so a Ctrl-C kept only the rows of whole batches (17 of 34 finished points with
0.3 s points). Here a real `cosim sweep` (its own local cluster, workers in other processes behind
--scheduler, or a cluster file's SubprocessCluster, whose `dask spec` processes get the Ctrl-C too) of a Python unit that sleeps 0.3 s per point (while the test's gate file exists) and then leaves a marker file
per finished point (the independent record) gets SIGINT from its terminal's process group (as Ctrl-C sends it) once N points finished.
Every marker older than the signal must have its row, no row may be made up by the stop (a killed point as
crashed, a point not run as failed), the client must be gone within a few seconds, and --resume must end with
the table an uninterrupted sweep writes.

The pause is there to have points in flight when the signal comes; the test removes the gate file once the
stopped client is gone, so the resume and the uninterrupted sweep it is compared with run their points without
it (the same unit file and spec, so --resume accepts them; 60 points of 0.3 s on 2 workers were ~16 s of
sleeping a case after the stop, benchmarks/test_suite_time.md).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from tests.helpers.paths import REPO

POINTS = 60
PAUSE = 0.3

UNIT = """
import os, time
from cosim import PythonUnit, Variable

class Slow(PythonUnit):
    variables = (Variable("k", "parameter", start=1.0), Variable("pause", "parameter", start=0.0),
                 Variable("y", "output", start=0.0))

    def do_step(self, t, h):
        if os.path.exists(GATE):  # removed by the test once the stop is checked
            time.sleep(self.pause)
        self.y = 3.0 * self.k + 0.5
        marker = os.path.join(MARKERS, f"{self.k:g}")
        with open(marker + ".tmp", "w") as f:
            f.write(repr(time.time()))
        os.replace(marker + ".tmp", marker)  # whole or absent
"""


def _study(folder: Path, markers: Path) -> Path:
    folder.mkdir(parents=True)
    markers.mkdir()
    (folder / "slow.py").write_text(UNIT.replace("MARKERS", repr(str(markers)))
                                    .replace("GATE", repr(str(folder / "pause"))))
    (folder / "pause").touch()
    spec = {"name": "slow", "units": {"s": {"python": "slow.py:Slow", "parameters": {"pause": PAUSE}}},
            "experiment": {"stop": 0.1, "step": 0.1}, "objectives": {"y": {"signal": "s.y", "reduce": "final"}},
            "design": {"parameters": {"s.k": {"min": 1, "max": POINTS, "step": 1}}}}
    path = folder / "spec.json"
    path.write_text(json.dumps(spec))
    return path


def _cosim(*args: str, **popen) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "cosim.cli.main", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONPATH=str(REPO / "src")),
                            start_new_session=True, **popen)


def _finished(markers: Path) -> dict[float, float]:
    """Point k -> the time its unit finished it, from the markers (the record independent of cosim's rows)."""
    return {float(p.name): float(p.read_text()) for p in markers.iterdir() if not p.name.endswith(".tmp")}


def _rows(out: Path) -> pd.DataFrame:
    parts = sorted((out / "parts").glob("part-*.parquet"))
    return pd.concat([pd.read_parquet(p) for p in parts]) if parts else pd.DataFrame({"s.k": [], "status": []})


SUBPROCESS_CLUSTER = {"type": "distributed.deploy.subprocess.SubprocessCluster",
                      "kwargs": {"n_workers": 2, "worker_kwargs": {"nthreads": 1}, "dashboard_address": "127.0.0.1:0"}}


@pytest.mark.parametrize("where", ["own local cluster", "scheduler in other processes", "SubprocessCluster file"])
def test_sigint_keeps_every_finished_point_and_resume_ends_as_an_uninterrupted_sweep(tmp_path, where,
                                                                                     local_cluster):
    markers = tmp_path / "markers"
    spec = _study(tmp_path / "study", markers)
    out = tmp_path / "out"
    cluster = {"own local cluster": ["--workers", "2"], "scheduler in other processes": ["--scheduler", local_cluster],
               "SubprocessCluster file": ["--cluster", str(tmp_path / "cluster.json")]}[where]
    (tmp_path / "cluster.json").write_text(json.dumps(SUBPROCESS_CLUSTER))
    sweep = ["sweep", str(spec), "--out", str(out), *cluster]
    proc = _cosim(*sweep)
    deadline = time.monotonic() + 180
    while len(_finished(markers)) < 12:  # batches are running, some half done (4-8 points of 0.3 s each)
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the points did not run"
        time.sleep(0.05)
    signalled = time.time()
    os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C: the whole process group
    _, err = proc.communicate(timeout=120)
    latency = time.time() - signalled
    assert proc.returncode == 130, err
    assert "cosim: interrupted" in err and "--resume" in err, err
    assert "Traceback" not in err and "BrokenPipe" not in err, err
    assert latency < 5, f"{latency:.1f} s from SIGINT to exit"  # ~0.3 s idle, 1-2 s behind --scheduler

    finished = {k for k, at in _finished(markers).items() if at <= signalled}
    assert len(finished) >= 12 and len(finished) < POINTS
    rows = _rows(out)
    assert finished <= set(rows["s.k"]), f"finished but not kept: {sorted(finished - set(rows['s.k']))}"
    assert (rows["status"] == "ok").all(), rows[rows["status"] != "ok"][["s.k", "status", "message"]]
    assert (rows["y"] == 3.0 * rows["s.k"] + 0.5).all()

    kept = set(rows["s.k"])
    (tmp_path / "study" / "pause").unlink()  # the stop is checked: the points after it need no pause
    for marker in markers.iterdir():
        marker.unlink()
    resumed = _cosim(*sweep, "--resume")
    _, err = resumed.communicate(timeout=300)
    assert resumed.returncode == 0, err
    assert not kept & set(_finished(markers)), "a point kept before the stop was computed again"
    assert not (out / "parts").exists()  # the finished study's rows are all in its table: no parts folder left
    table = pd.read_parquet(out / "results.parquet")
    uninterrupted = _cosim("sweep", str(spec), "--out", str(tmp_path / "whole"), *cluster)
    _, err = uninterrupted.communicate(timeout=300)
    assert uninterrupted.returncode == 0, err
    whole = pd.read_parquet(tmp_path / "whole" / "results.parquet")
    same = ["point_id", "s.k", "y", "status", "message"]
    pd.testing.assert_frame_equal(table[same], whole[same])
    assert list(table["s.k"]) == [float(k) for k in range(1, POINTS + 1)]
    assert list(table["y"]) == [3.0 * k + 0.5 for k in range(1, POINTS + 1)]


def test_kill_9_of_a_sweep_leaves_no_broken_pipe_traceback_from_its_point_processes(tmp_path):
    """Issue 28 item 11: the point children of a sweep killed with SIGKILL (they outlive it for a moment, their
    stderr is the terminal's) printed BrokenPipeError tracebacks when they sent their next row. Cheap points, so
    every child is sending rows when the client dies; stderr is read to its end, i.e. until every child is gone."""
    folder = tmp_path / "study"
    folder.mkdir()
    (folder / "fast.py").write_text("""
import time
from cosim import PythonUnit, Variable

class Fast(PythonUnit):
    variables = (Variable("k", "parameter", start=1.0), Variable("y", "output", start=0.0))

    def do_step(self, t, h):
        time.sleep(0.002)
        self.y = 2.0 * self.k
""")
    spec = folder / "spec.json"
    spec.write_text(json.dumps({"name": "fast", "units": {"s": {"python": "fast.py:Fast"}},
                                "experiment": {"stop": 0.1, "step": 0.1},
                                "objectives": {"y": {"signal": "s.y", "reduce": "final"}},
                                "design": {"parameters": {"s.k": {"min": 1, "max": 200_000, "step": 1}}}}))
    out = tmp_path / "out"
    proc = _cosim("sweep", str(spec), "--out", str(out), "--workers", "2")
    deadline = time.monotonic() + 180
    while not (out / "parts").is_dir() or not any((out / "parts").glob("part-*.parquet")):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "no rows came"
        time.sleep(0.05)
    time.sleep(1.0)  # rows flowing from both children
    os.kill(proc.pid, signal.SIGKILL)
    _, err = proc.communicate(timeout=60)  # returns once every process holding the stderr pipe is gone
    assert proc.returncode == -signal.SIGKILL
    assert "BrokenPipe" not in err and "Traceback" not in err, err
    kept = _rows(out)
    assert len(kept) > 0 and (kept["y"] == 2.0 * kept["s.k"]).all()  # the rows written before the kill are whole


OPTIMIZED = """
import os, time, uuid
from cosim import PythonUnit, Variable

class Slow(PythonUnit):
    variables = (Variable("k", "parameter", start=1.0), Variable("pause", "parameter", start=0.0),
                 Variable("y", "output", start=0.0))

    def do_step(self, t, h):
        if os.path.exists(GATE):  # removed by the test once the stop is checked
            time.sleep(self.pause)
        self.y = 3.0 * self.k + 0.5
        marker = os.path.join(MARKERS, uuid.uuid4().hex)
        with open(marker + ".tmp", "w") as f:
            f.write(f"{self.k!r} {time.time()!r}")
        os.replace(marker + ".tmp", marker)
"""


def test_sigint_keeps_every_finished_point_of_an_optimisation_and_resume_ends_as_uninterrupted(tmp_path):
    """cosim optimize goes through the same loop: a row is stored as its point finishes, not when its batch of 8
    ends, and the table is in trial order however the points of a batch finished."""
    markers = tmp_path / "markers"
    markers.mkdir()
    folder = tmp_path / "study"
    folder.mkdir()
    (folder / "slow.py").write_text(OPTIMIZED.replace("MARKERS", repr(str(markers)))
                                    .replace("GATE", repr(str(folder / "pause"))))
    (folder / "pause").touch()
    spec = folder / "spec.json"
    spec.write_text(json.dumps({
        "name": "slow", "units": {"s": {"python": "slow.py:Slow", "parameters": {"pause": PAUSE}}},
        "experiment": {"stop": 0.1, "step": 0.1},
        "objectives": {"y": {"signal": "s.y", "reduce": "final", "sense": "minimize"}},
        "design": {"parameters": {"s.k": {"min": 1.0, "max": 100.0}}},
        "optimize": {"sampler": "random", "budget": 24, "batch": 8, "seed": 5}}))

    def finished() -> dict[float, float]:
        out = {}
        for p in markers.iterdir():
            if not p.name.endswith(".tmp"):
                k, at = p.read_text().split()
                out[float(k)] = float(at)
        return out

    out = tmp_path / "out"
    run = ["optimize", str(spec), "--out", str(out), "--workers", "2"]
    proc = _cosim(*run)
    deadline = time.monotonic() + 180
    while len(finished()) < 11:  # the second batch of 8 has begun: 4 points a task, some done
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the points did not run"
        time.sleep(0.05)
    signalled = time.time()
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "cosim: interrupted" in err and "Traceback" not in err and "BrokenPipe" not in err, err
    assert time.time() - signalled < 5
    done = {k for k, at in finished().items() if at <= signalled}
    rows = _rows(out)
    assert len(done) >= 11 and done <= set(rows["s.k"]), f"finished but not kept: {sorted(done - set(rows['s.k']))}"
    assert (rows["status"] == "ok").all() and (rows["y"] == 3.0 * rows["s.k"] + 0.5).all()

    (folder / "pause").unlink()  # the stop is checked: the points after it need no pause
    resumed = _cosim(*run, "--resume")
    _, err = resumed.communicate(timeout=300)
    assert resumed.returncode == 0, err
    assert not (out / "parts").exists()
    whole = _cosim("optimize", str(spec), "--out", str(tmp_path / "whole"), "--workers", "2")
    _, err = whole.communicate(timeout=300)
    assert whole.returncode == 0, err
    same = ["point_id", "s.k", "y", "status", "trial", "batch", "sampler", "feasible"]
    table = pd.read_parquet(out / "results.parquet")
    pd.testing.assert_frame_equal(table[same], pd.read_parquet(tmp_path / "whole" / "results.parquet")[same])
    assert len(table) == 24 and list(table["trial"]) == sorted(table["trial"])
