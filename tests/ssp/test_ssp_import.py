"""SSP import: hand-written SSPs (tests/data/ssp/) around FMUs built from fmus/, checked against values computed here."""

from __future__ import annotations

import json
import zipfile

import pytest

import cosim
from cosim.cli.main import main
from cosim.errors import SpecError
from cosim.ssp import read_ssp
from cosim.system.validate import check_spec
from tests.helpers.ssp_fixtures import RPM, nested_expected, nested_files, nested_ssd, write_archive, write_folder


def _final(result, column):
    return float(result.traces[column].iloc[-1])


def _run(path, algorithm="jacobi", **experiment):
    from cosim.execution.run import Execution

    system = check_spec(path, {"algorithm": algorithm, **experiment})
    result = Execution(system, record=True).run()
    assert result.ok, result.message
    return system, result


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_nested_archive_runs_as_computed_by_hand(tmp_path, algorithm):
    path = write_archive(tmp_path / "nested.ssp", nested_files())
    system, result = _run(path, algorithm)
    # the components, and the connectors of sub-system SuT (its output 'out' is recorded as Root.SuT.out)
    assert list(system.units) == ["source", "SuT.integrator", "sink", "Root.SuT"]
    assert system.units["Root.SuT"].spec.kind == "connectors"
    assert result.traces["Root.SuT.out"].tolist() == result.traces["SuT.integrator.y"].tolist()
    expected = nested_expected(algorithm)
    for column, value in expected.items():
        assert _final(result, column) == pytest.approx(value, rel=1e-12, abs=1e-12), column
    assert len(result.traces) == 101  # DefaultExperiment 0..1 s, FixedStepMaster step 0.01 s


def test_bindings_mappings_and_transformations_are_flattened(tmp_path):
    archive = write_archive(tmp_path / "nested.ssp", nested_files())
    raw = read_ssp(archive).raw
    units = raw["units"]
    # FMUs are named inside the archive, not by the temporary folder: the spec's digest is the same in every process
    assert units["source"]["fmu"] == f"{archive.resolve()}!/resources/linear_ode.fmu"
    assert units["source"]["parameters"]["x0"] == 3.0  # the root system's binding beats the component's 5
    assert units["SuT.integrator"]["parameters"] == {"a": 0.0, "b": 2.0, "x0": 1.0}  # prefix; .ssm factor 2
    by_target = {c["to"]: c for c in raw["connections"]}
    assert by_target["SuT.integrator.u"]["from"] == "source.y"  # through the SuT.speed system connector
    assert by_target["SuT.integrator.u"]["factor"] == pytest.approx(RPM, rel=1e-15)
    assert by_target["sink.u"] == {"from": "SuT.integrator.y", "to": "sink.u", "convert": False, "factor": 10.0,
                                   "offset": 1.0}
    assert raw["experiment"] == {"start": 0.0, "stop": 1.0, "step": 0.01}


def test_a_value_bound_to_a_system_connector_reaches_the_connected_parameter(tmp_path):
    # the root system gets a parameter connector 'sink_gain' = 2 (bound at the root), connected to sink.b;
    # sink's own binding no longer sets b
    ssd = nested_ssd().replace('<ssv:Parameter name="b"><ssv:Real value="1"/></ssv:Parameter>', '')
    ssd = ssd.replace('<ssv:Parameter name="source.x0"><ssv:Real value="3"/></ssv:Parameter>',
                      '<ssv:Parameter name="source.x0"><ssv:Real value="3"/></ssv:Parameter>'
                      '<ssv:Parameter name="sink_gain"><ssv:Real value="2"/></ssv:Parameter>')
    ssd = ssd.replace('  <ssd:System name="Root">\n', '  <ssd:System name="Root">\n    <ssd:Connectors><ssd:Connector '
                      'name="sink_gain" kind="parameter"><ssc:Real/></ssd:Connector></ssd:Connectors>\n', 1)
    ssd = ssd.replace('<ssd:Connection startElement="source" startConnector="y"',
                      '<ssd:Connection startConnector="sink_gain" endElement="sink" endConnector="b"/>'
                      '<ssd:Connection startElement="source" startConnector="y"')
    raw = read_ssp(write_archive(tmp_path / "param.ssp", nested_files(ssd))).raw
    assert raw["units"]["sink"]["parameters"]["b"] == 2.0
    _, result = _run(write_archive(tmp_path / "param2.ssp", nested_files(ssd)))
    assert _final(result, "sink.y") == pytest.approx(nested_expected("jacobi", sink_b=2.0)["sink.y"], rel=1e-12)


