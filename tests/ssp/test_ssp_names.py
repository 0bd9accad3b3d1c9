"""Names SSP allows and cosim renames (issue 33, item 1): a system, component or system connector named with a
hyphen, a space, a dot or a non-ASCII letter works on every command, renamed one way (cosim.ssp.names), and a
spec may name them either way; a problem of the spec flattened from an SSP names the SSD element.

The SSP is the DC motor in the shape Dymola exports it (root 'DC-Motor', nested 'SuT', tests/helpers/ssp_fixtures.py)
around linear_ode built from src/cosim/fmus/; values are checked against dc_motor_expected (its equations).
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from cosim.cli.main import main
from cosim.errors import Problem
from cosim.ssp import read_ssp
from cosim.ssp.locate import at_ssd_elements
from cosim.ssp.names import cosim_name, rename_prefix
from tests.helpers.ssp_fixtures import dc_motor_expected, dc_motor_ssd, ensure_built, write_archive

ODD = {"sub": "Sub-System ü", "machine": "e.machine", "mass": "edrive mass", "phi": "phi-B", "gain": "k·1"}


def _dc_motor(tmp_path: Path, name: str = "dc_motor.ssp", **names: str) -> Path:
    fmu = Path(ensure_built("linear_ode", 2)).read_bytes()
    return write_archive(tmp_path / name, {"SystemStructure.ssd": dc_motor_ssd(**names).encode(),
                                           "resources/linear_ode.fmu": fmu})


def test_the_one_renaming():
    assert cosim_name("DC-Motor") == "DC_Motor"
    assert cosim_name("sub system") == "sub_system"
    assert cosim_name("Getriebe_ü") == "Getriebe__"
    assert cosim_name("1st.e.machine") == "_1st.e.machine"  # dots kept: a part each
    assert cosim_name("already_fine.x") == "already_fine.x"
    renamed = {"DC-Motor": "DC_Motor", "DC-Motor.SuT.phi-B": "DC_Motor.SuT.phi_B"}
    assert rename_prefix("DC-Motor.SuT.phi-B", renamed) == "DC_Motor.SuT.phi_B"
    assert rename_prefix("DC-Motor.k", renamed) == "DC_Motor.k"
    assert rename_prefix("DC-Motorx.k", renamed) == "DC-Motorx.k"  # a prefix ends at a dot


@pytest.mark.parametrize("names", [{}, {"sub": "sub-system"}, ODD], ids=["dymola", "sub-system", "odd"])
def test_the_dc_motor_validates_inspects_and_runs_as_exported(tmp_path, names, capsys):
    # the regression: 18 problems such as "$.units: 'DC-Motor' is not a valid name here"
    ssp = _dc_motor(tmp_path, **names)
    sub = cosim_name(names.get("sub", "SuT"))
    phi = cosim_name(names.get("phi", "phiB")).replace(".", "_")
    machine = f"{sub}.{cosim_name(names.get('machine', 'emachine_model'))}"
    mass = f"{sub}.{cosim_name(names.get('mass', 'edrive_mass'))}"
    assert main(["validate", str(ssp), "--step", "0.1"]) == 0
    assert main(["inspect", str(ssp)]) == 0
    shown = capsys.readouterr().out
    assert f"unit {mass}:" in shown and f"unit DC_Motor.{sub}: connectors" in shown
    out = tmp_path / "t.csv"
    assert main(["run", str(ssp), "--step", "0.1", "--algorithm", "jacobi", "--out", str(out)]) == 0
    traces = pd.read_csv(out)
    want = dc_motor_expected(1.0, 0.1)
    assert traces[f"{machine}.y"].iloc[-1] == pytest.approx(want["machine"], rel=1e-12)
    assert traces[f"{mass}.y"].iloc[-1] == pytest.approx(want["mass"], rel=1e-12)
    # the output connectors of both systems, by their cosim names
    assert traces[f"DC_Motor.{phi}"].iloc[-1] == pytest.approx(want["mass"], rel=1e-12)
    assert traces[f"DC_Motor.{sub}.{phi}"].iloc[-1] == pytest.approx(want["mass"], rel=1e-12)


def test_renaming_notes_name_every_renamed_element_once(tmp_path):
    system = read_ssp(_dc_motor(tmp_path, **ODD))
    notes = [n for n in system.notes if "is called" in n]
    assert notes == [
        "component 'Sub-System ü.e.machine' is called 'Sub_System__.e.machine' (names keep ASCII letters, digits, "
        "_); 1 more components renamed likewise: 'Sub_System__.edrive_mass'",
        "system 'DC-Motor' is called 'DC_Motor' (names keep ASCII letters, digits, _); 1 more systems renamed "
        "likewise: 'DC_Motor.Sub_System__'",
        "connector 'DC-Motor.phi-B' is called 'DC_Motor.phi_B' (names keep ASCII letters, digits, _); 3 more "
        "connectors renamed likewise: 'DC_Motor.k_1', 'DC_Motor.Sub_System__.phi_B', 'DC_Motor.Sub_System__.k_1'"]


def test_a_spec_names_the_ssp_either_way_in_record_objectives_and_design(tmp_path):
    import cosim

    _dc_motor(tmp_path, **ODD)
    gains = [1.0, 2.0]
    spec = {"system": "dc_motor.ssp", "experiment": {"step": 0.1, "algorithm": "jacobi"},
            "record": ["DC-Motor.Sub-System ü.e.machine.y", "Sub_System__.edrive_mass.y"],
            "objectives": {"phi": {"signal": "DC-Motor.Sub-System ü.phi-B", "reduce": "final"},
                           "machine": {"signal": "Sub-System ü.e.machine.y", "reduce": "final"}},
            "design": {"parameters": {"DC-Motor.k·1": {"values": gains}}}}
    (tmp_path / "spec.json").write_text(json.dumps(spec, ensure_ascii=False), encoding="utf-8")
    assert main(["validate", str(tmp_path / "spec.json")]) == 0
    table = cosim.sweep(str(tmp_path / "spec.json"), workers=1, quiet=True).sort_values("DC_Motor.k_1")
    assert table["DC_Motor.k_1"].tolist() == gains and (table["status"] == "ok").all()
    for gain, phi, machine in zip(gains, table["phi"], table["machine"]):
        want = dc_motor_expected(1.0, 0.1, gain)
        assert phi == pytest.approx(want["mass"], rel=1e-12)
        assert machine == pytest.approx(want["machine"], rel=1e-12)
    # --set takes the cosim name of the connector the design names
    out = tmp_path / "t.csv"
    assert main(["run", str(tmp_path / "spec.json"), "--set", "DC_Motor.k_1=2", "--out", str(out)]) == 0
    assert pd.read_csv(out)["Sub_System__.edrive_mass.y"].iloc[-1] == pytest.approx(
        dc_motor_expected(1.0, 0.1, 2.0)["mass"], rel=1e-12)


def test_the_export_of_a_renamed_system_reads_back_the_same(tmp_path):
    _dc_motor(tmp_path, **ODD)
    (tmp_path / "spec.json").write_text(json.dumps({
        "system": "dc_motor.ssp", "experiment": {"step": 0.1, "algorithm": "jacobi"},
        "objectives": {"phi": {"signal": "DC-Motor.phi-B", "reduce": "final"}}}, ensure_ascii=False),
        encoding="utf-8")
    assert main(["export", str(tmp_path / "spec.json"), "-o", str(tmp_path / "exp" / "back.ssp")]) == 0
    out = tmp_path / "back.csv"
    assert main(["run", str(tmp_path / "exp" / "back.spec.json"), "--out", str(out)]) == 0
    assert pd.read_csv(out)["Sub_System__.edrive_mass.y"].iloc[-1] == pytest.approx(
        dc_motor_expected(1.0, 0.1)["mass"], rel=1e-12)


def test_a_problem_of_the_flattened_spec_names_the_ssd_element(tmp_path):
    ssp = _dc_motor(tmp_path, **ODD)
    problems = [Problem(str(ssp), "$.units.Sub_System__.edrive_mass.parameters.b", "too big", "smaller"),
                Problem(str(ssp), "$.units.DC_Motor.Sub_System__", "bad connectors unit", "fix it"),
                Problem(str(ssp), "$.record[3]", "bad", "fix"), Problem("", "", "a usage problem", "")]
    located = at_ssd_elements(problems, ssp)
    ssd = f"{ssp}:SystemStructure.ssd"
    assert [(p.file, p.path) for p in located] == [
        (ssd, "/ssd:SystemStructureDescription[@name='DC-Motor']/ssd:System"
         "[@name='DC-Motor']/ssd:Elements/ssd:System[@name='Sub-System ü']/ssd:Elements/ssd:Component"
         "[@name='edrive mass']"),
        (ssd, "/ssd:SystemStructureDescription[@name='DC-Motor']/ssd:System"
         "[@name='DC-Motor']/ssd:Elements/ssd:System[@name='Sub-System ü']"),
        (ssd, "/ssd:SystemStructureDescription[@name='DC-Motor']/ssd:System"
         "[@name='DC-Motor']"),
        ("", "")]
    assert [p.message for p in located] == [p.message for p in problems]
