"""Units of measure: conversion factors, and connections converted (or refused) in real runs.

Expected values are computed here from the definitions of the units
(1 rpm = pi/30 rad/s, T[K] = T[degC] + 273.15, 1 mm = 0.001 m), and the
master must produce exactly ``factor * x + offset`` at every step.
"""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

import cosim
from cosim.util.quantities import IncompatibleUnits, UnitDefinition, UnknownUnit, conversion, parse_unit
from tests.helpers.tools import python_unit

RPM = math.pi / 30.0


@pytest.mark.parametrize("source, target, expected", [
    ("rpm", "rad/s", (RPM, 0.0)),
    ("degC", "K", (1.0, 273.15)),
    ("K", "degC", (1.0, -273.15)),
    ("mm", "m", (0.001, 0.0)),
    ("km/h", "m/s", (1000.0 / 3600.0, 0.0)),
    ("N.m", "J", (1.0, 0.0)),
    ("kW", "W", (1000.0, 0.0)),
    ("m/s2", "m.s-2", (1.0, 0.0)),
    ("W/(m.K)", "W.m-1.K-1", (1.0, 0.0)),
    ("deg", "rad", (math.pi / 180.0, 0.0)),
])
def test_conversion_factors(source, target, expected):
    factor, offset = conversion(source, target)
    assert factor == pytest.approx(expected[0], rel=1e-15) and offset == pytest.approx(expected[1], abs=1e-12)


def test_incompatible_and_unknown_units_are_refused_with_both_units_named():
    with pytest.raises(IncompatibleUnits, match=r"'N\.m' \(kg\.m2\.s-2\) and 'A' \(A\)"):
        conversion("N.m", "A")
    with pytest.raises(IncompatibleUnits):
        conversion("rad/s", "Hz")  # FMI counts rad as a base unit
    with pytest.raises(UnknownUnit, match="'furlong'"):
        conversion("furlong", "m")


def test_fmu_definitions_win_over_the_unit_syntax():
    own = {"rpm": UnitDefinition("rpm", (0, 0, -1, 0, 0, 0, 0, 1), 0.1)}  # a deliberately different factor
    assert conversion("rpm", "rad/s", own) == (0.1, 0.0)
    assert parse_unit("degC").offset == 273.15 and parse_unit("degC/s").offset == 0.0


def measured_spec(**connection_options) -> dict:
    return {
        "units": {"src": {"python": python_unit("MeasuredSource")}, "sink": {"python": python_unit("SiSink")}},
        "connections": [
            {"from": "src.speed", "to": "sink.omega", **connection_options},
            {"from": "src.temp", "to": "sink.temperature", **connection_options},
            {"from": "src.length", "to": "sink.x", **connection_options},
        ],
        "experiment": {"stop": 1.0, "step": 0.1},
        "record": ["src.speed", "src.temp", "src.length", "sink.omega_seen", "sink.temperature_seen", "sink.x_seen"],
    }


def test_connections_convert_rpm_degC_mm_exactly(write_spec):
    result = cosim.run(str(write_spec(measured_spec())))
    assert result.ok, result.message
    tr = result.traces
    # Gauss-Seidel: the source steps first, so at t_k the sink has received (and echoes) the source at t_k
    np.testing.assert_array_equal(tr["sink.omega_seen"].to_numpy()[1:], tr["src.speed"].to_numpy()[1:] * RPM)
    np.testing.assert_array_equal(tr["sink.temperature_seen"].to_numpy()[1:],
                                  tr["src.temp"].to_numpy()[1:] + 273.15)
    np.testing.assert_array_equal(tr["sink.x_seen"].to_numpy()[1:], tr["src.length"].to_numpy()[1:] * 0.001)
    assert tr["sink.omega_seen"].iloc[-1] == pytest.approx((600.0 + 30.0 * 1.0) * math.pi / 30.0, rel=1e-15)


def test_convert_false_passes_values_unchanged(write_spec):
    result = cosim.run(str(write_spec(measured_spec(convert=False))))
    assert result.ok, result.message
    tr = result.traces
    np.testing.assert_array_equal(tr["sink.omega_seen"].to_numpy()[1:], tr["src.speed"].to_numpy()[1:])
    np.testing.assert_array_equal(tr["sink.temperature_seen"].to_numpy()[1:], tr["src.temp"].to_numpy()[1:])


