"""`cosim inspect`: the ports (name, causality, type, shape, unit, start, range) of every kind of unit."""

from __future__ import annotations

import pandas as pd
import pytest

from cosim.cli.main import main
from tests.helpers.paths import HELPERS


def rows(text: str) -> dict[str, list[str]]:
    """Port name -> the row's cells split on runs of two or more spaces (the table's column gaps)."""
    import re

    table = {}
    for line in text.splitlines():
        cells = re.split(r"\s{2,}", line.strip())
        if len(cells) >= 4 and cells[1] in ("input", "output", "parameter", "calculatedParameter", "independent"):
            table[cells[0]] = cells
    return table


def inspect(capsys, target: str) -> str:
    assert main(["inspect", target]) == 0
    return capsys.readouterr().out


def test_an_fmi2_fmu_lists_its_array_ports_once_with_shape_unit_start_and_range(capsys):
    ports = rows(inspect(capsys, "builtin:motor_gear_energy_fmi2"))
    assert ports["tau"][:5] == ["tau", "input", "Real", "7", "N.m"]
    assert "tau[1]" not in ports  # FMI 2.0 scalars tau[1]..tau[7] are the one array port tau
    assert ports["gear_ratio"][:4] == ["gear_ratio", "parameter", "Real", "7"]
    assert "(100, 100, 100, 100, ...)" in ports["gear_ratio"] and "[0, inf]" in ports["gear_ratio"]
    assert ports["e_total"][:5] == ["e_total", "output", "Real", "scalar", "J"]


def test_a_python_unit_by_file_and_by_module(capsys):
    ports = rows(inspect(capsys, f"{HELPERS / 'units_for_tests.py'}:Gain"))
    assert ports["k"] == ["k", "parameter", "Real", "scalar", "2"]
    assert ports["u"][:3] == ["u", "input", "Real"] and ports["y"][:3] == ["y", "output", "Real"]
    text = inspect(capsys, "models.motor_gear_energy:MotorGearEnergy")
    assert "Python unit" in text and rows(text)["omega"][:5] == ["omega", "input", "Real", "7", "rad/s"]
    # issue 39: a description longer than the column is cut at a word boundary ("max(electric p" before)
    assert rows(text)["recuperation"][-1] == "false: the supply takes no power back, p_el =..."


@pytest.mark.parametrize("text, width, expected", [
    ("short enough", 60, "short enough"),
    ("Signed motor speed omega * 60/(2 pi) * R", 21, "Signed motor speed..."),
    ("Signed motor speed omega * 60/(2 pi) * R", 20, "Signed motor..."),
    ("a, b; c", 6, "a..."),
    ("Supercalifragilistic word", 10, "Superca..."),
    ("two\n  lines", 60, "two lines"),
])
def test_shorten_cuts_between_words_only(text, width, expected):
    from cosim.cli.inspection import shorten

    assert shorten(text, width) == expected and len(shorten(text, width)) <= width


def test_a_recorded_table_lists_what_a_player_offers(tmp_path, capsys):
    table = tmp_path / "rec.parquet"
    pd.DataFrame({"time": [0.0, 0.1], "move.x[1]": [1.0, 2.0], "move.x[2]": [3.0, 4.0],
                  "move.v": [5.0, 6.0]}).to_parquet(table)
    ports = rows(inspect(capsys, str(table)))
    assert ports["move.x"][:4] == ["move.x", "output", "Real", "2"]
    assert ports["move.v"][:5] == ["move.v", "output", "Real", "scalar", "5"]
    assert ports["v"][:4] == ["v", "output", "Real", "scalar"]  # the short name a replacing player offers


def test_a_spec_lists_every_units_ports(write_spec, capsys):
    path = write_spec({"units": {"g": {"python": f"{HELPERS / 'units_for_tests.py'}:Gain"},
                                 "e": {"fmu": "builtin:motor_gear_energy_fmi3"}},
                       "experiment": {"stop": 0.1, "step": 0.1}})
    text = inspect(capsys, str(path))
    assert "unit g: python" in text and "unit e: FMI 3.0 builtin:motor_gear_energy_fmi3" in text
    assert {"k", "u", "y", "tau", "omega", "e_total"} <= set(rows(text))


@pytest.mark.parametrize("target, fragment", [
    ("missing.py:Unit", "no such file"), ("orchestrator:NoSuchClass", "has no class 'NoSuchClass'"),
    ("missing.fmu", "missing.fmu"), ("builtin:nope_fmi3", "no built-in FMU 'nope_fmi3'"), ("what", "spec.json"),
])
def test_what_cannot_be_inspected_is_exit_2_with_the_reason(capsys, target, fragment):
    assert main(["inspect", target]) == 2
    err = capsys.readouterr().err
    assert fragment in err and "Traceback" not in err
