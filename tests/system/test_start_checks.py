"""A spec's ``start`` values are checked against what the FMU lets an environment set, before anything runs.

An output or local the unit calculates (FMI initial="calculated") has no start value to set: a spec that set one
passed ``cosim validate`` and failed only at run time, in the FMU.  A state declared initial="exact" (decay's x,
as the Reference FMU Dahlquist declares its state) keeps being settable.
"""

from __future__ import annotations

import math

import pandas as pd
import pytest

from cosim.cli.main import main


def _spec(built_fmu, write_spec, version: int, start: dict) -> str:
    fmu = built_fmu("decay", version)
    return str(write_spec({"units": {"d": {"fmu": str(fmu), "start": start}}, "connections": [],
                           "experiment": {"stop": 1.0, "step": 0.1}, "record": ["d.x"]}))


@pytest.mark.parametrize("version", [2, 3])
def test_a_start_value_on_a_calculated_local_is_refused_by_validate(built_fmu, write_spec, capsys, version):
    spec = _spec(built_fmu, write_spec, version, {"der_x": 2.0})
    assert main(["validate", spec]) == 2
    err = capsys.readouterr().err
    assert "units.d.start" in err, err
    assert "'der_x' of unit 'd' is a local the unit calculates" in err, err
    assert "initial=\"calculated\"" in err and "remove it from 'start'" in err, err
    assert "Traceback" not in err


@pytest.mark.parametrize("version", [2, 3])
def test_a_start_value_on_a_state_declared_exact_still_runs(built_fmu, write_spec, tmp_path, version):
    spec = _spec(built_fmu, write_spec, version, {"x": 2.0})
    assert main(["validate", spec]) == 0
    out = tmp_path / "run.parquet"
    assert main(["run", spec, "--out", str(out)]) == 0
    traces = pd.read_parquet(out)
    assert traces["d.x"].iloc[0] == pytest.approx(2.0)  # the start value set, then x = 2 e^{-t}
    assert traces["d.x"].iloc[-1] == pytest.approx(2.0 * math.exp(-1.0), rel=1e-6)
