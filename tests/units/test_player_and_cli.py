"""`cosim run` and `cosim inspect` from the command line, and the signal player:
a unit tested alone against signals recorded in the whole system."""

from __future__ import annotations

import subprocess
import sys

import pandas as pd
import pytest

from cosim.cli.main import main
from cosim.units.player import PlayerUnitType
from tests.helpers.tools import python_unit
from tests.units.test_fmu_units import energy_spec


def cosim(*args: str) -> subprocess.CompletedProcess:
    """The real console entry point, in a separate process."""
    return subprocess.run([sys.executable, "-m", "cosim.cli.main", *args], capture_output=True, text=True)


@pytest.mark.parametrize("suffix", [".parquet", ".csv"])
def test_run_prints_objectives_and_writes_traces(write_spec, tmp_path, suffix):
    spec = energy_spec({"fmu": "builtin:motor_gear_energy_fmi3"})
    spec["record"] = ["drive.*", "energy.e_total"]
    path = write_spec(spec)
    out = tmp_path / f"traces{suffix}"
    done = cosim("run", str(path), "--set", "energy.recuperation=false", "--out", str(out))
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].split() == ["objective", "value", "unit"]
    table = {line.split()[0]: line.split()[1:] for line in lines[1:] if line and not line.startswith(("status", "traces"))}
    assert table["energy"][1] == "J" and table["per_joint[7]"][1] == "J"
    assert "status: ok; 2000 steps to t=2 s" in done.stdout
    traces = pd.read_csv(out) if suffix == ".csv" else pd.read_parquet(out)
    assert list(traces.columns) == ["time"] + [f"drive.tau[{i}]" for i in range(1, 8)] + \
        [f"drive.omega[{i}]" for i in range(1, 8)] + ["energy.e_total"]
    assert len(traces) == 2001
    # without recuperation the total equals the no-recuperation energy
    assert float(table["energy"][0]) == pytest.approx(float(table["no_recuperation"][0]), rel=1e-5)
    assert traces["energy.e_total"].iloc[-1] == pytest.approx(float(table["energy"][0]), rel=1e-5)


def test_run_with_a_bad_set_is_a_usage_error(write_spec):
    path = write_spec(energy_spec({"fmu": "builtin:motor_gear_energy_fmi3"}))
    done = cosim("run", str(path), "--set", "energy.k_mm=1", "--set", "nothing")
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "--set 'nothing': write UNIT.PARAM=VALUE" in done.stderr
    done = cosim("run", str(path), "--set", "energy.k_mm=1")
    assert done.returncode == 2 and "has no variable 'k_mm'. Did you mean 'k_m'?" in done.stderr


def test_failed_run_exits_1(write_spec):
    path = write_spec({"units": {"bad": {"python": python_unit("Failing")}},
                       "experiment": {"stop": 1.0, "step": 0.1},
                       "objectives": {"y": {"signal": "bad.y", "reduce": "final"}}})
    done = cosim("run", str(path))
    assert done.returncode == 1 and "status: failed" in done.stdout and "boom" in done.stderr


def test_inspect_lists_fmu_variables_and_spec_structure(write_spec, built_fmu, capsys):
    assert main(["inspect", str(built_fmu("motor_gear_energy", 2))]) == 0
    text = capsys.readouterr().out
    assert "FMI 2.0 co-simulation" in text
    row = next(line.split() for line in text.splitlines() if line.strip().startswith("k_m "))
    assert row[:5] == ["k_m", "parameter", "Real", "7", "N.m/A"]  # the scalars k_m[1]..k_m[7] as one array
    path = write_spec(energy_spec({"fmu": "builtin:motor_gear_energy_fmi3"}))
    assert main(["inspect", str(path)]) == 0
    text = capsys.readouterr().out
    assert "unit energy: FMI 3.0 builtin:motor_gear_energy_fmi3 (2 inputs" in text
    assert "drive.tau -> energy.tau" in text and "stepping order: drive -> energy" in text


def test_energy_fmu_alone_against_recorded_signals_matches_the_whole_system(write_spec, tmp_path):
    whole = energy_spec({"fmu": "builtin:motor_gear_energy_fmi3"})
    whole["record"] = ["drive.*"]
    traces = tmp_path / "recorded.parquet"
    assert main(["run", str(write_spec(whole, "whole.json")), "--out", str(traces)]) == 0
    alone = energy_spec({"fmu": "builtin:motor_gear_energy_fmi3"})
    alone["units"]["drive"] = {"player": "recorded.parquet"}  # the one-line change
    import cosim

    a = cosim.run(str(write_spec(whole, "whole.json")), record=False)
    b = cosim.run(str(write_spec(alone, "alone.json")), record=False)
    assert a.ok and b.ok, b.message
    for name, value in a.objectives.items():
        assert b.objectives[name] == pytest.approx(value, rel=1e-12), name


@pytest.mark.parametrize("mode,expected", [("linear", [0.0, 5.0, 10.0, 15.0, 20.0, 20.0]),
                                           ("hold", [0.0, 0.0, 10.0, 10.0, 20.0, 20.0]),
                                           ("nearest", [0.0, 0.0, 10.0, 10.0, 20.0, 20.0])])
def test_player_interpolation(tmp_path, mode, expected):
    table = tmp_path / "t.csv"
    pd.DataFrame({"time": [0.0, 1.0, 2.0], "x": [0.0, 10.0, 20.0], "v[1]": [1, 2, 3], "v[2]": [4, 5, 6]}) \
        .to_csv(table, index=False)
    unit_type = PlayerUnitType(table, interpolation=mode)
    assert unit_type.describe().variable("v").shape == (2,)
    unit = unit_type.instantiate("p")
    unit.setup(0.0, 2.5)
    values = [unit.get_values(["x"])["x"]]
    for k in range(5):
        unit.do_step(k * 0.5, 0.5)
        values.append(unit.get_values(["x"])["x"])
    assert values == pytest.approx(expected)
    assert unit.get_values(["v"])["v"] == pytest.approx([3.0, 6.0])


def test_player_refuses_leaving_the_recording_when_asked(tmp_path, write_spec):
    table = tmp_path / "t.csv"
    pd.DataFrame({"time": [0.0, 1.0], "x": [0.0, 1.0]}).to_csv(table, index=False)
    path = write_spec({"units": {"p": {"player": str(table), "extrapolation": "error"}},
                       "experiment": {"stop": 2.0, "step": 0.5},
                       "objectives": {"x": {"signal": "p.x", "reduce": "final"}}})
    import cosim

    result = cosim.run(str(path))
    assert result.status == "failed" and "leaves the recorded time range [0, 1]" in result.message
