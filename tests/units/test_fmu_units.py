"""FMU units through the common unit protocol: FMI 2.0 and 3.0, arrays, errors, cleanup,
and swapping the energy FMU for the Python unit with the same ports."""

from __future__ import annotations

import os

import numpy as np
import pytest

import cosim
from cosim.units.fmu.description import EXTRACTED, FmuUnitType
from cosim.units.protocol import resolve_port
from tests.helpers.tools import python_unit


@pytest.mark.parametrize("version", [2, 3])
def test_array_ports_are_the_same_in_fmi2_and_fmi3(built_fmu, version):
    unit_type = FmuUnitType(built_fmu("gain_array", version))
    d = unit_type.describe()
    assert d.variable("u").shape == (3,) and d.variable("y").shape == (3,)
    assert d.depends_on("y") == ("u",) or "u" in d.depends_on("y")
    unit = unit_type.instantiate("g")
    try:
        unit.setup(0.0, 1.0)
        unit.set_values({"k": 2.5})
        unit.enter_initialization()
        unit.set_values({"u": [1.0, -2.0, 4.0]})
        unit.exit_initialization()
        assert unit.get_values(["y"])["y"] == pytest.approx([2.5, -5.0, 10.0])
        unit.set_values({"u[2]": 8.0})  # one element of an array: the others keep their values
        assert unit.get_values(["u", "y[2]"]) == {"u": pytest.approx([1.0, 8.0, 4.0]), "y[2]": pytest.approx(20.0)}
        unit.do_step(0.0, 0.1)
        _, refs = resolve_port(d, "y[3]")
        assert unit.get(unit.select(refs)) == pytest.approx([10.0])
    finally:
        unit.terminate()


@pytest.mark.parametrize("version", [2, 3])
def test_an_fmi_error_names_unit_time_status_and_log(built_fmu, write_spec, version):
    spec = write_spec({
        "units": {"f": {"fmu": str(built_fmu("fault", version)), "parameters": {"mode": 3, "trigger_time": 0.35}}},
        "experiment": {"stop": 1.0, "step": 0.1},
        "objectives": {"y": {"signal": "f.y", "reduce": "final"}},
    })
    result = cosim.run(str(spec))
    assert result.status == "failed"
    assert f"unit 'f' at t=0.4: fmi{version}DoStep returned Error" in result.message
    assert "FMU log:" in result.message
    assert result.steps == 4


def test_nan_output_fails_the_run(built_fmu, write_spec):
    spec = write_spec({
        "units": {"f": {"fmu": str(built_fmu("fault", 3)), "parameters": {"mode": 4, "trigger_time": 0.5}}},
        "experiment": {"stop": 1.0, "step": 0.1},
        "objectives": {"y": {"signal": "f.y", "reduce": "max"}},
    })
    result = cosim.run(str(spec))
    assert result.status == "failed" and "not finite: y" in result.message


def test_units_are_terminated_and_temporary_folders_removed(built_fmu, write_spec, tmp_path):
    """A run in a fresh process leaves no extracted FMU behind, after success and after failure."""
    import subprocess
    import sys

    spec = write_spec({
        "units": {"f": {"fmu": str(built_fmu("fault", 2)), "parameters": {"mode": 3, "trigger_time": 0.2}},
                  "o": {"fmu": str(built_fmu("linear_ode", 3))}},
        "experiment": {"stop": 1.0, "step": 0.1},
    })
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    code = ("import cosim, sys, glob, os; r = cosim.run(sys.argv[1]); "
            "print(r.status, len(glob.glob(os.path.join(sys.argv[2], 'cosim_fmu_*'))))")
    out = subprocess.run([sys.executable, "-c", code, str(spec), str(tmp)], capture_output=True, text=True,
                         env={**os.environ, "TMPDIR": str(tmp)}, check=True).stdout.split()
    assert out == ["failed", "2"]  # both FMUs extracted while the process lives
    assert list(tmp.iterdir()) == []  # and removed when it exits


def test_instances_share_one_extraction_and_free_their_libraries(built_fmu):
    unit_type = FmuUnitType(built_fmu("linear_ode", 2))
    before = len(EXTRACTED._folders)
    for i in range(50):
        unit = unit_type.instantiate(f"o{i}")
        unit.setup(0.0, 1.0)
        unit.enter_initialization()
        unit.exit_initialization()
        unit.do_step(0.0, 0.1)
        unit.terminate()
        unit.terminate()  # safe to call twice
    assert len(EXTRACTED._folders) - before <= 1


def test_reset_restores_start_values(built_fmu):
    unit = FmuUnitType(built_fmu("linear_ode", 3)).instantiate("o")
    try:
        for _ in range(2):
            unit.setup(0.0, 1.0)
            unit.set_values({"x0": 2.0, "a": -1.0})
            unit.enter_initialization()
            unit.exit_initialization()
            for k in range(10):
                unit.do_step(k * 0.1, 0.1)
            assert unit.get_values(["y"])["y"] == pytest.approx(2.0 * np.exp(-1.0), rel=1e-12)
            unit.reset()
    finally:
        unit.terminate()


def energy_spec(energy_unit: dict) -> dict:
    """A drive profile from a Python source feeding the energy unit, FMU or Python."""
    return {
        "units": {
            "drive": {"python": python_unit("DriveProfile")},
            "energy": energy_unit,
        },
        "connections": [{"from": "drive.tau", "to": "energy.tau"}, {"from": "drive.omega", "to": "energy.omega"}],
        "experiment": {"stop": 2.0, "step": 0.001},
        "record": ["energy.p_total"],
        "objectives": {
            "energy": {"signal": "energy.e_total", "reduce": "final", "unit": "J"},
            "per_joint": {"signal": "energy.e_el", "reduce": "final", "unit": "J"},
            "no_recuperation": {"signal": "energy.e_total_no_recuperation", "reduce": "final", "unit": "J"},
            "peak": {"signal": "energy.p_total", "reduce": "max", "unit": "W"},
        },
    }


@pytest.mark.parametrize("energy_unit", [
    {"fmu": "builtin:motor_gear_energy_fmi2"},
    {"python": "models.motor_gear_energy:MotorGearEnergy"},
])
def test_energy_fmu_and_python_unit_are_interchangeable(write_spec, energy_unit):
    reference = cosim.run(str(write_spec(energy_spec({"fmu": "builtin:motor_gear_energy_fmi3"}), "ref.json")))
    other = cosim.run(str(write_spec(energy_spec(energy_unit), "other.json")))
    assert reference.ok and other.ok, (reference.message, other.message)
    assert reference.objectives["energy"] > 1.0  # a real, non-trivial amount of energy
    assert reference.objectives["no_recuperation"] > reference.objectives["energy"]  # braking phases exist
    assert other.objectives.keys() == reference.objectives.keys()
    for name, value in reference.objectives.items():
        assert other.objectives[name] == pytest.approx(value, rel=1e-12, abs=1e-12), name
