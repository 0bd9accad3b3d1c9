"""Ctrl-C on `cosim sweep --cluster FILE` and `--scheduler ADDRESS`: one line, exit 130, no traceback, rows kept.

A terminal's Ctrl-C is SIGINT to cosim's whole process group: with a cluster
file, that group also holds the scheduler and worker processes the cluster
class started (a LocalCluster's workers, a SubprocessCluster's scheduler and
workers); with --scheduler the cluster runs elsewhere and only the client
stops.  Real processes, a real SIGINT to the group; then --resume gives the
exact table.
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

from .sweep_fixtures import dask_processes  # noqa: F401  (fixture)
from .test_hostile_files import _exact, _spec

REPO = Path(__file__).resolve().parent.parent

CLUSTERS = {
    "LocalCluster file": {"type": "distributed.LocalCluster",
                          "kwargs": {"n_workers": 2, "threads_per_worker": 1, "dashboard_address": "127.0.0.1:0"}},
    "SubprocessCluster file": {"type": "distributed.deploy.subprocess.SubprocessCluster",
                               "kwargs": {"n_workers": 2, "worker_kwargs": {"nthreads": 1},
                                          "dashboard_address": "127.0.0.1:0"}},
}


def _interrupted_sweep(spec: Path, out: Path, where: list[str]) -> tuple[int, str]:
    """Start `cosim sweep`, SIGINT its process group once some rows are written; (exit code, stderr)."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli.main", "sweep", str(spec), "--out", str(out),
                             "--batch-size", "2", *where], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, start_new_session=True)
    try:
        deadline = time.monotonic() + 180
        while not list((out / "parts").glob("part-*.parquet")):
            assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()[1]
            time.sleep(0.1)  # stop it once some rows are written
        os.killpg(proc.pid, signal.SIGINT)  # a terminal's Ctrl-C reaches the whole process group
        signalled = time.monotonic()
        _, err = proc.communicate(timeout=120)
        print(f"signal to exit: {time.monotonic() - signalled:.1f} s")  # (figures: benchmarks/interrupt_latency.md)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    time.sleep(1.0)  # anything the group's other processes print after the client is gone
    return proc.returncode, err


@pytest.mark.parametrize("cluster", sorted(CLUSTERS))
def test_ctrl_c_on_a_cluster_file_sweep(tmp_path, cluster):
    spec, out = _spec(tmp_path, 40, pause=0.05), tmp_path / "out"
    (tmp_path / "cluster.json").write_text(json.dumps(CLUSTERS[cluster]))
    code, err = _interrupted_sweep(spec, out, ["--cluster", str(tmp_path / "cluster.json")])
    assert code == 130, err
    assert "cosim: interrupted" in err and "Traceback" not in err and "Error" not in err, err
    stored = len(pd.concat(pd.read_parquet(p) for p in (out / "parts").glob("part-*.parquet")))
    assert 0 < stored < 40
    resumed = subprocess.run([sys.executable, "-m", "cosim.cli.main", "sweep", str(spec), "--out", str(out),
                              "--cluster", str(tmp_path / "cluster.json"), "--resume"], capture_output=True,
                             text=True, env=dict(os.environ, PYTHONPATH=str(REPO)), timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    _exact(pd.read_parquet(out / "results.parquet"), 40)


def test_ctrl_c_on_a_scheduler_sweep_leaves_the_cluster_running(tmp_path, dask_processes):
    address, _ = dask_processes
    spec, out = _spec(tmp_path, 40, pause=0.05), tmp_path / "out"
    code, err = _interrupted_sweep(spec, out, ["--scheduler", address])
    assert code == 130, err
    assert "cosim: interrupted" in err and "Traceback" not in err and "Error" not in err, err
    resumed = subprocess.run([sys.executable, "-m", "cosim.cli.main", "sweep", str(spec), "--out", str(out),
                              "--scheduler", address, "--resume"], capture_output=True, text=True,
                             env=dict(os.environ, PYTHONPATH=str(REPO)), timeout=300)
    assert resumed.returncode == 0, resumed.stderr  # the same scheduler and workers, still there
    _exact(pd.read_parquet(out / "results.parquet"), 40)