def test_rpm_into_a_real_fmu_is_converted(write_spec):
    spec = {
        "units": {"src": {"python": python_unit("MeasuredSource")},
                  "energy": {"fmu": "builtin:motor_gear_energy_fmi3"}},
        "connections": [{"from": "src.speed", "to": "energy.omega[2]"}],
        "experiment": {"stop": 0.5, "step": 0.1},
        "record": ["src.speed", "energy.omega[2]"],
    }
    result = cosim.run(str(write_spec(spec)))
    assert result.ok, result.message
    tr = result.traces
    np.testing.assert_array_equal(tr["energy.omega[2]"].to_numpy()[1:], tr["src.speed"].to_numpy()[1:] * RPM)


def test_player_columns_with_units_are_converted(write_spec, tmp_path):
    table = tmp_path / "speeds.csv"
    pd.DataFrame({"time": [0.0, 1.0], "n": [0.0, 3000.0]}).to_csv(table, index=False)
    spec = {
        "units": {"play": {"player": "speeds.csv", "units": {"n": "rpm"}}, "sink": {"python": python_unit("SiSink")}},
        "connections": [{"from": "play.n", "to": "sink.omega"}],
        "experiment": {"stop": 1.0, "step": 0.25},
        "record": ["play.n", "sink.omega_seen"],
    }
    result = cosim.run(str(write_spec(spec)))
    assert result.ok, result.message
    tr = result.traces
    np.testing.assert_array_equal(tr["sink.omega_seen"].to_numpy()[1:], tr["play.n"].to_numpy()[1:] * RPM)


def test_incompatible_connection_is_refused_by_validate(write_spec):
    spec = measured_spec()
    spec["connections"].append({"from": "src.torque", "to": "sink.current"})
    path = write_spec(spec)
    done = subprocess.run([sys.executable, "-m", "cosim.cli.main", "validate", str(path)],
                          capture_output=True, text=True)
    assert done.returncode == 2, done.stdout + done.stderr
    out = done.stdout + done.stderr
    assert "Traceback" not in out
    assert f"{path}: $.connections[3]: units do not fit (different quantities): 'src.torque' is in 'N.m', " \
           "'sink.current' is in 'A'" in out
    assert "\"convert\": false" in out
    # the fix it names works: with convert false the spec validates
    spec["connections"][3]["convert"] = False
    assert subprocess.run([sys.executable, "-m", "cosim.cli.main", "validate", str(write_spec(spec))],
                          capture_output=True, text=True).returncode == 0


def test_player_units_naming_no_column_is_refused(write_spec, tmp_path):
    (tmp_path / "t.csv").write_text("time,n\n0,1\n1,2\n")
    spec = {"units": {"play": {"player": "t.csv", "units": {"speed": "rpm"}}}, "experiment": {"stop": 1, "step": 0.5}}
    with pytest.raises(cosim.SpecError, match=r"\$\.units\.play\.player: .*'units' names speed"):
        cosim.build_system(cosim.load_spec(write_spec(spec)))


def test_a_relative_quantity_converts_without_the_offset(write_spec):
    spec = {"units": {"src": {"python": python_unit("TemperatureRise")}, "sink": {"python": python_unit("SiSink")}},
            "connections": [{"from": "src.rise", "to": "sink.temperature"}],
            "experiment": {"stop": 0.2, "step": 0.1}, "record": ["sink.temperature_seen"]}
    result = cosim.run(str(write_spec(spec)))
    assert result.ok, result.message
    assert list(result.traces["sink.temperature_seen"])[1:] == [2.0, 2.0]  # a rise of 2 degC is 2 K, not 275.15 K


def test_a_recorded_parquet_table_keeps_its_units_for_a_player(write_spec, tmp_path):
    from cosim.cli.main import main

    recording = measured_spec()
    recording["record"] = ["src.speed"]
    assert main(["run", str(write_spec(recording, "record.json")), "--out", str(tmp_path / "rec.parquet")]) == 0
    assert pd.read_parquet(tmp_path / "rec.parquet").attrs["units"] == {"src.speed": "rpm"}
    spec = {"units": {"src": {"player": "rec.parquet"}, "sink": {"python": python_unit("SiSink")}},
            "connections": [{"from": "src.speed", "to": "sink.omega"}],
            "experiment": {"stop": 1.0, "step": 0.1}, "record": ["src.speed", "sink.omega_seen"]}
    result = cosim.run(str(write_spec(spec, "replay.json")))
    assert result.ok, result.message
    tr = result.traces
    np.testing.assert_array_equal(tr["sink.omega_seen"].to_numpy()[1:], tr["src.speed"].to_numpy()[1:] * RPM)
