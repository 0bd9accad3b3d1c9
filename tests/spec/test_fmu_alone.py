"""An FMU alone (issue 33, item 8): `cosim run|validate|inspect model.fmu` runs it by itself with its default
experiment (completed as FMPy completes it), every output recorded, --set for parameters, and --input playing a
table into its inputs.  The FMUs are built from src/cosim/fmus/ (linear_ode: der(x) = a x + b u, y = x,
integrated exactly for u held over a step); values are computed here from that equation."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import pandas as pd
import pytest

from cosim.cli.main import main
from cosim.fmus.build import ensure_built


def _fmu(tmp_path: Path, name: str = "linear_ode") -> Path:
    return Path(shutil.copy(ensure_built(name, 2), tmp_path / f"{name}.fmu"))


def test_run_and_validate_an_fmu_alone_with_its_default_experiment(tmp_path, capsys):
    fmu = _fmu(tmp_path)
    assert main(["validate", str(fmu)]) == 0  # was: "cannot read the file ... save it as UTF-8 text"
    assert "1 unit(s)" in capsys.readouterr().out
    out = tmp_path / "t.csv"
    assert main(["run", str(fmu), "--out", str(out), "--set", "linear_ode.a=-2"]) == 0
    traces = pd.read_csv(out)
    # the default experiment: stop 1 s, step 0.01 s; u = 0, x0 = 1, a = -2: y = exp(-2 t)
    assert len(traces) == 101 and list(traces.columns) == ["time", "linear_ode.y"]
    assert traces["linear_ode.y"].iloc[-1] == pytest.approx(math.exp(-2.0), rel=1e-9)
    assert main(["inspect", str(fmu)]) == 0
    assert "u     input" in capsys.readouterr().out


def test_an_input_table_is_played_into_the_fmus_inputs(tmp_path):
    fmu = _fmu(tmp_path)
    table = tmp_path / "signals.csv"
    table.write_text("time,linear_ode.u\n0,2\n1,2\n")  # as cosim run --out names a recorded input
    out = tmp_path / "t.csv"
    assert main(["run", str(fmu), "--input", str(table), "--set", "linear_ode.a=0", "--stop", "0.5",
                 "--out", str(out)]) == 0
    traces = pd.read_csv(out)
    assert traces["time"].iloc[-1] == pytest.approx(0.5)
    assert traces["linear_ode.y"].iloc[-1] == pytest.approx(1.0 + 2.0 * 0.5, rel=1e-12)  # x0 + b u t, b = 1


def test_a_table_naming_no_input_and_input_without_an_fmu_are_clear_problems(tmp_path, capsys):
    fmu = _fmu(tmp_path)
    (tmp_path / "bad.csv").write_text("time,zz\n0,1\n")
    assert main(["run", str(fmu), "--input", str(tmp_path / "bad.csv")]) == 2
    err = capsys.readouterr().err
    assert "no column of the table names an input of linear_ode.fmu (columns: zz; inputs: u)" in err
    assert "Traceback" not in err
    (tmp_path / "spec.json").write_text('{"units": {"a": {"fmu": "linear_ode.fmu"}}, '
                                        '"experiment": {"stop": 1, "step": 0.1}}')
    assert main(["run", str(tmp_path / "spec.json"), "--input", str(tmp_path / "bad.csv")]) == 2
    assert "plays a table into an FMU run alone" in capsys.readouterr().err
