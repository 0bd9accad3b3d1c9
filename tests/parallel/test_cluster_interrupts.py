"""Ctrl-C on `cosim sweep --cluster FILE` and `--scheduler ADDRESS`: one line, exit 130, no traceback, rows kept.

A terminal's Ctrl-C is SIGINT to cosim's whole process group: with a cluster
file, that group also holds the scheduler and worker processes the cluster
class started (a LocalCluster's workers, a SubprocessCluster's scheduler and
workers); with --scheduler the cluster runs elsewhere and only the client
stops.  "cosim: interrupted" is the last line on stderr, and no process of the
group outlives cosim.  Real processes, a real SIGINT to the group; then
--resume gives the exact table.
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
import psutil
import pytest

from tests.helpers.paths import REPO
from tests.helpers.triple_study import assert_triples_exact, triple_spec

CLUSTERS = {
    "LocalCluster file": {"type": "distributed.LocalCluster",
                          "kwargs": {"n_workers": 2, "threads_per_worker": 1, "dashboard_address": "127.0.0.1:0"}},
    "SubprocessCluster file": {"type": "distributed.deploy.subprocess.SubprocessCluster",
                               "kwargs": {"n_workers": 2, "worker_kwargs": {"nthreads": 1},
                                          "dashboard_address": "127.0.0.1:0"}},
    # workers that its adapt starts after the class returned (as a job system's would): they too must ignore the
    # Ctrl-C and leave the stop to cosim's client (before: their KeyboardInterrupt tracebacks on the terminal)
    "LocalCluster file, adapting": {"type": "distributed.LocalCluster",
                                    "kwargs": {"n_workers": 0, "threads_per_worker": 1,
                                               "dashboard_address": "127.0.0.1:0"},
                                    "adapt": {"minimum": 2, "maximum": 2}},
}


def _processes_in_group(group: int) -> list[str]:
    """The live processes of process group ``group`` (zombies left to a reaper are not running)."""
    found = []
    for process in psutil.process_iter(["pid", "status", "cmdline"]):
        try:
            if os.getpgid(process.pid) == group and process.info["status"] != psutil.STATUS_ZOMBIE:
                found.append(" ".join(process.info["cmdline"] or [])[:120])
        except (ProcessLookupError, psutil.Error):
            pass
    return found


def _interrupted_sweep(spec: Path, out: Path, where: list[str]) -> tuple[int, str]:
    """Start `cosim sweep`, SIGINT its process group once some rows are written; (exit code, stderr).

    Also checks that when cosim has exited no process of its group is left: the processes a cluster class
    started here end with cosim, so none prints anything after cosim's last line (the Dask nannies of a
    SubprocessCluster went on for 2 s after cosim, and logged their closing on the terminal).
    """
    env = dict(os.environ, PYTHONPATH=str(REPO / "src"))  # this checkout's cosim, also in the cluster's processes
    with open(out.parent / "stderr.txt", "w") as stderr:  # a file: a pipe would wait for every process holding it
        proc = subprocess.Popen([sys.executable, "-m", "cosim.cli.main", "sweep", str(spec), "--out", str(out),
                                 "--batch-size", "2", *where], stdout=subprocess.DEVNULL, stderr=stderr, text=True,
                                env=env, start_new_session=True)
    try:
        deadline = time.monotonic() + 180
        while not list((out / "parts").glob("part-*.parquet")):
            assert proc.poll() is None and time.monotonic() < deadline, (out.parent / "stderr.txt").read_text()
            time.sleep(0.1)  # stop it once some rows are written
        os.killpg(proc.pid, signal.SIGINT)  # a terminal's Ctrl-C reaches the whole process group
        signalled = time.monotonic()
        proc.wait(timeout=120)
        print(f"signal to exit: {time.monotonic() - signalled:.1f} s")  # (figures: benchmarks/interrupt_latency.md)
        left = _processes_in_group(proc.pid)
    finally:
        if proc.poll() is None or _processes_in_group(proc.pid):
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    time.sleep(1.0)  # anything the group's other processes print after the client is gone
    err = (out.parent / "stderr.txt").read_text()
    assert left == [], f"still running when cosim had exited: {left}\n{err}"
    return proc.returncode, err


def _last_line(err: str) -> str:
    return err.strip().splitlines()[-1]


@pytest.mark.parametrize("cluster", sorted(CLUSTERS))
def test_ctrl_c_on_a_cluster_file_sweep(tmp_path, cluster):
    spec, out = triple_spec(tmp_path, 40, pause=0.05), tmp_path / "out"
    (tmp_path / "cluster.json").write_text(json.dumps(CLUSTERS[cluster]))
    code, err = _interrupted_sweep(spec, out, ["--cluster", str(tmp_path / "cluster.json")])
    assert code == 130, err
    assert "cosim: interrupted" in err and "Traceback" not in err and "Error" not in err, err
    assert _last_line(err) == "cosim: interrupted", err  # nothing from Dask's processes after it
    stored = len(pd.concat(pd.read_parquet(p) for p in (out / "parts").glob("part-*.parquet")))
    assert 0 < stored < 40
    resumed = subprocess.run([sys.executable, "-m", "cosim.cli.main", "sweep", str(spec), "--out", str(out),
                              "--cluster", str(tmp_path / "cluster.json"), "--resume"], capture_output=True,
                             text=True, env=dict(os.environ, PYTHONPATH=str(REPO / "src")), timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    assert_triples_exact(pd.read_parquet(out / "results.parquet"), 40)


def test_ctrl_c_on_a_scheduler_sweep_leaves_the_cluster_running(tmp_path, dask_processes):
    address, _ = dask_processes
    spec, out = triple_spec(tmp_path, 40, pause=0.05), tmp_path / "out"
    code, err = _interrupted_sweep(spec, out, ["--scheduler", address])
    assert code == 130, err
    assert "cosim: interrupted" in err and "Traceback" not in err and "Error" not in err, err
    assert _last_line(err) == "cosim: interrupted", err
    resumed = subprocess.run([sys.executable, "-m", "cosim.cli.main", "sweep", str(spec), "--out", str(out),
                              "--scheduler", address, "--resume"], capture_output=True, text=True,
                             env=dict(os.environ, PYTHONPATH=str(REPO / "src")), timeout=300)
    assert resumed.returncode == 0, resumed.stderr  # the same scheduler and workers, still there
    assert_triples_exact(pd.read_parquet(out / "results.parquet"), 40)
