"""The public API: plain typed functions, cheap to import, the same defaults as the command line."""

from __future__ import annotations

import inspect
import json
import os
import subprocess
import sys
from pathlib import Path

import pandas as pd

import orchestrator

ROOT = Path(__file__).resolve().parent.parent


def test_import_loads_neither_the_engine_nor_dask_and_registers_no_exit_hook():
    code = ("import atexit, sys; before = atexit._ncallbacks(); import orchestrator; "
            "print(atexit._ncallbacks() - before, sorted(m for m in sys.modules if m.split('.')[0] in "
            "('dask', 'distributed', 'pandas', 'numpy', 'fmpy', 'orchestrator')))")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
    assert out.split(None, 1) == ["0", "['orchestrator']\n"]


def test_every_public_name_resolves_and_is_typed():
    for name in orchestrator.__all__:
        assert getattr(orchestrator, name) is not None, name
    for function in (orchestrator.run, orchestrator.sweep, orchestrator.run_point):
        signature = inspect.signature(function)
        assert signature.return_annotation is not inspect.Signature.empty, function
        assert all(p.annotation is not inspect.Parameter.empty for p in signature.parameters.values()), function


def test_sweep_defaults_to_one_worker_per_core_like_the_command_line(tmp_path, write_spec):
    from orchestrator.sweep import Sweep
    from orchestrator.sweep_cli import add_sweep_parser

    from .conftest import python_unit

    assert inspect.signature(orchestrator.sweep).parameters["workers"].default is None
    spec = write_spec({"units": {"ode": {"python": python_unit("LinearOde")}}, "experiment": {"stop": 0.1, "step": 0.1},
                       "design": {"parameters": {"ode.a": {"values": [-1.0]}}}})
    assert Sweep(spec, out=tmp_path / "o").workers == os.cpu_count()
    import argparse

    parser = argparse.ArgumentParser()
    add_sweep_parser(parser.add_subparsers())
    assert parser.parse_args(["sweep", str(spec)]).workers is None  # the same Sweep default


def test_sweep_returns_a_dataframe_and_the_counts_stay_on_disk(tmp_path, write_spec):
    from orchestrator.sweep import Sweep

    from .conftest import python_unit

    spec = write_spec({"units": {"ode": {"python": python_unit("LinearOde"), "parameters": {"x0": 1.0}}},
                       "experiment": {"stop": 1.0, "step": 0.01},
                       "objectives": {"y": {"signal": "ode.y", "reduce": "final"}},
                       "design": {"parameters": {"ode.a": {"values": [-1.0, -2.0]}}}})
    table = orchestrator.sweep(spec, workers=1, quiet=True)  # no out: a temporary folder, still a DataFrame
    assert isinstance(table, pd.DataFrame) and list(table["status"]) == ["ok", "ok"]
    counts = Sweep(spec, workers=1, out=tmp_path / "kept", quiet=True).run_to_disk()
    assert counts == {"ok": 2, "failed": 0, "timeout": 0, "crashed": 0}
    assert json.loads((tmp_path / "kept" / "metadata.json").read_text())["counts"] == counts
