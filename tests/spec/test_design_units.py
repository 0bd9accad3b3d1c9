"""A design parameter's ``unit`` is converted to its port's unit, or refused (issue 28, item 3).

Before, ``"unit": "kN.m/rad"`` on a stiffness in N.m/rad was silently ignored (the unit got 1000 times too
little) and ``"unit": "A"`` on it passed ``cosim validate``.
"""

from __future__ import annotations

import json
import math

import pytest

import cosim
from cosim.cli.main import main
from tests.helpers.paths import REPO

SPRING = '''\
from cosim import PythonUnit, Variable


class TorsionSpring(PythonUnit):
    """torque = stiffness * angle, with the angle in degrees, converted by the unit itself."""
    variables = (Variable("stiffness", "parameter", unit="N.m/rad", start=100.0, max=5000.0),
                 Variable("angle", "parameter", unit="deg", start=30.0),
                 Variable("torque", "output", unit="N.m", start=0.0))

    def do_step(self, t, h):
        self.torque = self.stiffness * self.angle * 3.141592653589793 / 180.0
'''


def _spec(folder, **design):
    (folder / "spring.py").write_text(SPRING)
    spec = {"units": {"spring": {"python": "spring.py:TorsionSpring"}},
            "experiment": {"stop": 0.2, "step": 0.1},
            "objectives": {"torque": {"signal": "spring.torque", "reduce": "final", "unit": "N.m"}},
            "design": {"parameters": design}}
    path = folder / "spec.json"
    path.write_text(json.dumps(spec))
    return path


def test_a_design_unit_is_converted_to_the_ports_unit(tmp_path, local_cluster):  # noqa: F811
    spec = _spec(tmp_path, **{"spring.stiffness": {"values": [1, 2.5], "unit": "kN.m/rad"},
                              "spring.angle": {"values": [math.degrees(0.5)], "unit": "deg"}})
    assert main(["validate", str(spec)]) == 0
    df = cosim.sweep(str(spec), out=str(tmp_path / "out"), scheduler=local_cluster, quiet=True)
    by_stiffness = df.set_index("spring.stiffness")["torque"]
    assert sorted(by_stiffness.index) == [1, 2.5]  # the table keeps the values as the design writes them
    assert by_stiffness[1] == pytest.approx(1000.0 * 0.5, rel=1e-12)  # 1 kN.m/rad * 0.5 rad, in N.m
    assert by_stiffness[2.5] == pytest.approx(2500.0 * 0.5, rel=1e-12)
    assert cosim.read_results(tmp_path / "out").attrs  # written like any sweep


def test_a_design_unit_of_another_quantity_is_refused_by_validate(tmp_path, capsys):
    spec = _spec(tmp_path, **{"spring.stiffness": {"values": [1, 2], "unit": "A"}})
    assert main(["validate", str(spec)]) == 2
    err = capsys.readouterr().err
    assert "$.design.parameters.spring.stiffness.unit" in err and str(spec) in err
    assert "'A' cannot be converted to 'N.m/rad', the unit of 'spring.stiffness' (different quantities)" in err
    assert "write the range in 'N.m/rad'" in err


def test_a_unit_cosim_does_not_know_is_refused(tmp_path, capsys):
    spec = _spec(tmp_path, **{"spring.stiffness": {"min": 1, "max": 2, "step": 1, "unit": "kilonewton"}})
    assert main(["validate", str(spec)]) == 2
    assert "'kilonewton' cannot be converted to 'N.m/rad'" in capsys.readouterr().err


def test_the_ports_range_is_checked_after_conversion(tmp_path, capsys):
    """max 5000 N.m/rad: 4 kN.m/rad fits, 6 kN.m/rad does not (6 N.m/rad would have, unconverted)."""
    fits = _spec(tmp_path, **{"spring.stiffness": {"min": 1, "max": 4, "step": 1, "unit": "kN.m/rad"}})
    assert main(["validate", str(fits)]) == 0
    too_stiff = _spec(tmp_path, **{"spring.stiffness": {"min": 1, "max": 6, "step": 1, "unit": "kN.m/rad"}})
    assert main(["validate", str(too_stiff)]) == 2
    err = capsys.readouterr().err
    assert "$.design.parameters.spring.stiffness" in err and "6000" in err


def test_a_design_unit_on_a_port_without_a_unit_labels_the_values(tmp_path):
    """The Panda trajectory's waypoints are rad or deg by its `convention`: they declare no unit, and the
    pick-and-place study's "unit": "deg" is the column's label, never a conversion."""
    from cosim.spec.loader import load_spec
    from cosim.system.builder import build_system

    system = build_system(load_spec(REPO / "examples" / "pick_and_place" / "spec_coarse.json"))
    assert system.design_conversions == {}
