"""SSPs in the forms other tools write them (issue 25): OMSimulator 3's system connectors (startElement=""),
one-to-many .ssm, parameter connections against a component's own binding, FMUs without a binary for this platform,
relative paths of every form, and notes only where something is really missing.

Every SSP is written here: hand-written XML in tests/data/ssp/ (oms3.ssd and its .ssv/.ssm, in the form OMSimulator 3's
Python writer emits) around linear_ode built from src/cosim/fmus/; values are checked against oms3_expected, which
solves the system's equations by hand.
"""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import pytest

from cosim.cli.main import main
from cosim.errors import SpecError
from cosim.execution.run import Execution
from cosim.ssp import read_ssp
from cosim.system.validate import check_spec
from tests.helpers.ssp_fixtures import (
    SETPOINT,
    SSP_FILES,
    TABLE_COMPONENT,
    oms3_expected,
    oms3_files,
    oms3_ssd,
    table_ssd,
    write_archive,
    write_folder,
)

STEP = {"step": 0.1}


def _run(path, algorithm="jacobi", **experiment):
    system = check_spec(path, {"algorithm": algorithm, **STEP, **experiment})
    result = Execution(system, record=True).run()
    assert result.ok, result.message
    return result


def _problems(path, experiment=STEP):
    with pytest.raises(SpecError) as caught:
        check_spec(path, experiment)
    return caught.value.problems


def _final(result, column):
    return float(result.traces[column].iloc[-1])


# --- item 1: startElement="" / endElement="" name the system's own connector --------------------------------


def test_empty_start_and_end_element_name_the_systems_own_connector(tmp_path):
    ssd = oms3_ssd()
    assert 'startElement=""' in ssd and 'endElement=""' in ssd
    raw = read_ssp(write_archive(tmp_path / "oms3.ssp", oms3_files())).raw
    omitted = ssd.replace('startElement="" ', "").replace('endElement="" ', "")
    (tmp_path / "omitted").mkdir()
    again = read_ssp(write_archive(tmp_path / "omitted" / "oms3.ssp", oms3_files(omitted))).raw
    for unit in again["units"].values():
        unit["fmu"] = unit["fmu"].replace("/omitted/", "/")
    assert raw["units"] == again["units"] and raw["connections"] == again["connections"]
    assert raw["units"]["sub.B"]["parameters"] == {"a": 0.0, "b": -0.5, "x0": 0.0}
    assert raw["connections"] == [{"from": "A.y", "to": "sub.B.u", "convert": False}]


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_oms3_form_runs_as_computed_by_hand(tmp_path, algorithm):
    result = _run(write_archive(tmp_path / "oms3.ssp", oms3_files()), algorithm)
    times = result.traces["time"].to_numpy()
    assert len(times) == 11
    for column in ("A.y", "sub.B.y"):
        got = result.traces[column].to_numpy()
        want = [oms3_expected(t)[column] for t in times]
        assert got == pytest.approx(want, rel=1e-12, abs=1e-12), column


def test_an_unknown_element_still_says_how_to_name_the_systems_connector(tmp_path):
    ssd = oms3_ssd().replace('startElement="A" startConnector="y"', 'startElement="AA" startConnector="y"')
    [problem] = _problems(write_archive(tmp_path / "bad.ssp", oms3_files(ssd)))
    assert "startElement 'AA' is not an element of system" in problem.message and "Did you mean 'A'" in problem.message
    assert 'startElement=""' in problem.fix
    assert problem.path.endswith("ssd:System[@name='default']/ssd:Connections/ssd:Connection[1]")


# --- item 2: an .ssm mapping one source to several targets ------------------------------------------------


def _with_root_binding(binding: str) -> str:
    """oms3.ssd with the root's inline binding of k replaced by ``binding`` (an ssd:ParameterBinding)."""
    ssd = oms3_ssd()
    start = ssd.index("    <ssd:ParameterBindings>")
    end = ssd.index("</ssd:ParameterBindings>", start) + len("</ssd:ParameterBindings>")
    return ssd[:start] + f"    <ssd:ParameterBindings>{binding}</ssd:ParameterBindings>" + ssd[end:]


def test_one_source_mapped_to_several_targets_sets_each_with_its_own_transformation(tmp_path):
    # oms3_values.ssv: Input1 = 2; oms3_values.ssm: Input1 -> A.x0, Input1 -> sub.B.x0, Input1 -> k (x -0.25)
    ssd = _with_root_binding('<ssd:ParameterBinding source="resources/values.ssv">'
                             '<ssd:ParameterMapping source="resources/values.ssm"/></ssd:ParameterBinding>')
    members = oms3_files(ssd, **{"resources/values.ssv": (SSP_FILES / "oms3_values.ssv").read_bytes(),
                                 "resources/values.ssm": (SSP_FILES / "oms3_values.ssm").read_bytes()})
    system = read_ssp(write_archive(tmp_path / "map.ssp", members))
    units = system.raw["units"]
    assert units["A"]["parameters"]["x0"] == 2.0  # the root's binding beats A's own x0 = 2.0 (same value)
    assert units["sub.B"]["parameters"]["x0"] == 2.0  # beats B's own 0.0
    assert units["sub.B"]["parameters"]["b"] == -0.5  # k = -0.25 * 2, through the parameter connection
    result = _run(write_archive(tmp_path / "map2.ssp", members))
    assert _final(result, "sub.B.y") == pytest.approx(oms3_expected(1.0, x0_b=2.0)["sub.B.y"], rel=1e-12)


# --- item 3: a parameter connection carries the higher system's value -------------------------------------


def test_a_parameter_connection_beats_the_components_own_binding_with_a_note(tmp_path):
    system = read_ssp(write_archive(tmp_path / "oms3.ssp", oms3_files()))
    assert system.raw["units"]["sub.B"]["parameters"] == {"a": 0.0, "b": -0.5, "x0": 0.0}
    [note] = [n for n in system.notes if "overrides" in n]
    assert "'sub.B.b'" in note and "-0.5" in note and "system connector 'k'" in note and "0.05" in note
    assert "bound by 'sub.B'" in note


def test_a_parameter_connection_beats_the_components_own_ssv_file(tmp_path):
    own = ('<ssd:ParameterBindings><ssd:ParameterBinding source="resources/B.ssv"/></ssd:ParameterBindings>')
    ssd = oms3_ssd()
    start = ssd.index("            <ssd:ParameterBindings>")
    end = ssd.index("</ssd:ParameterBindings>", start) + len("</ssd:ParameterBindings>")
    ssd = ssd[:start] + own + ssd[end:]
    ssv = (SSP_FILES / "oms3_values.ssv").read_text().replace('name="Input1"', 'name="b"').replace('value="2.0"', 'value="0.05"')
    system = read_ssp(write_archive(tmp_path / "ssv.ssp", oms3_files(ssd, **{"resources/B.ssv": ssv.encode()})))
    assert system.raw["units"]["sub.B"]["parameters"]["b"] == -0.5
    assert any("overrides" in n and "resources/B.ssv" in n for n in system.notes)


def test_without_a_value_on_the_system_connector_the_components_own_binding_holds(tmp_path):
    ssd = _with_root_binding("")  # k has no value now
    ssd = ssd.replace("    <ssd:ParameterBindings></ssd:ParameterBindings>", "")
    system = read_ssp(write_archive(tmp_path / "nok.ssp", oms3_files(ssd)))
    assert system.raw["units"]["sub.B"]["parameters"]["b"] == 0.05
    result = _run(write_archive(tmp_path / "nok2.ssp", oms3_files(ssd)))
    assert _final(result, "sub.B.y") == pytest.approx(oms3_expected(1.0, b_b=0.05)["sub.B.y"], rel=1e-12)