def test_parameter_values_are_converted_to_the_connector_unit(tmp_path):
    # integrator.ssv gives b = 120 1/min; the SSD declares the connector b in 1/s: b = 2 1/s as before
    members = nested_files(nested_ssd().replace(
        '<ssd:Connector name="u" kind="input"><ssc:Real unit="rad/s"/></ssd:Connector>',
        '<ssd:Connector name="u" kind="input"><ssc:Real unit="rad/s"/></ssd:Connector>'
        '<ssd:Connector name="b" kind="parameter"><ssc:Real unit="1/s"/></ssd:Connector>'))
    members["resources/integrator.ssv"] = members["resources/integrator.ssv"].replace(
        b'<ssv:Real value="2"/>', b'<ssv:Real value="120" unit="1/min"/>')
    raw = read_ssp(write_archive(tmp_path / "units.ssp", members)).raw
    assert raw["units"]["SuT.integrator"]["parameters"]["b"] == pytest.approx(2.0, rel=1e-15)


def test_folder_ssd_file_and_archive_agree(tmp_path):
    members = nested_files()
    archive = write_archive(tmp_path / "nested.ssp", members)
    folder = write_folder(tmp_path / "unpacked", members)
    values = [_final(_run(p)[1], "sink.y") for p in (archive, folder, folder / "SystemStructure.ssd")]
    assert values[0] == values[1] == values[2]


def test_a_system_connector_without_unit_passes_the_unit_through(tmp_path):
    ssd = nested_ssd().replace('<ssd:Connector name="speed" kind="input"><ssc:Real unit="rad/s"/></ssd:Connector>',
                               '<ssd:Connector name="speed" kind="input"><ssc:Real/></ssd:Connector>')
    raw = read_ssp(write_archive(tmp_path / "through.ssp", nested_files(ssd))).raw
    assert {c["to"]: c for c in raw["connections"]}["SuT.integrator.u"]["factor"] == pytest.approx(RPM, rel=1e-15)


def test_suppress_unit_conversion_keeps_the_raw_value(tmp_path):
    ssd = nested_ssd().replace('endElement="SuT" endConnector="speed"/>',
                               'endElement="SuT" endConnector="speed" suppressUnitConversion="true"/>')
    _, result = _run(write_archive(tmp_path / "s.ssp", nested_files(ssd)))
    assert _final(result, "sink.y") == pytest.approx(nested_expected("jacobi", factor=1.0)["sink.y"], rel=1e-12)


def test_ssp_1_0_document(tmp_path):
    ssd = nested_ssd().replace('name="nested" version="2.0"', 'name="nested" version="1.0"') \
                      .replace('<ssv:ParameterSet version="2.0"', '<ssv:ParameterSet version="1.0"')
    _, result = _run(write_archive(tmp_path / "v1.ssp", nested_files(ssd)))
    assert _final(result, "sink.y") == pytest.approx(nested_expected("jacobi")["sink.y"], rel=1e-12)


def test_osp_step_hint_and_missing_step(tmp_path, capsys):
    no_oms = nested_ssd().replace('stepSize="0.01"', 'stepsize_removed="0.01"').replace(
        'xmlns:oms=', 'xmlns:osp="http://opensimulationplatform.com/SSP/OSPAnnotations" xmlns:oms=')
    path = write_archive(tmp_path / "nostep.ssp", nested_files(no_oms))
    # no step size: OMSimulator's default step, 1e-3 s (issue 33 item 3), with a note naming it and --step
    assert check_spec(path).spec.experiment.step == 1e-3
    assert main(["run", str(path), "--step", "0.02"]) == 0
    assert "100" not in capsys.readouterr().out.split("status:")[1].split("steps")[0]  # 50 steps

    osp = no_oms.replace('<ssd:DefaultExperiment startTime="0" stopTime="1"/>',
                         '<ssd:DefaultExperiment startTime="0" stopTime="1"><ssd:Annotations>'
                         '<ssc:Annotation type="com.opensimulationplatform"><osp:Algorithm>'
                         '<osp:FixedStepAlgorithm baseStepSize="0.05"/></osp:Algorithm></ssc:Annotation>'
                         '</ssd:Annotations></ssd:DefaultExperiment>')
    assert read_ssp(write_archive(tmp_path / "osp.ssp", nested_files(osp))).raw["experiment"]["step"] == 0.05


