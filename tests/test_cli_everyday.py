"""Everyday command-line use that once ended in a traceback: a closed pipe, a bad scheduler address, --version."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd

import orchestrator
from orchestrator.cli import main

REPO = Path(__file__).resolve().parents[1]


def cosim(*args: str, **kwargs) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    return subprocess.Popen([sys.executable, "-m", "orchestrator.cli", *args], env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kwargs)


def test_version_prints_the_package_version(capsys):
    try:
        main(["--version"])
    except SystemExit as exc:
        assert exc.code == 0
    assert capsys.readouterr().out.strip() == f"cosim {orchestrator.__version__}"


def test_output_into_a_pipe_closed_early_is_not_an_error(tmp_path):
    """`cosim pareto ... | head -1`: the reader leaves after one line; cosim stops quietly with exit 0."""
    n = 20_000  # a front of 20 000 rows: far more than a pipe's buffer
    x = np.linspace(0.0, 1.0, n)
    pd.DataFrame({"point_id": [f"p{i:06d}" for i in range(n)], "a": x, "b": 1.0 - x,
                  "status": "ok"}).to_parquet(tmp_path / "t.parquet")
    proc = cosim("pareto", str(tmp_path / "t.parquet"), "--min", "a", "--min", "b")
    first = proc.stdout.readline()
    proc.stdout.close()  # what `head -1` does after its line
    stderr = proc.stderr.read()
    assert proc.wait(timeout=120) == 0, stderr
    assert first.startswith("Pareto front") and stderr == ""


def test_a_malformed_scheduler_address_is_a_usage_error_naming_the_form(tmp_path, capsys):
    spec = REPO / "examples" / "drive_energy" / "spec.json"
    for address in ("nonsense", "tcp://host-without-port", "foo://x:1"):
        assert main(["sweep", str(spec), "--out", str(tmp_path / "out"), "--scheduler", address]) == 2
        err = capsys.readouterr().err
        assert f"--scheduler '{address}' is not a Dask scheduler address" in err and "tcp://HOST:PORT" in err
        assert "Traceback" not in err
    assert not (tmp_path / "out").exists()  # refused before anything was written
