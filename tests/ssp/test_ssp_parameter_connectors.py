"""A system's parameter connectors are signals (issue 33, item 2): bound by a binding and feeding FMU parameters,
a root's or nested system's parameter connector can be recorded, used in an objective, shown by cosim inspect and
set with --set on the SSP alone, with the value the tool shows for it (a nested connector fed by the root's
shows the root's value).  The SSP is the DC motor in Dymola's shape (tests/helpers/ssp_fixtures.py): DC-Motor.gain
(bound to 1) feeds SuT.gain, which feeds emachine_model.b."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from cosim.cli.main import main
from tests.helpers.ssp_fixtures import dc_motor_expected, dc_motor_ssd, ensure_built, write_archive


def _dc_motor(tmp_path: Path) -> Path:
    fmu = Path(ensure_built("linear_ode", 2)).read_bytes()
    return write_archive(tmp_path / "dc_motor.ssp", {"SystemStructure.ssd": dc_motor_ssd().encode(),
                                                     "resources/linear_ode.fmu": fmu})


@pytest.mark.parametrize("gain", [None, 3.0])
def test_parameter_connectors_are_recorded_and_objectives_with_the_value_the_tool_shows(tmp_path, gain):
    _dc_motor(tmp_path)
    (tmp_path / "spec.json").write_text(json.dumps({
        "system": "dc_motor.ssp", "experiment": {"step": 0.1, "algorithm": "jacobi"},
        "record": ["DC-Motor.gain", "DC-Motor.SuT.gain", "SuT.edrive_mass.y"],
        "objectives": {"g": {"signal": "SuT.gain", "reduce": "final"}}}))
    out = tmp_path / "t.csv"
    sets = ["--set", f"DC_Motor.gain={gain}"] if gain is not None else []
    assert main(["run", str(tmp_path / "spec.json"), "--out", str(out), *sets]) == 0
    final = pd.read_csv(out).iloc[-1]
    want = gain if gain is not None else 1.0
    assert final["DC_Motor.gain"] == want and final["DC_Motor.SuT.gain"] == want
    assert final["SuT.edrive_mass.y"] == pytest.approx(dc_motor_expected(1.0, 0.1, want)["mass"], rel=1e-12)


def test_the_ssp_alone_takes_set_on_a_parameter_connector_and_inspect_shows_them(tmp_path, capsys):
    path = _dc_motor(tmp_path)
    out = tmp_path / "t.csv"
    # the regression: "unit 'DC_Motor' has no variable 'gain'"
    assert main(["run", str(path), "--step", "0.1", "--algorithm", "jacobi", "--set", "DC_Motor.gain=2",
                 "--out", str(out)]) == 0
    final = pd.read_csv(out).iloc[-1]
    want = dc_motor_expected(1.0, 0.1, 2.0)
    assert final["SuT.emachine_model.y"] == pytest.approx(want["machine"], rel=1e-12)
    assert final["DC_Motor.phiB"] == pytest.approx(want["mass"], rel=1e-12)
    capsys.readouterr()
    assert main(["inspect", str(path)]) == 0
    shown = capsys.readouterr().out
    assert "gain  parameter  Real  scalar        1 *           system connector DC_Motor.gain" in shown
    assert "system connector DC_Motor.SuT.gain" in shown