def _problems(path):
    with pytest.raises(SpecError) as caught:
        check_spec(path)
    return caught.value.problems


def test_missing_fmu_names_the_component(tmp_path, capsys):
    members = nested_files()
    del members["resources/linear_ode.fmu"]
    path = write_archive(tmp_path / "nofmu.ssp", members)
    problems = _problems(path)
    assert len(problems) == 3  # one per component using it
    assert problems[0].file == f"{path}:SystemStructure.ssd"
    assert problems[0].path.endswith("ssd:Component[@name='source']")
    assert "resources/linear_ode.fmu" in problems[0].message and "resources/" in problems[0].fix
    assert main(["validate", str(path)]) == 2
    assert "Traceback" not in capsys.readouterr().err


def test_fmu_next_to_the_archive_is_found(tmp_path):
    members = nested_files()
    (tmp_path / "linear_ode.fmu").write_bytes(members.pop("resources/linear_ode.fmu"))
    _, result = _run(write_archive(tmp_path / "beside.ssp", members))
    assert _final(result, "sink.y") == pytest.approx(nested_expected("jacobi")["sink.y"], rel=1e-12)


def test_broken_ssv_is_reported_with_its_file_and_line(tmp_path):
    members = nested_files()
    members["resources/integrator.ssv"] = members["resources/integrator.ssv"].replace(b"</ssv:Parameters>", b"")
    [problem] = _problems(write_archive(tmp_path / "badssv.ssp", members))
    assert problem.file.endswith("badssv.ssp:resources/integrator.ssv")
    assert "malformed XML" in problem.message and problem.path.startswith("line ")

    members = nested_files()
    members["resources/integrator.ssv"] = members["resources/integrator.ssv"].replace(b'value="2"', b'valu="2"')
    problems = _problems(write_archive(tmp_path / "schema.ssp", members))
    assert [p.message.split(": ", 1)[1] for p in problems] == [
        "Element 'ssv:Real', attribute 'valu': The attribute 'valu' is not allowed.",
        "Element 'ssv:Real': The attribute 'value' is required but missing."]
    assert all(p.path.endswith("ssv:Parameter[@name='b']/ssv:Real") for p in problems)


def test_unknown_connector_suggests_the_right_one(tmp_path):
    ssd = nested_ssd().replace('endElement="sink" endConnector="u"', 'endElement="sink" endConnector="uu"')
    [problem] = _problems(write_archive(tmp_path / "unknown.ssp", nested_files(ssd)))
    assert "endConnector 'uu' is not a connector of component 'sink'" in problem.message
    assert "Did you mean 'u'" in problem.message
    assert problem.path.endswith("ssd:System[@name='Root']/ssd:Connections/ssd:Connection[2]")

    ssd = nested_ssd().replace('<ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>',
                               '<ssd:Connector name="input" kind="input"><ssc:Real/></ssd:Connector>')
    problems = _problems(write_archive(tmp_path / "declared.ssp", nested_files(ssd)))
    assert any("connector 'input' is not a variable of FMU" in p.message for p in problems)