def test_a_direct_binding_of_a_higher_system_beats_the_parameter_connection(tmp_path):
    # the root binds sub.B.b = 3 directly and k = -0.5 (fed to sub.B.b through sub.gain): the same system
    # binds it both ways, so the direct binding is kept, with a note
    ssd = oms3_ssd().replace('<ssv:Parameter name="k">', '<ssv:Parameter name="sub.B.b"><ssv:Real value="3.0"/>'
                             '</ssv:Parameter><ssv:Parameter name="k">', 1)
    system = read_ssp(write_archive(tmp_path / "tie.ssp", oms3_files(ssd)))
    assert system.raw["units"]["sub.B"]["parameters"]["b"] == 3.0
    assert any("bound directly" in n and "'sub.B.b'" in n for n in system.notes)


# --- item 4: an FMU without a binary for this platform -----------------------------------------------------


def _without_binaries(fmu: bytes) -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(fmu)) as source, zipfile.ZipFile(out, "w") as target:
        for info in source.infolist():
            if not info.filename.startswith("binaries/"):
                target.writestr(info, source.read(info))
    return out.getvalue()


def test_an_fmu_without_a_binary_for_this_platform_is_a_problem_at_its_component(tmp_path, capsys):
    members = oms3_files()
    members["resources/linear_ode.fmu"] = _without_binaries(members["resources/linear_ode.fmu"])
    path = write_archive(tmp_path / "nobin.ssp", members)
    problems = _problems(path)
    assert [p.path.rsplit("/", 1)[-1] for p in problems] == ["ssd:Component[@name='A']", "ssd:Component[@name='B']"]
    assert all(p.file == f"{path}:SystemStructure.ssd" for p in problems)
    assert "FMU 'resources/linear_ode.fmu' cannot be used" in problems[0].message
    assert "binar" in problems[0].message and problems[0].fix
    assert main(["validate", str(path), "--step", "0.1"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "ssd:Component[@name='A']" in err


def test_an_fmu_that_is_no_zip_is_a_problem_not_a_traceback(tmp_path, capsys):
    members = oms3_files()
    members["resources/linear_ode.fmu"] = b"not a zip archive"
    path = write_archive(tmp_path / "nozip.ssp", members)
    assert main(["validate", str(path), "--step", "0.1"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "ssd:Component[@name='A']" in err


# --- item 5: relative paths with a folder part -------------------------------------------------------------


def test_every_path_form_reads_the_same_system(tmp_path, monkeypatch):
    members = oms3_files()
    write_folder(tmp_path / "sub" / "x", members)
    write_folder(tmp_path / "sub" / "y", {**members, "other.ssd": members.pop("SystemStructure.ssd")})
    write_archive(tmp_path / "sub" / "x.ssp", oms3_files())
    monkeypatch.chdir(tmp_path)
    expected = oms3_expected(1.0)["sub.B.y"]
    for given in ("sub/x", "sub/x/SystemStructure.ssd", "sub/y/other.ssd", "sub/x.ssp", "./sub/x/"):
        assert _final(_run(given), "sub.B.y") == pytest.approx(expected, rel=1e-12), given
    monkeypatch.chdir(tmp_path / "sub" / "x")
    assert _final(_run("."), "sub.B.y") == pytest.approx(expected, rel=1e-12)
    assert main(["validate", ".", "--step", "0.1"]) == 0


# --- item 9: notes only for what is really missing; units in brackets ---------------------------------------


def test_no_note_about_a_missing_step_when_the_command_line_gives_it(tmp_path, capsys, caplog):
    ssd = oms3_ssd().replace('fixedStepSize="0.1"', 'fixedStep_removed="0.1"')
    path = write_archive(tmp_path / "nostep.ssp", oms3_files(ssd))
    assert main(["validate", str(path), "--step", "0.1", "--stop", "1"]) == 0
    captured = capsys.readouterr()
    assert "step size" not in captured.err and "stop time" not in captured.err
    # without --step: OMSimulator's default step (issue 33 item 3), said once
    assert main(["validate", str(path)]) == 0
    err = "\n".join(r.getMessage() for r in caplog.records)
    assert err.count("the SSP gives no step size") == 1 and "run with OMSimulator's defaults, step 0.001 s" in err


def test_a_unit_in_brackets_is_read_without_them_with_one_note(tmp_path):
    # issue 33 item 4: OMSimulator sets the value and keeps the unit as written; cosim reads '[1/min]' as 1/min
    # and converts to the connector's 1/s: -30 1/min = -0.5 1/s, the value oms3.ssd binds itself
    ssd = oms3_ssd().replace('<ssv:Real value="-0.5"/>', '<ssv:Real value="-30" unit="[1/min]"/>')
    ssd = ssd.replace('<ssd:Connector name="k" kind="parameter">\n        <ssc:Real/>',
                      '<ssd:Connector name="k" kind="parameter">\n        <ssc:Real unit="1/s"/>')
    path = write_archive(tmp_path / "brackets.ssp", oms3_files(ssd))
    notes = [n for n in read_ssp(path).notes if "written in brackets" in n]
    assert len(notes) == 1 and notes[0].endswith(
        "ssv:Parameter[@name='k']/ssv:Real: unit '[1/min]' is written in brackets (as tools show units); SSP and "
        "FMI write '1/min': read as such"), notes
    result = _run(path)
    assert _final(result, "sub.B.y") == pytest.approx(oms3_expected(1.0)["sub.B.y"], rel=1e-12)


# --- item 6: inspect of every SSP form, without stop time or step size, showing the bound values ------------


def _port_rows(text: str) -> dict[str, dict[str, list[str]]]:
    """unit -> port -> the row's cells (split on the table's gaps of two or more spaces)."""
    import re

    units: dict[str, dict[str, list[str]]] = {}
    current = None
    for line in text.splitlines():
        if line.startswith("unit "):
            current = units.setdefault(line.split()[1].rstrip(":"), {})
        elif current is not None and line.startswith("  "):
            cells = re.split(r"\s{2,}", line.strip())
            current[cells[0]] = cells
    return units


def test_inspect_reads_every_ssp_form_without_stop_or_step_and_shows_the_bound_values(tmp_path, monkeypatch,
                                                                                    capsys):
    ssd = oms3_ssd().replace('fixedStepSize="0.1"', 'fixedStep_removed="0.1"').replace(' stopTime="1.0"', "")
    members = oms3_files(ssd)
    write_archive(tmp_path / "x.ssp", members)
    write_folder(tmp_path / "x", members)
    monkeypatch.chdir(tmp_path)
    for given in ("x.ssp", "x", "x/SystemStructure.ssd", "."):
        if given == ".":
            monkeypatch.chdir(tmp_path / "x")
        assert main(["inspect", given]) == 0, given
        out = capsys.readouterr().out
        ports = _port_rows(out)
        # sub.B's own binding says b = 0.05; the root's k = -0.5 reaches it through the parameter connection
        assert ports["sub.B"]["b"][:2] == ["b", "parameter"] and ports["sub.B"]["b"][4] == "-0.5 *", out
        assert ports["A"]["x0"][4] == "2 *" and ports["A"]["u"][4] == "0"  # u: the FMU's own start, unmarked
        assert "experiment: 0 .. 1 s, step 0.001 s" in out  # OMSimulator's defaults (issue 33 item 3)
        assert "note: 'sub.B.b': -0.5 from system connector 'k'" in out
    assert main(["inspect", ".", "--stop", "2", "--step", "0.5"]) == 0
    assert "experiment: 0 .. 2 s, step 0.5 s" in capsys.readouterr().out


def test_inspect_of_a_spec_shows_the_values_it_sets(tmp_path, capsys):
    import json

    write_archive(tmp_path / "x.ssp", oms3_files())
    (tmp_path / "spec.json").write_text(json.dumps({"system": "x.ssp", "units": {"A": {"parameters": {"x0": 7.5}}},
                                                    "experiment": {"step": 0.1}}))
    assert main(["inspect", str(tmp_path / "spec.json")]) == 0
    ports = _port_rows(capsys.readouterr().out)
    assert ports["A"]["x0"][4] == "7.5 *" and ports["sub.B"]["b"][4] == "-0.5 *"


# --- item 14: tolerated forms, each read with one note naming the file and the standard's form --------------


def _inline_mapping_ssd(version: str = "") -> str:
    """oms3.ssd whose root binds Input1 = 2 inline, with an inline .ssm (OMSimulator 3 writes it without version)
    mapping it to A.x0, sub.B.x0 and (x -0.25) to k."""
    ssm = (SSP_FILES / "oms3_values.ssm").read_text()
    entries = ssm[ssm.index("<ssm:MappingEntry"):ssm.index("</ssm:ParameterMapping>")]
    return _with_root_binding(
        '<ssd:ParameterBinding><ssd:ParameterValues><ssv:ParameterSet version="2.0" name="parameters">'
        '<ssv:Parameters><ssv:Parameter name="Input1"><ssv:Real value="2.0"/></ssv:Parameter></ssv:Parameters>'
        f'</ssv:ParameterSet></ssd:ParameterValues><ssd:ParameterMapping><ssm:ParameterMapping{version}>{entries}'
        '</ssm:ParameterMapping></ssd:ParameterMapping></ssd:ParameterBinding>')


def test_an_inline_mapping_without_version_is_read_with_a_note(tmp_path):
    path = write_archive(tmp_path / "noversion.ssp", oms3_files(_inline_mapping_ssd()))
    system = read_ssp(path)
    parameters = system.raw["units"]["sub.B"]["parameters"]
    assert (parameters["x0"], parameters["b"]) == (2.0, -0.5)  # one-to-many, inline
    [note] = [n for n in system.notes if "has no 'version'" in n]
    assert note.startswith(f"{path}:SystemStructure.ssd: /ssd:SystemStructureDescription[@name='default']")
    assert "ssm:ParameterMapping has no 'version' (SSP requires version=\"1.0\" or \"2.0\"); read as version 2.0" in note
    result = _run(path)
    assert _final(result, "sub.B.y") == pytest.approx(oms3_expected(1.0, x0_b=2.0)["sub.B.y"], rel=1e-12)
    with_version = read_ssp(write_archive(tmp_path / "v.ssp", oms3_files(_inline_mapping_ssd(' version="2.0"'))))
    assert not [n for n in with_version.notes if "has no 'version'" in n]


def test_parameter_files_without_version_are_read_with_a_note(tmp_path):
    ssd = _with_root_binding('<ssd:ParameterBinding source="resources/values.ssv">'
                             '<ssd:ParameterMapping source="resources/values.ssm"/></ssd:ParameterBinding>')
    ssv = (SSP_FILES / "oms3_values.ssv").read_bytes().replace(b' version="2.0"', b"")
    ssm = (SSP_FILES / "oms3_values.ssm").read_bytes().replace(b' version="2.0"', b"")
    system = read_ssp(write_archive(tmp_path / "files.ssp", oms3_files(
        ssd, **{"resources/values.ssv": ssv, "resources/values.ssm": ssm})))
    assert system.raw["units"]["sub.B"]["parameters"]["b"] == -0.5
    notes = [n for n in system.notes if "has no 'version'" in n]
    assert len(notes) == 2 and {n.split(": ")[0].rsplit(":", 1)[1] for n in notes} == {"resources/values.ssv",
                                                                                       "resources/values.ssm"}


def test_a_components_own_ssv_naming_component_dot_param_is_read_with_one_note(tmp_path):
    # OMSimulator's whole-model .ssv template names 'A.x0'; bound to component A, SSP would name it 'x0'
    ssv = ('<?xml version="1.0" encoding="utf-8"?>\n<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/'
           'SystemStructureParameterValues" version="2.0" name="parameters"><ssv:Parameters>'
           '<ssv:Parameter name="A.x0"><ssv:Real value="4.0"/></ssv:Parameter>'
           '<ssv:Parameter name="A.b"><ssv:Real value="0.0"/></ssv:Parameter>'
           '</ssv:Parameters></ssv:ParameterSet>')
    ssd = oms3_ssd().replace(
        '        </ssd:ParameterBindings>\n      </ssd:Component>\n      <ssd:System name="sub">',
        '          <ssd:ParameterBinding source="resources/A.ssv"/>\n        </ssd:ParameterBindings>\n'
        '      </ssd:Component>\n      <ssd:System name="sub">', 1)
    path = write_archive(tmp_path / "prefixed.ssp", oms3_files(ssd, **{"resources/A.ssv": ssv.encode()}))
    system = read_ssp(path)
    assert system.raw["units"]["A"]["parameters"]["x0"] == 4.0  # the later binding at one level wins
    [note] = [n for n in system.notes if "component's name" in n]
    assert note.startswith(f"{path}:resources/A.ssv names the parameters of component 'A'")
    assert "SSP names them relative to the component ('x0')" in note
    result = _run(path)
    assert _final(result, "sub.B.y") == pytest.approx(oms3_expected(1.0, x0_a=4.0)["sub.B.y"], rel=1e-12)


def test_two_parameter_bindings_and_annotations_first_are_read_in_the_schemas_order(tmp_path):
    # OMSimulator 3 writes inline values and .ssv references as two sibling ssd:ParameterBindings; OMSimulator 2
    # put the system's ssd:Annotations before its ssd:Connectors
    ssv = (SSP_FILES / "oms3_values.ssv").read_text().replace('name="Input1"', 'name="x0"').replace(
        'value="2.0"', 'value="6.0"')
    ssd = oms3_ssd().replace(
        '        </ssd:ParameterBindings>\n      </ssd:Component>\n      <ssd:System name="sub">',
        '        </ssd:ParameterBindings>\n        <ssd:ParameterBindings><ssd:ParameterBinding '
        'source="resources/A.ssv"/></ssd:ParameterBindings>\n      </ssd:Component>\n      <ssd:System name="sub">', 1)
    annotations = ssd[ssd.index("    <ssd:Annotations>\n      <ssc:Annotation type=\"org.openmodelica\">"):
                      ssd.index("  </ssd:System>\n  <ssd:DefaultExperiment")]
    ssd = ssd.replace(annotations, "").replace('  <ssd:System name="default">\n',
                                               '  <ssd:System name="default">\n' + annotations, 1)
    path = write_archive(tmp_path / "order.ssp", oms3_files(ssd, **{"resources/A.ssv": ssv.encode()}))
    system = read_ssp(path)
    assert system.raw["units"]["A"]["parameters"]["x0"] == 6.0  # the .ssv comes later: it wins over inline 2.0
    [two] = [n for n in system.notes if "ssd:ParameterBindings;" in n]
    assert "ssd:Component[@name='A'] has 2 ssd:ParameterBindings; SSP allows one" in two
    [order] = [n for n in system.notes if "order the schema does not give" in n]
    assert "ssd:System[@name='default'] has its children in an order the schema does not give (ssd:Annotations before " \
           "ssd:Connectors); SSP 2.0 expects Connectors, ElementGeometry, ParameterBindings" in order
    assert all(n.startswith(f"{path}:SystemStructure.ssd: ") for n in (two, order))
    result = _run(path)
    assert _final(result, "sub.B.y") == pytest.approx(oms3_expected(1.0, x0_a=6.0)["sub.B.y"], rel=1e-12)


def test_what_stays_wrong_after_the_tolerated_corrections_is_reported_on_the_users_file(tmp_path):
    # annotations first (tolerated) and a connector kind the standard does not know (not): the original's problems
    ssd = oms3_ssd().replace('<ssd:Connector name="out" kind="output">', '<ssd:Connector name="out" kind="sideways">')
    annotations = ssd[ssd.index("    <ssd:Annotations>\n      <ssc:Annotation type=\"org.openmodelica\">"):
                      ssd.index("  </ssd:System>\n  <ssd:DefaultExperiment")]
    ssd = ssd.replace(annotations, "").replace('  <ssd:System name="default">\n',
                                               '  <ssd:System name="default">\n' + annotations, 1)
    problems = _problems(write_archive(tmp_path / "still.ssp", oms3_files(ssd)))
    assert any("'ssd:Connectors': This element is not expected" in p.message for p in problems)
    assert all("breaks the SSP schema" in p.message for p in problems)
    ssd = ssd.replace('kind="sideways"', 'kind="output"')
    assert read_ssp(write_archive(tmp_path / "fine.ssp", oms3_files(ssd))).raw["units"]


def test_an_enumeration_value_given_as_its_integer_is_read_with_a_note(tmp_path):
    ssd = oms3_ssd().replace('<ssv:Real value="-0.5"/>', '<ssv:Enumeration value="3"/>')
    system = read_ssp(write_archive(tmp_path / "enum.ssp", oms3_files(ssd)))
    assert any("gives the enumeration value as the integer 3; SSP gives the item's name" in n for n in system.notes)


# --- item 13: implementation and OMSimulator's solver annotations --------------------------------------------

_CVODE_ASSIGNED = ('        <ssd:Annotations>\n          <ssc:Annotation type="org.openmodelica">\n'
                   '            <oms:Annotations>\n              <oms:SimulationInformation name="solver2"/>\n'
                   '            </oms:Annotations>\n          </ssc:Annotation>\n        </ssd:Annotations>\n')
_A_END = '      </ssd:Component>\n      <ssd:System name="sub">'


def _solver_ssd() -> str:
    """oms3.ssd with OMSimulator 3 solvers: A (implementation ModelExchange) assigned cvode 'solver2', B
    CoSimulation, two oms_ma masters of 0.1 s and 0.05 s."""
    ssd = oms3_ssd().replace(_A_END, _CVODE_ASSIGNED + _A_END, 1)
    ssd = ssd.replace('source="resources/linear_ode.fmu" implementation="any">',
                      'source="resources/linear_ode.fmu" implementation="ModelExchange">', 1)
    ssd = ssd.replace('source="resources/linear_ode.fmu" implementation="any">',
                      'source="resources/linear_ode.fmu" implementation="CoSimulation">', 1)
    return ssd.replace(
        '<oms:SimulationInformation name="solver1" method="oms_ma" fixedStepSize="0.1"/>',
        '<oms:SimulationInformation name="solver1" method="oms_ma" fixedStepSize="0.1"/>\n'
        '          <oms:SimulationInformation name="solver2" method="cvode" relativeTolerance="0.0001" '
        'initialStepSize="1e-06" minimumStepSize="1e-12" maximumStepSize="0.001"/>\n'
        '          <oms:SimulationInformation name="solver3" method="oms_ma" fixedStepSize="0.05"/>')


def test_implementation_and_solver_annotations_become_interface_tolerance_max_step_and_step(tmp_path):
    path = write_archive(tmp_path / "solvers.ssp", oms3_files(_solver_ssd()))
    system = read_ssp(path)
    units = system.raw["units"]
    assert (units["A"]["interface"], units["A"]["tolerance"], units["A"]["max_step"]) == ("model-exchange", 1e-4,
                                                                                          1e-3)
    assert units["sub.B"]["interface"] == "co-simulation" and "tolerance" not in units["sub.B"]
    assert system.raw["experiment"]["step"] == 0.05
    assert any("several steps (0.1, 0.05): cosim steps every unit with the smallest, 0.05 s" in n
               for n in system.notes)
    [unread] = [n for n in system.notes if "not read (cosim's CVode" in n]
    assert unread.startswith("solver 'solver2': initialStepSize, minimumStepSize not read")
    result = Execution(check_spec(path), record=True).run()  # the SSP's own step: no --step
    assert result.ok and len(result.traces) == 21
    expected = [oms3_expected(t)["sub.B.y"] for t in result.traces["time"]]
    assert result.traces["sub.B.y"].to_numpy() == pytest.approx(expected, rel=1e-12, abs=1e-12)
    assert result.traces["A.y"].to_numpy() == pytest.approx(2.0, rel=1e-9)  # A integrated by CVode: dx/dt = 0


def test_oms2_solver_forms_and_osp_step_hints(tmp_path):
    # OMSimulator 2: a VariableStepSolver on the system of a ModelExchange component, a variable-step master
    ssd = oms3_ssd().replace('source="resources/linear_ode.fmu" implementation="any">',
                             'source="resources/linear_ode.fmu" implementation="ModelExchange">', 1)
    ssd = ssd.replace(
        '<oms:SimulationInformation name="solver1" method="oms_ma" fixedStepSize="0.1"/>',
        '<oms:SimulationInformation><oms:VariableStepSolver description="cvode" absoluteTolerance="0.0001" '
        'relativeTolerance="0.001" minimumStepSize="1e-08" maximumStepSize="0.01" initialStepSize="0.001"/>'
        '<oms:FixedStepMaster description="oms-ma" stepSize="0.1"/></oms:SimulationInformation>')
    ssd = ssd.replace(_A_END, '        <ssd:Annotations><ssc:Annotation type="com.opensimulationplatform">'
                      '<osp:StepSizeHint xmlns:osp="http://opensimulationplatform.com/SSP/OSPAnnotations" '
                      'value="0.05"/></ssc:Annotation><ssc:Annotation type="com.example.layout"><x/></ssc:Annotation>'
                      '</ssd:Annotations>\n' + _A_END, 1)
    system = read_ssp(write_archive(tmp_path / "oms2.ssp", oms3_files(ssd)))
    a = system.raw["units"]["A"]
    assert (a["interface"], a["tolerance"], a["max_step"]) == ("model-exchange", 1e-3, 1e-2)
    assert system.raw["experiment"]["step"] == 0.1
    assert "OSP step size hints ignored (A 0.05 s): cosim steps every unit with one communication step" in system.notes
    assert "annotations of type 'com.example.layout' are not read" in system.notes
    assert ("solver 'root cvode': initialStepSize, minimumStepSize, absoluteTolerance not read (cosim's CVode takes "
            "a relative tolerance and a maximum step)") in system.notes


def test_solver_assignments_cosim_cannot_follow_are_notes_or_problems(tmp_path):
    ssd = _solver_ssd().replace('<oms:SimulationInformation name="solver2"/>',
                                '<oms:SimulationInformation name="nosuch"/>')
    system = read_ssp(write_archive(tmp_path / "unknown.ssp", oms3_files(ssd)))
    assert "component 'A' is assigned solver 'nosuch', which no system defines: ignored" in system.notes
    assert system.raw["units"]["A"]["interface"] == "model-exchange"  # implementation="ModelExchange" still holds

    ssd = _solver_ssd().replace('implementation="ModelExchange"', 'implementation="ScheduledExecution"')
    [problem] = _problems(write_archive(tmp_path / "scheduled.ssp", oms3_files(ssd)))
    assert 'implementation="ScheduledExecution" is not supported' in problem.message
    assert problem.path.endswith("ssd:Component[@name='A']")

    # an FMU offering only co-simulation asked to run as model exchange: a problem at its component
    from cosim.fmus.build import ensure_built

    ssd = oms3_ssd().replace('<ssd:Component name="A" type="application/x-fmu-sharedlibrary" '
                             'source="resources/linear_ode.fmu" implementation="any">',
                             '<ssd:Component name="C" type="application/x-fmu-sharedlibrary" '
                             'source="resources/gain_array.fmu" implementation="ModelExchange"/>'
                             '<ssd:Component name="A" type="application/x-fmu-sharedlibrary" '
                             'source="resources/linear_ode.fmu" implementation="any">')
    members = oms3_files(ssd, **{"resources/gain_array.fmu": Path(ensure_built("gain_array", 2)).read_bytes()})
    [problem] = _problems(write_archive(tmp_path / "csonly.ssp", members))
    assert problem.path.endswith("ssd:Component[@name='C']")
    assert "FMU 'resources/gain_array.fmu' cannot be used" in problem.message and "co-simulation" in problem.message


# --- item 11: a CSV table as a component, played ------------------------------------------------------------

def _setpoint(t: float) -> float:
    """The table, interpolated linearly by hand."""
    return 0.0 if t <= 0.5 else (t - 0.5 if t <= 1.5 else 1.0)


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_a_csv_component_is_played_into_the_system(tmp_path, algorithm):
    members = oms3_files(table_ssd(), **{"resources/setpoint.csv": SETPOINT})
    path = write_archive(tmp_path / "table.ssp", members)
    raw = read_ssp(path).raw
    assert raw["units"]["setpoint"] == {"player": f"{path.resolve()}!/resources/setpoint.csv",
                                        "interpolation": "linear", "all_real": True, "columns": ["speed"]}
    assert {"from": "setpoint.speed", "to": "sub.B.u", "convert": False} in raw["connections"]
    h, b = 0.1, -0.5  # sub.B integrates b * u exactly for u held over each step, from x0 = 0
    times = [k * h for k in range(11)]
    expected, y = [0.0], 0.0
    for k in range(10):  # Jacobi: B steps from the table's value at the start of the step; Gauss-Seidel: the end
        y += h * b * _setpoint(times[k] if algorithm == "jacobi" else times[k + 1])
        expected.append(y)
    for given in (path, write_folder(tmp_path / algorithm, members) / "SystemStructure.ssd"):
        result = _run(given, algorithm)
        assert result.traces["sub.B.y"].to_numpy() == pytest.approx(expected, rel=1e-12, abs=1e-15)
        assert result.traces["setpoint.speed"].to_numpy() == pytest.approx([_setpoint(t) for t in times], abs=1e-12)


def test_table_components_cosim_cannot_play_are_problems_at_their_element(tmp_path):
    members = oms3_files(table_ssd().replace("resources/setpoint.csv", "resources/Gain_res.mat"),
                         **{"resources/Gain_res.mat": b"MATLAB 5.0"})
    [problem] = _problems(write_archive(tmp_path / "mat.ssp", members))
    assert "table 'resources/Gain_res.mat' is no CSV file" in problem.message and "CSV" in problem.fix
    assert problem.path.endswith("ssd:Component[@name='setpoint']")

    ssd = table_ssd().replace('<ssd:Connector name="speed" kind="output">', '<ssd:Connector name="sped" kind="output">')
    ssd = ssd.replace('startConnector="speed" endElement="sub"', 'startConnector="sped" endElement="sub"')
    [problem] = _problems(write_archive(tmp_path / "col.ssp", oms3_files(ssd, **{"resources/setpoint.csv": SETPOINT})))
    assert "connector 'sped' is not a column of resources/setpoint.csv" in problem.message
    assert "Did you mean 'speed'" in problem.message

    members = oms3_files(table_ssd(), **{"resources/setpoint.csv": b"t,speed\n0,1\n"})
    [problem] = _problems(write_archive(tmp_path / "notime.ssp", members))
    assert "cannot read table 'resources/setpoint.csv'" in problem.message and "'time'" in problem.message


# --- item 12: several SSDs in one SSP (variants) ------------------------------------------------------------


def _variants(tmp_path):
    """An archive as OMSimulator 3 exports two variants: SystemStructure.ssd (name="default") and one more .ssd at
    the root (name="Variant-B", its root system still called "default") where A starts at x0 = 3 instead of 2;
    here the file is variant_b.ssd, so that the variant's name and its file's stem differ."""
    variant_b = oms3_ssd().replace('name="default" version="2.0"', 'name="Variant-B" version="2.0"', 1).replace(
        '<ssv:Parameter name="x0">\n                    <ssv:Real value="2.0"/>',
        '<ssv:Parameter name="x0">\n                    <ssv:Real value="3.0"/>', 1)
    assert variant_b.count('value="3.0"') == 1
    return write_archive(tmp_path / "variants.ssp", oms3_files(**{"variant_b.ssd": variant_b.encode()}))


def test_a_variant_is_chosen_by_name_on_the_command_line_and_in_a_spec(tmp_path, capsys):
    import json

    path = _variants(tmp_path)
    default = _run(path)
    assert _final(default, "sub.B.y") == pytest.approx(oms3_expected(1.0)["sub.B.y"], rel=1e-12)
    system = check_spec(path, {**STEP, "algorithm": "jacobi"}, "Variant-B")
    assert system.spec.name == "Variant-B"
    result = Execution(system, record=True).run()
    assert _final(result, "sub.B.y") == pytest.approx(oms3_expected(1.0, x0_a=3.0)["sub.B.y"], rel=1e-12)
    assert check_spec(path, STEP, "variant_b").units["A"].spec.parameters["x0"] == 3.0  # by the file stem too
    assert main(["run", str(path), "--variant", "Variant-B", "--step", "0.1"]) == 0

    (tmp_path / "spec.json").write_text(json.dumps({"system": {"ssp": "variants.ssp", "variant": "Variant-B"},
                                                    "experiment": {"step": 0.1, "algorithm": "jacobi"},
                                                    "objectives": {"y": {"signal": "sub.B.y", "reduce": "final"}}}))
    import cosim

    assert cosim.run(tmp_path / "spec.json").objectives["y"] == pytest.approx(
        oms3_expected(1.0, x0_a=3.0)["sub.B.y"], rel=1e-12)

    capsys.readouterr()
    assert main(["inspect", str(path), "--variant", "Variant-B"]) == 0
    out = capsys.readouterr().out
    assert "variants: default (SystemStructure.ssd), Variant-B (variant_b.ssd, shown)" in out
    assert _port_rows(out)["A"]["x0"][4] == "3 *"


def test_an_unknown_variant_is_a_problem_listing_the_variants(tmp_path, capsys):
    path = _variants(tmp_path)
    assert main(["validate", str(path), "--variant", "Variant-C", "--step", "0.1"]) == 2
    err = capsys.readouterr().err
    assert "the SSP has no variant 'Variant-C'; its variants: default (" in err and "Variant-B (" in err
    assert "Did you mean 'Variant-B'" in err and "Traceback" not in err
    spec = tmp_path / "spec.json"
    spec.write_text('{"units": {"g": {"fmu": "builtin:linear_ode_fmi2"}}, "experiment": {"stop": 1, "step": 1}}')
    assert main(["validate", str(spec), "--variant", "B"]) == 2
    assert '"system": {"ssp": "x.ssp", "variant": "B"}' in capsys.readouterr().err


def test_two_ssds_of_one_name_keep_systemstructure_with_a_note(tmp_path):
    # OMSimulator 3 exporting after switching the active variant leaves a stale copy under the old file name
    stale = oms3_ssd().replace('name="default" version="2.0"', 'name="Variant-B" version="2.0"', 1)
    members = oms3_files(stale, **{"Variant-B.ssd": stale.encode()})
    path = write_archive(tmp_path / "stale.ssp", members)
    system = read_ssp(path)
    assert list(system.files.variants) == ["Variant-B"]
    assert f"{path}:Variant-B.ssd names its variant 'Variant-B' as {path}:SystemStructure.ssd does: 'Variant-B' " \
           f"is {path}:SystemStructure.ssd" in system.notes


# --- item 7: an SSP with values on system connectors only ---------------------------------------------------


def _values_only(ssd_text=None):
    """The OMSimulator-3-form SSD without its elements and connections: the root's connectors k (bound to -0.5)
    and out (fed by nothing) are all there is."""
    ssd = ssd_text if ssd_text is not None else oms3_ssd()
    return ssd[:ssd.index("    <ssd:Elements>")] + ssd[ssd.index("    <ssd:Annotations>\n      <ssc:Annotation"):]


def test_an_ssp_without_components_runs_its_system_connectors_constants(tmp_path, capsys):
    path = write_folder(tmp_path / "values_only", oms3_files(_values_only()))
    result = _run(path)
    assert list(result.traces.columns) == ["time", "default.k"]
    assert result.traces["time"].tolist() == pytest.approx([i / 10 for i in range(11)], abs=1e-12)
    assert result.traces["default.k"].tolist() == [-0.5] * 11  # the bound value, at every communication point
    assert main(["run", str(path), "--step", "0.5"]) == 0
    assert main(["inspect", str(path)]) == 0
    out = capsys.readouterr().out
    assert "unit default: connectors default" in out and "-0.5 *" in out and "system connector default.k" in out


def test_an_ssp_without_components_and_without_a_value_is_one_clear_problem(tmp_path, capsys):
    ssd = _values_only()
    ssd = ssd[:ssd.index("    <ssd:ParameterBindings>")] + ssd[ssd.index("    </ssd:ParameterBindings>\n") +
                                                                  len("    </ssd:ParameterBindings>\n"):]
    path = write_folder(tmp_path / "nothing", oms3_files(ssd))
    [problem] = _problems(path)
    assert problem.file == f"{path}:SystemStructure.ssd"
    assert problem.message == ("the SSP has no component (FMU or CSV table) and no system connector holding a "
                               "value: nothing to run (its system connectors default.k, default.out are fed by "
                               "nothing)")
    assert "ssd:Component" in problem.fix
    assert main(["run", str(path)]) == 2
    err = capsys.readouterr().err
    assert "nothing to run" in err and "must not be empty" not in err and "Traceback" not in err


@pytest.mark.parametrize("old, new, attribute", [
    ('fixedStepSize="0.1"', 'fixedStepSize="fast"', "fixedStepSize"),
    ('fixedStepSize="0.1"', 'fixedStepSize="-0.1"', "fixedStepSize"),
    ('<oms:SimulationInformation name="solver1" method="oms_ma" fixedStepSize="0.1"/>',
     '<oms:SimulationInformation><oms:FixedStepMaster stepSize="1e-3s"/></oms:SimulationInformation>', "stepSize"),
])
def test_a_tool_annotation_number_that_is_none_is_a_problem_not_a_traceback(tmp_path, capsys, old, new, attribute):
    # the SSP schema does not check the tools' own annotations: cosim does, where it reads them
    path = write_archive(tmp_path / "bad.ssp", oms3_files(oms3_ssd().replace(old, new)))
    [problem] = _problems(path)
    assert problem.message.endswith(' is not a number') and f'{attribute}="' in problem.message
    assert problem.path.split("/")[-1].startswith("oms:")
    assert main(["validate", str(path)]) == 2
    assert "Traceback" not in capsys.readouterr().err


# --- item 7 (in part): a spec names the SSP's system connectors and root-prefixed unit ports ---------------


def test_a_spec_names_system_connectors_and_root_prefixed_ports_as_tool_users_write_them(tmp_path):
    import json

    import cosim

    write_archive(tmp_path / "oms3.ssp", oms3_files())
    spec = {"system": "oms3.ssp", "experiment": {"step": 0.1, "algorithm": "jacobi"},
            "record": ["default.out", "sub.res", "default.A.y"],
            "objectives": {"out": {"signal": "default.out", "reduce": "final"},
                           "res_min": {"signal": "default.sub.res", "reduce": "min"}}}
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    system = check_spec(tmp_path / "spec.json")
    assert system.spec.record == ("sub.B.y", "sub.B.y", "A.y")  # default.out <- sub.res <- sub.B.y, factor 1
    result = cosim.run(tmp_path / "spec.json")
    assert result.objectives["out"] == pytest.approx(oms3_expected(1.0)["sub.B.y"], rel=1e-12)
    assert result.objectives["res_min"] == pytest.approx(oms3_expected(1.0)["sub.B.y"], rel=1e-12)  # y = -t


_SCALED_OUT = ('<ssd:Connection startElement="sub" startConnector="res" endElement="" endConnector="out">'
               '<ssc:LinearTransformation factor="2.0" offset="1.0"/></ssd:Connection>')


def test_scaled_and_constant_system_connectors_are_signals_of_their_own(tmp_path):
    # default.out = 2 x sub.res + 1 (a LinearTransformation), sub.res = sub.B.y; default.k holds -0.5 and reaches
    # sub.gain through a parameter connection (and from there B.b); sub.speed carries A.y unchanged
    import json

    import cosim

    ssd = oms3_ssd().replace('<ssd:Connection startElement="sub" startConnector="res" endElement="" '
                             'endConnector="out"/>', _SCALED_OUT)
    write_archive(tmp_path / "scaled.ssp", oms3_files(ssd))
    spec = {"system": "scaled.ssp", "experiment": {"step": 0.1, "algorithm": "jacobi"},
            "record": ["default.out", "default.k", "sub.gain", "default.sub.speed", "sub.res"],
            "objectives": {"out_final": {"signal": "default.out", "reduce": "final"},
                           "out_max": {"signal": "out", "reduce": "max"},  # the root's connector, as OMS names it
                           "gain": {"signal": "default.sub.gain", "reduce": "mean"}}}
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    system = check_spec(tmp_path / "spec.json")
    assert system.spec.record == ("default.out", "default.k", "default.sub.gain", "A.y", "sub.B.y")
    result = Execution(system, record=True).run()
    assert result.ok, result.message
    traces = result.traces
    for t, out, y in zip(traces["time"], traces["default.out"], traces["sub.B.y"]):
        assert y == pytest.approx(oms3_expected(t)["sub.B.y"], rel=1e-12, abs=1e-12)
        assert out == pytest.approx(2 * oms3_expected(t)["sub.B.y"] + 1, rel=1e-12, abs=1e-12)
    assert traces["default.k"].tolist() == traces["default.sub.gain"].tolist() == [-0.5] * 11
    assert traces["A.y"].tolist() == [2.0] * 11
    objectives = cosim.run(tmp_path / "spec.json").objectives
    assert objectives["out_final"] == pytest.approx(2 * oms3_expected(1.0)["sub.B.y"] + 1, rel=1e-12)  # -1
    assert objectives["out_max"] == pytest.approx(1.0, rel=1e-12)  # at t = 0, y = 0
    assert objectives["gain"] == -0.5


def test_a_system_connector_converting_units_carries_the_converted_value(tmp_path):
    # sub.res declares rpm, B.y (no unit on B's connector, none in the FMU) passes rad/s through sub.speed...:
    # here the root's 'out' is declared in rpm and sub.res in rad/s, so default.out = 60 / (2 pi) x sub.B.y
    import json
    import math

    ssd = oms3_ssd().replace('<ssd:Connector name="out" kind="output">\n        <ssc:Real/>',
                             '<ssd:Connector name="out" kind="output">\n        <ssc:Real unit="rpm"/>')
    ssd = ssd.replace('<ssd:Connector name="res" kind="output">\n            <ssc:Real/>',
                      '<ssd:Connector name="res" kind="output">\n            <ssc:Real unit="rad/s"/>')
    assert ssd.count('unit="rpm"') == 1 and ssd.count('unit="rad/s"') == 1
    write_archive(tmp_path / "rpm.ssp", oms3_files(ssd))
    spec = {"system": "rpm.ssp", "experiment": {"step": 0.1, "algorithm": "jacobi"},
            "record": ["default.out", "sub.B.y"]}
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    system = check_spec(tmp_path / "spec.json")
    assert system.units["default"].description.by_name["out"].unit == "rpm"
    result = Execution(system, record=True).run()
    assert result.ok, result.message
    expected = [60 / (2 * math.pi) * y for y in result.traces["sub.B.y"]]
    assert result.traces["default.out"].tolist() == pytest.approx(expected, rel=1e-12)
    assert result.traces["sub.B.y"].iloc[-1] == pytest.approx(oms3_expected(1.0)["sub.B.y"], rel=1e-12)


def test_a_system_connector_named_like_a_spec_unit_is_a_problem(tmp_path):
    import json

    ssd = oms3_ssd().replace('<ssd:Connection startElement="sub" startConnector="res" endElement="" '
                             'endConnector="out"/>', _SCALED_OUT)
    write_archive(tmp_path / "scaled.ssp", oms3_files(ssd))
    # 'default.out' names the spec's own unit 'default' (the spec's names win); 'out' the root's connector
    spec = {"system": "scaled.ssp", "experiment": {"step": 0.1}, "record": ["out"],
            "units": {"default": {"fmu": "builtin:linear_ode_fmi2"}}}
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    [problem] = _problems(tmp_path / "spec.json", None)
    assert (problem.path, problem.message) == (
        "$.record[0]", "'out' is the SSP's system connector default.out, but the spec has a unit named "
                       "'default' as the system is")
    assert problem.fix == "rename the unit 'default'"


# --- no traceback for any input file --------------------------------------------------------------------------


def test_an_ssd_with_any_element_or_attribute_removed_or_spoilt_reads_or_gives_problems_never_a_traceback(tmp_path):
    """Each element and each attribute of the OMSimulator-3-form SSD (with a table and solvers) removed in turn,
    and each attribute emptied or given a stray text: the SSP reads, or its problems are reported (each with a fix);
    nothing else is raised."""
    from lxml import etree

    ssd = _solver_ssd().replace('      <ssd:System name="sub">', TABLE_COMPONENT + '      <ssd:System name="sub">', 1)
    folder = write_folder(tmp_path / "mutated", oms3_files(ssd, **{"resources/setpoint.csv": SETPOINT}))
    original = etree.fromstring(ssd.encode())
    mutations = []
    for index, element in enumerate(original.iter()):
        if not isinstance(element.tag, str):
            continue
        if index:
            mutations.append(("element", index, None))
        mutations.extend((what, index, name) for name in element.attrib for what in ("attribute", "", "x/../[1]"))
    assert len(mutations) > 300
    outcomes = {"read": 0, "problems": 0}
    for what, index, name in mutations:
        root = etree.fromstring(ssd.encode())
        element = list(root.iter())[index]
        if what == "element":
            element.getparent().remove(element)
        elif what == "attribute":
            del element.attrib[name]
        else:
            element.set(name, what)
        (folder / "SystemStructure.ssd").write_bytes(etree.tostring(root))
        try:
            read_ssp(folder)
            outcomes["read"] += 1
        except SpecError as exc:
            assert exc.problems and all(p.message and p.fix for p in exc.problems), (what, index, name)
            outcomes["problems"] += 1
    assert outcomes["read"] and outcomes["problems"]


def test_a_table_starting_with_a_separator_line_is_read_with_a_note(tmp_path):
    members = oms3_files(table_ssd(), **{"resources/setpoint.csv": b'"sep=,"\n' + SETPOINT})
    path = write_archive(tmp_path / "sep.ssp", members)
    system = read_ssp(path)
    assert f"{path}:resources/setpoint.csv starts with a 'sep=' line" in " ".join(system.notes)
    result = _run(path, "gauss-seidel")
    times = result.traces["time"]
    assert result.traces["setpoint.speed"].to_numpy() == pytest.approx([_setpoint(t) for t in times], abs=1e-12)


def test_inspect_of_a_spec_on_an_ssp_without_stop_or_step(tmp_path, capsys):
    import json

    ssd = oms3_ssd().replace('fixedStepSize="0.1"', 'fixedStep_removed="0.1"').replace(' stopTime="1.0"', "")
    write_archive(tmp_path / "x.ssp", oms3_files(ssd))
    (tmp_path / "spec.json").write_text(json.dumps({"system": "x.ssp"}))
    assert main(["inspect", str(tmp_path / "spec.json")]) == 0
    out = capsys.readouterr().out
    assert "experiment: 0 .. 1 s, step 0.001 s" in out  # OMSimulator's defaults (issue 33 item 3)
    assert _port_rows(out)["sub.B"]["b"][4] == "-0.5 *"
    assert main(["validate", str(tmp_path / "spec.json")]) == 0


# --- `cosim run x.ssp` records the output connectors of the root system and its sub-systems ------------------


def test_running_an_ssp_records_its_systems_output_connectors_by_their_names(tmp_path, capsys):
    # issue 25's leftover: default.out = 2 x sub.res + 1 (a LinearTransformation) and sub.res = sub.B.y (unchanged)
    # are outputs of the root system and of sub: recorded as default.out and default.sub.res; sub.speed (an
    # input) and default.k (a parameter) are not outputs
    import json

    import pandas as pd

    ssd = oms3_ssd().replace('<ssd:Connection startElement="sub" startConnector="res" endElement="" '
                             'endConnector="out"/>', _SCALED_OUT)
    path = write_archive(tmp_path / "scaled.ssp", oms3_files(ssd))
    assert main(["run", str(path), "--step", "0.1", "--algorithm", "jacobi", "--out", str(tmp_path / "t.csv")]) == 0
    traces = pd.read_csv(tmp_path / "t.csv")
    assert list(traces.columns) == ["time", "A.y", "sub.B.y", "default.out", "default.sub.res"]
    assert traces["time"].to_numpy() == pytest.approx([k / 10 for k in range(11)], abs=1e-12)
    for t, out, res in zip(traces["time"], traces["default.out"], traces["default.sub.res"]):
        assert res == pytest.approx(oms3_expected(t)["sub.B.y"], rel=1e-12, abs=1e-12)  # y = -t
        assert out == pytest.approx(2 * oms3_expected(t)["sub.B.y"] + 1, rel=1e-12, abs=1e-12)
    # a spec naming the SSP without 'record' records the same; with 'record', what it names
    (tmp_path / "spec.json").write_text(json.dumps({"system": "scaled.ssp",
                                                    "experiment": {"step": 0.1, "algorithm": "jacobi"}}))
    same = _run(tmp_path / "spec.json").traces
    assert list(same.columns) == list(traces.columns)
    assert same.to_numpy() == pytest.approx(traces.to_numpy(), rel=1e-15, abs=0)
    (tmp_path / "spec.json").write_text(json.dumps({"system": "scaled.ssp", "record": ["default.out"],
                                                    "experiment": {"step": 0.1, "algorithm": "jacobi"}}))
    assert list(_run(tmp_path / "spec.json").traces.columns) == ["time", "default.out"]
    assert "Traceback" not in capsys.readouterr().err


def test_output_connectors_of_a_system_named_like_a_spec_unit_are_left_out_of_the_implied_record(tmp_path):
    # a spec unit 'default' (the root system's name) keeps its name; the root's connectors are then not recorded,
    # sub's are (its connectors unit is 'default.sub'); as before, a spec without 'record' records the SSP's units
    import json

    write_archive(tmp_path / "oms3.ssp", oms3_files())
    (tmp_path / "spec.json").write_text(json.dumps({
        "system": "oms3.ssp", "experiment": {"step": 0.1, "algorithm": "jacobi"},
        "units": {"default": {"fmu": "builtin:linear_ode_fmi2", "parameters": {"a": 0.0, "b": 0.0, "x0": 4.0}}}}))
    traces = _run(tmp_path / "spec.json").traces
    assert list(traces.columns) == ["time", "A.y", "sub.B.y", "default.sub.res"]
    assert traces["sub.B.y"].to_numpy() == pytest.approx([oms3_expected(t)["sub.B.y"] for t in traces["time"]],
                                                         rel=1e-12, abs=1e-12)
    assert traces["default.sub.res"].tolist() == traces["sub.B.y"].tolist()


# --- a design parameter naming a system's parameter connector sets the parameters it feeds ---------------------

# default.k (bound -0.5) feeds sub.gain through 2 k + 0.1 and from there sub.B.b; and A.x0 through -4 k: at the
# bound value B.b = -0.9 and A.x0 = 2 (as A's own binding says, which the root's parameter connection beats)
_K_FEEDS = ('<ssd:Connection startElement="" startConnector="k" endElement="sub" endConnector="gain">'
            '<ssc:LinearTransformation factor="2.0" offset="0.1"/></ssd:Connection>\n'
            '      <ssd:Connection startElement="" startConnector="k" endElement="A" endConnector="x0">'
            '<ssc:LinearTransformation factor="-4.0"/></ssd:Connection>')


def _k_feeds_ssp(tmp_path):
    ssd = oms3_ssd().replace('<ssd:Connection startElement="" startConnector="k" endElement="sub" '
                             'endConnector="gain"/>', _K_FEEDS)
    return write_archive(tmp_path / "feeds.ssp", oms3_files(ssd))


def test_a_design_parameter_naming_a_parameter_connector_sets_every_parameter_it_feeds(tmp_path):
    # issue 25's leftover: a sweep over default.k sets A.x0 = -4 k and sub.B.b = 2 k + 0.1; so A.y = -4 k and
    # sub.B.y(1) = b x A.y x 1 (B integrates b u exactly from 0, u = A.y held)
    import json

    import cosim

    _k_feeds_ssp(tmp_path)
    ks = [-0.5, -0.25, 0.5]
    (tmp_path / "spec.json").write_text(json.dumps({
        "system": "feeds.ssp", "experiment": {"step": 0.1, "algorithm": "jacobi"},
        "objectives": {"a": {"signal": "A.y", "reduce": "final"}, "b": {"signal": "sub.B.y", "reduce": "final"}},
        "design": {"parameters": {"default.k": {"values": ks}}}}))
    system = check_spec(tmp_path / "spec.json")
    assert system.units["default"].spec.options["feeds"] == {"k": [
        {"to": "sub.B.b", "factor": 2.0, "offset": 0.1}, {"to": "A.x0", "factor": -4.0, "offset": 0.0}]}
    base = Execution(system, record=True).run()  # the bound value: as the SSP alone runs
    assert base.ok and base.traces["A.y"].iloc[-1] == 2.0
    assert base.traces["sub.B.y"].iloc[-1] == pytest.approx(-0.9 * 2.0, rel=1e-12)
    table = cosim.sweep(str(tmp_path / "spec.json"), workers=1, quiet=True).sort_values("default.k")
    assert table["default.k"].tolist() == ks and (table["status"] == "ok").all()
    for k, a, b in zip(ks, table["a"], table["b"]):
        assert a == pytest.approx(-4 * k, rel=1e-12)
        assert b == pytest.approx((2 * k + 0.1) * (-4 * k) * 1.0, rel=1e-12, abs=1e-15)
    # the root's bare name and the value on the command line (--set) mean the same
    assert main(["run", str(tmp_path / "spec.json"), "--set", "default.k=0.25", "--out",
                 str(tmp_path / "t.csv")]) == 0
    import pandas as pd

    traces = pd.read_csv(tmp_path / "t.csv")
    assert traces["A.y"].iloc[-1] == pytest.approx(-1.0, rel=1e-12)
    assert traces["sub.B.y"].iloc[-1] == pytest.approx(0.6 * -1.0, rel=1e-12)


def test_a_design_parameter_naming_an_output_or_fed_connector_is_a_clear_problem(tmp_path):
    import json

    _k_feeds_ssp(tmp_path)
    (tmp_path / "spec.json").write_text(json.dumps({
        "system": "feeds.ssp", "experiment": {"step": 0.1},
        "design": {"parameters": {"default.out": {"values": [1.0, 2.0]}, "sub.speed": {"values": [1.0]}}}}))
    problems = _problems(tmp_path / "spec.json", None)
    by_path = {p.path: p for p in problems}
    assert by_path["$.design.parameters.default.out"].message == (
        "'default.out' is an output connector of the SSP's system 'default', which carries sub.B.y: a design "
        "parameter sets a value before the run, which only a parameter connector (kind=\"parameter\") of a system "
        "takes")
    assert by_path["$.design.parameters.sub.speed"].message.startswith(
        "'sub.speed' is a connector of the SSP's system 'default.sub', which carries A.y:")
    assert "parameter connector" in by_path["$.design.parameters.sub.speed"].fix
    assert main(["validate", str(tmp_path / "spec.json")]) == 2


def test_a_design_parameter_naming_a_connector_that_sets_no_parameter_is_a_clear_problem(tmp_path):
    # sub.gain takes its value from default.k (the connector to sweep); out holds none in oms3's own form
    import json

    _k_feeds_ssp(tmp_path)
    ssd = oms3_ssd().replace('<ssv:Parameter name="k">\n                <ssv:Real value="-0.5"/>\n'
                             '              </ssv:Parameter>\n', '')
    assert ssd != oms3_ssd()
    write_archive(tmp_path / "unbound.ssp", oms3_files(ssd))
    for ssp, key, start in (("feeds.ssp", "sub.gain", "'sub.gain' is a connector of the SSP's system 'default.sub' "
                             "that sets no unit parameter"),
                            ("unbound.ssp", "k", "'k' is a connector of the SSP's system 'default' that holds no "
                             "value")):
        (tmp_path / "spec.json").write_text(json.dumps({"system": ssp, "experiment": {"step": 0.1},
                                                        "design": {"parameters": {key: {"values": [1.0]}}}}))
        [problem] = _problems(tmp_path / "spec.json", None)
        assert problem.path == f"$.design.parameters.{key}" and problem.message.startswith(start), problem.message
