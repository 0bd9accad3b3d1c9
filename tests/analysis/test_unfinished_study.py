"""report, pareto, plot and explore on the folder of an interrupted study, whose rows are still in parts
(issue 28, item 5); ``cosim report`` without ``-o`` (issue 28, item 15).

Before, every one of them said "no such results table" about a folder holding rows in ``parts/``.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

from cosim.analysis.table import load_results
from tests.helpers.paths import REPO
from tests.helpers.triple_study import triple_spec

ENV = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO / "src"), os.environ.get("PYTHONPATH", "")]))


def _cosim(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cosim.cli.main", *args], capture_output=True, text=True, env=ENV,
                          timeout=300)


def _interrupted_sweep(tmp_path: Path) -> Path:
    """A 40-point sweep stopped by Ctrl-C (SIGINT to its process group) once some rows are in parts/."""
    spec, out = triple_spec(tmp_path, 40, pause=0.05), tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli.main", "sweep", str(spec), "--out", str(out),
                             "--batch-size", "2", "--workers", "1"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, env=ENV, start_new_session=True)
    try:
        deadline = time.monotonic() + 240
        while len(list((out / "parts").glob("part-*.parquet"))) < 2:
            assert proc.poll() is None and time.monotonic() < deadline, "the sweep ended before it was stopped"
            time.sleep(0.05)
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return out


def test_an_interrupted_sweeps_folder_can_be_looked_at(tmp_path):
    out = _interrupted_sweep(tmp_path)
    assert not (out / "results.parquet").exists()
    parts = pd.concat(pd.read_parquet(p) for p in (out / "parts").glob("part-*.parquet"))
    stored = set(parts["point_id"])
    assert 0 < len(stored) < 40

    table = load_results(out)  # what explore, report, pareto and plot read
    assert set(table.df["point_id"]) == stored and table.df["point_id"].is_unique
    assert all(table.df["y"] == 3.0 * table.df["s.k"])  # y = 3 k, the unit's formula
    assert "unfinished study" in table.note and "--resume" in table.note
    assert table.spec is not None  # metadata.json is read as for a finished one

    report = _cosim("report", str(out))  # no -o: report.html in the folder
    assert report.returncode == 0, report.stderr
    assert "unfinished study" in report.stderr and (out / "report.html").stat().st_size > 10_000
    best = min(table.df["s.k"])
    pareto = _cosim("pareto", str(out), "--min", "y")
    assert pareto.returncode == 0, pareto.stderr
    assert f"1 of {len(stored)} rows" in pareto.stdout and f" {best} " in pareto.stdout.splitlines()[-1] + " "
    plot = _cosim("plot", str(out), "--x", "s.k", "--y", "y", "-o", str(tmp_path / "cloud.png"))
    assert plot.returncode == 0, plot.stderr
    assert f"{len(stored)} points coloured" in plot.stdout
    assert not (out / "results.parquet").exists()  # looking changes nothing: --resume still finds the parts


def test_report_without_o_writes_beside_a_table_file(tmp_path):
    pd.DataFrame({"point_id": ["a", "b"], "x": [1.0, 2.0], "y": [2.0, 1.0], "status": "ok"}).to_parquet(
        tmp_path / "t.parquet")
    done = _cosim("report", str(tmp_path / "t.parquet"))
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == f"written: {tmp_path / 'report.html'}"