def test_units_without_ssd_definition_are_read_by_name_unknown_ones_refused(tmp_path):
    without = nested_ssd().replace('<ssc:Unit name="rpm"><ssc:BaseUnit s="-1" rad="1" factor="0.10471975511965977"/>'
                                   '</ssc:Unit>', '')
    raw = read_ssp(write_archive(tmp_path / "nodef.ssp", nested_files(without))).raw
    assert {c["to"]: c for c in raw["connections"]}["SuT.integrator.u"]["factor"] == pytest.approx(RPM, rel=1e-15)

    unknown = without.replace('<ssc:Real unit="rpm"/>', '<ssc:Real unit="revs"/>')
    [problem] = _problems(write_archive(tmp_path / "unknown_unit.ssp", nested_files(unknown)))
    assert "cannot convert 'revs' to 'rad/s'" in problem.message and "suppressUnitConversion" in problem.fix
    ssd = nested_ssd().replace('<ssc:BaseUnit s="-1" rad="1" factor="0.10471975511965977"/>',
                               '<ssc:BaseUnit m="1"/>')
    [problem] = _problems(write_archive(tmp_path / "otherunit.ssp", nested_files(ssd)))
    assert "different quantities" in problem.message
    assert problem.path.endswith("ssd:System[@name='Root']/ssd:Connections/ssd:Connection[1]")


def test_entities_are_not_expanded(tmp_path):
    secret = tmp_path / "secret.txt"
    secret.write_text("TOP-SECRET")
    ssd = nested_ssd().replace('<?xml version="1.0" encoding="UTF-8"?>',
                               f'<?xml version="1.0" encoding="UTF-8"?>\n<!DOCTYPE x [<!ENTITY e SYSTEM '
                               f'"file://{secret}">]>').replace('name="nested" version', 'name="&e;" version')
    path = write_archive(tmp_path / "xxe.ssp", nested_files(ssd))
    try:
        raw = read_ssp(path).raw
        assert "TOP-SECRET" not in json.dumps(raw)
    except SpecError as exc:
        assert "TOP-SECRET" not in str(exc)


def test_archive_members_may_not_escape(tmp_path):
    path = tmp_path / "escape.ssp"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("SystemStructure.ssd", nested_ssd())
        zf.writestr("../escaped.txt", "x")
    [problem] = _problems(path)
    assert "escapes the extraction folder" in problem.message and problem.path == "../escaped.txt"
    assert not (tmp_path / "escaped.txt").exists()


def test_spec_takes_its_system_from_an_ssp_and_overrides_it(tmp_path):
    write_archive(tmp_path / "nested.ssp", nested_files())
    spec = {
        "system": "nested.ssp",
        "units": {"sink": {"parameters": {"b": 2.0}}},
        "experiment": {"algorithm": "jacobi"},
        "objectives": {"sink_final": {"signal": "sink.y", "reduce": "final"}},
        "design": {"parameters": {"sink.b": {"values": [1.0, 2.0]}}},
    }
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    result = cosim.run(tmp_path / "spec.json")
    assert result.objectives["sink_final"] == pytest.approx(nested_expected("jacobi", sink_b=2.0)["sink.y"],
                                                            rel=1e-12)
    table = cosim.sweep(tmp_path / "spec.json", workers=1)
    by_b = dict(zip(table["sink.b"], table["sink_final"]))
    for b in (1.0, 2.0):
        assert by_b[b] == pytest.approx(nested_expected("jacobi", sink_b=b)["sink.y"], rel=1e-12)


def test_sweep_of_an_ssp_resumes_in_a_new_process(tmp_path):
    # the spec read from an archive names its FMUs inside the archive, not by this process's temporary
    # folder, so a second process finds the same spec digest and accepts --resume
    import subprocess
    import sys

    path = write_archive(tmp_path / "nested.ssp", nested_files())
    command = [sys.executable, "-m", "cosim.cli.main", "sweep", str(path), "--out", str(tmp_path / "out"),
               "--workers", "1", "--step", "0.1"]
    first = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    again = subprocess.run(command + ["--resume"], capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    assert "all 1 points already in" in again.stderr


def test_spec_naming_a_missing_ssp(tmp_path, capsys):
    (tmp_path / "spec.json").write_text(json.dumps({"system": "gone.ssp", "experiment": {"stop": 1, "step": 1}}))
    assert main(["validate", str(tmp_path / "spec.json")]) == 2
    err = capsys.readouterr().err
    assert "$.system" in err and "'gone.ssp' not found" in err
