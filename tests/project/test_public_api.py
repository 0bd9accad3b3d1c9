"""The public API: plain typed functions, cheap to import, the same defaults as the command line."""

from __future__ import annotations

import inspect
import json
import os
import subprocess
import sys

import pandas as pd

import cosim
from tests.helpers.paths import REPO

ROOT = REPO


def test_import_loads_neither_the_engine_nor_dask_and_registers_no_exit_hook():
    code = ("import atexit, sys; before = atexit._ncallbacks(); import cosim; "
            "print(atexit._ncallbacks() - before, sorted(m for m in sys.modules if m.split('.')[0] in "
            "('dask', 'distributed', 'pandas', 'numpy', 'fmpy', 'cosim')))")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
    assert out.split(None, 1) == ["0", "['cosim']\n"]


def test_help_of_every_subcommand_imports_neither_pandas_nor_dask():
    """``cosim optimize --help`` took 1.8 s, 1.3 s of it importing pandas for the list of sampler names."""
    code = ("import sys; from cosim.cli.main import main, _parser\n"
            "names = [a for a in _parser()._subparsers._group_actions[0].choices]\n"
            "for name in names:\n"
            "    try:\n"
            "        main([name, '--help'])\n"
            "    except SystemExit:\n"
            "        pass\n"
            "print(len(names), sorted(m for m in sys.modules if m in ('pandas', 'dask', 'distributed', 'optuna')), "
            "file=sys.stderr)")
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    err = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stderr
    count, imported = err.strip().splitlines()[-1].split(" ", 1)
    assert int(count) >= 10 and imported == "[]"


def test_every_public_name_resolves_and_is_typed():
    for name in cosim.__all__:
        assert getattr(cosim, name) is not None, name
    for function in (cosim.run, cosim.sweep, cosim.optimize, cosim.sensitivity, cosim.read_results, cosim.pareto,
                     cosim.run_point):
        signature = inspect.signature(function)
        assert signature.return_annotation is not inspect.Signature.empty, function
        assert all(p.annotation is not inspect.Parameter.empty for p in signature.parameters.values()), function


def test_sweep_defaults_to_one_worker_per_core_like_the_command_line(tmp_path, write_spec):
    from cosim.cli.sweep import add_sweep_parser
    from cosim.studies.sweep import Sweep
    from tests.helpers.tools import python_unit

    assert inspect.signature(cosim.sweep).parameters["workers"].default is None
    spec = write_spec({"units": {"ode": {"python": python_unit("LinearOde")}}, "experiment": {"stop": 0.1, "step": 0.1},
                       "design": {"parameters": {"ode.a": {"values": [-1.0]}}}})
    assert Sweep(spec, out=tmp_path / "o").workers == os.cpu_count()
    import argparse

    parser = argparse.ArgumentParser()
    add_sweep_parser(parser.add_subparsers())
    assert parser.parse_args(["sweep", str(spec)]).workers is None  # the same Sweep default


def test_sweep_returns_a_dataframe_and_the_counts_stay_on_disk(tmp_path, write_spec):
    from cosim.studies.sweep import Sweep
    from tests.helpers.tools import python_unit

    spec = write_spec({"units": {"ode": {"python": python_unit("LinearOde"), "parameters": {"x0": 1.0}}},
                       "experiment": {"stop": 1.0, "step": 0.01},
                       "objectives": {"y": {"signal": "ode.y", "reduce": "final"}},
                       "design": {"parameters": {"ode.a": {"values": [-1.0, -2.0]}}}})
    table = cosim.sweep(spec, workers=1, quiet=True)  # no out: a temporary folder, still a DataFrame
    assert isinstance(table, pd.DataFrame) and list(table["status"]) == ["ok", "ok"]
    counts = Sweep(spec, workers=1, out=tmp_path / "kept", quiet=True).run_to_disk()
    assert counts == {"ok": 2, "failed": 0, "timeout": 0, "crashed": 0}
    assert json.loads((tmp_path / "kept" / "metadata.json").read_text())["counts"] == counts


def test_read_results_and_pareto_of_a_sweep_folder(tmp_path, write_spec):
    """The notebook path: sweep into a folder, read it back with its metadata, take the Pareto front."""
    from tests.helpers.tools import python_unit

    spec = write_spec({"units": {"ode": {"python": python_unit("LinearOde"), "parameters": {"x0": 1.0}}},
                       "experiment": {"stop": 1.0, "step": 0.01},
                       "objectives": {"y": {"signal": "ode.y", "reduce": "final", "sense": "minimize"},
                                      "a2": {"expr": "0 * y + 1", "sense": "minimize"}},
                       "design": {"parameters": {"ode.a": {"values": [-1.0, -2.0, -3.0]}}}})
    cosim.sweep(spec, workers=1, out=tmp_path / "out", quiet=True)
    df = cosim.read_results(tmp_path / "out")
    assert sorted(df["ode.a"]) == [-3.0, -2.0, -1.0]
    assert df.attrs["metadata"]["counts"]["ok"] == 3 and "objectives" in df.attrs["spec"]
    # y = exp(a t) at t = 1: the smallest y (a = -3) is the one non-dominated row (a2 is equal everywhere)
    front = cosim.pareto(tmp_path / "out")
    assert list(front["ode.a"]) == [-3.0]
    assert abs(float(front["y"].iloc[0]) - 0.049787068) < 1e-3
    both = cosim.pareto(tmp_path / "out", maximize=["y"])
    assert list(both["ode.a"]) == [-1.0]


def test_python_dash_m_cosim_is_the_command_line():
    out = subprocess.run([sys.executable, "-m", "cosim", "--version"], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == f"cosim {cosim.__version__}"


def test_the_old_name_still_imports_for_fmus_exported_before():
    """FMUs exported by earlier versions import orchestrator.unit: the alias maps it onto cosim's modules."""
    code = ("import orchestrator.unit as u, orchestrator.units.python as p, cosim.units.protocol as n; "
            "print(u is n, p.PythonUnit is __import__('cosim').PythonUnit, u.__name__)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["True", "True", "cosim.units.protocol"]
    # ... and says, once, when the alias goes and what to do instead
    assert done.stderr.count("FutureWarning") == 1, done.stderr
    assert "will be removed on 2027-06-01 (release 0.3): import cosim instead" in done.stderr
