"""SSP export and Python units as FMUs: export, import again, compare bit for bit."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest
from lxml import etree

from cosim.cli.main import main
from cosim.errors import SpecError
from cosim.execution.point import run_point
from cosim.execution.run import Execution
from cosim.export.ssp import companion_spec_path, export_ssp
from cosim.ssp.xml import NS
from cosim.system.validate import check_spec
from tests.helpers.paths import REPO
from tests.helpers.ssp_fixtures import nested_expected, nested_files, oms3_expected, oms3_files, oms3_ssd, write_archive
from tests.helpers.tools import python_unit

ROOT = REPO
DRIVE_ENERGY = ROOT / "examples" / "drive_energy" / "spec.json"


def _traces(path, **experiment):
    result = Execution(check_spec(path, experiment or None), record=True).run()
    assert result.ok, result.message
    return result


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_nested_ssp_exported_and_read_back_is_bit_identical(tmp_path, algorithm):
    original = write_archive(tmp_path / "nested.ssp", nested_files())
    system = check_spec(original, {"algorithm": algorithm})
    exported = export_ssp(system, tmp_path / "flat.ssp")
    again = _traces(exported)  # the algorithm travels in the org.cosim annotation
    first = _traces(original, algorithm=algorithm)
    assert list(again.traces.columns) == list(first.traces.columns)
    assert np.array_equal(again.traces.to_numpy(), first.traces.to_numpy())
    assert again.traces["sink.y"].iloc[-1] == pytest.approx(nested_expected(algorithm)["sink.y"], rel=1e-12)


def test_exported_archive_layout_and_parameter_files(tmp_path, built_fmu):
    spec = {
        "name": "ring",
        "units": {"a": {"fmu": str(built_fmu("linear_ode", 2)), "parameters": {"a": -1.0, "x0": 0.1 + 0.2}},
                  "g": {"fmu": str(built_fmu("gain_array", 3)), "parameters": {"k": 1 / 3}}},
        "connections": [{"from": "a.y", "to": "g.u[2]", "factor": 3.0, "offset": -1.0}],
        "experiment": {"stop": 0.5, "step": 0.1, "algorithm": "jacobi"},
        "objectives": {"y": {"signal": "g.y[2]", "reduce": "final"}},
    }
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    assert main(["export", str(tmp_path / "spec.json"), "-o", str(tmp_path / "out" / "ring.ssp")]) == 0
    archive = tmp_path / "out" / "ring.ssp"
    with zipfile.ZipFile(archive) as zf:
        names = sorted(zf.namelist())
        ssd = etree.fromstring(zf.read("SystemStructure.ssd"))
        ssv = etree.fromstring(zf.read("resources/a.ssv"))
    assert names == ["SystemStructure.ssd", "resources/a.ssv", "resources/g.ssv", "resources/gain_array_fmi3.fmu",
                     "resources/linear_ode_fmi2.fmu"]
    assert ssd.get("version") == "2.0"
    values = {p.get("name"): p[0].get("value") for p in ssv.iter(f"{{{NS['ssv']}}}Parameter")}
    assert values == {"a": "-1.0", "x0": repr(0.1 + 0.2)}  # 17 digits: reads back bit for bit
    steps = [e.get("stepSize") for e in ssd.iter() if isinstance(e.tag, str) and e.tag.endswith("FixedStepMaster")]
    assert steps == ["0.1"]
    default = ssd.find(f"{{{NS['ssd']}}}DefaultExperiment")
    assert (default.get("startTime"), default.get("stopTime")) == ("0.0", "0.5")
    [connection] = ssd.iter(f"{{{NS['ssd']}}}Connection")
    assert (connection.get("endElement"), connection.get("endConnector")) == ("g", "u[2]")
    companion = json.loads((tmp_path / "out" / "ring.spec.json").read_text())
    assert companion["system"] == "ring.ssp" and companion["objectives"] == spec["objectives"]
    from cosim import run

    direct, again = run(tmp_path / "spec.json"), run(tmp_path / "out" / "ring.spec.json")
    assert direct.objectives == again.objectives
    # Jacobi sets the inputs after each step (issue 25 item 8), so at the stop time g.u[2] holds a.y at t = 0.5
    # (5 steps); g.y = k * u[2] is feed-through, read after u[2] was set
    expected = 1 / 3 * (3.0 * _linear_ode_final(-1.0, 1.0, 0.1 + 0.2, 0.0, 0.1, 5) - 1.0)
    assert direct.objectives["y"] == pytest.approx(expected, rel=1e-12)


def _linear_ode_final(a, b, x0, u, h, n):
    """linear_ode's output after n exact steps with a held input (its own formula, evaluated here)."""
    x = x0
    for _ in range(n):
        x = np.exp(a * h) * x + (np.exp(a * h) - 1) / a * b * u
    return x


def test_python_units_are_exported_as_fmus_and_read_back_bit_identical(tmp_path):
    spec = json.loads(DRIVE_ENERGY.read_text())
    spec["units"]["drive"]["python"] = str(DRIVE_ENERGY.parent / "drive_profile.py") + ":DriveProfile"
    spec["experiment"]["stop"] = 0.3
    spec.pop("design")
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    out = tmp_path / "drive.ssp"
    assert main(["export", str(tmp_path / "spec.json"), "-o", str(out)]) == 0
    again = check_spec(tmp_path / "drive.spec.json")
    assert again.units["drive"].description.kind == "fmu"
    assert again.units["drive"].description.fmi_version == "2.0"
    first = Execution(check_spec(tmp_path / "spec.json"), record=True).run()
    second = Execution(again, record=True).run()
    assert first.ok and second.ok, (first.message, second.message)
    assert first.objectives == second.objectives
    assert np.array_equal(first.traces.to_numpy(), second.traces.to_numpy())


def test_player_units_are_refused(tmp_path, write_spec):
    import pandas as pd

    pd.DataFrame({"time": [0.0, 1.0], "y": [0.0, 1.0]}).to_csv(tmp_path / "rec.csv", index=False)
    path = write_spec({"units": {"p": {"player": "rec.csv"}}, "experiment": {"stop": 1, "step": 0.5}})
    with pytest.raises(SpecError) as caught:
        export_ssp(check_spec(path), tmp_path / "x.ssp")
    assert caught.value.problems[0].path == "$.units.p"
    assert not (tmp_path / "x.ssp").exists()


@pytest.mark.parametrize("cls", ["Gain", "Clock"])
def test_export_fmu_keeps_ports_units_parameters_and_feedthrough(tmp_path, capsys, cls):
    from cosim.units.fmu.description import FmuUnitType
    from cosim.units.python.unit import PythonUnitType

    target = python_unit(cls)
    assert main(["export-fmu", target, "-o", str(tmp_path / "gain.fmu")]) == 0
    assert "runs where Python" in capsys.readouterr().out
    python = PythonUnitType(target).describe()
    fmu = FmuUnitType(tmp_path / "gain.fmu", "gain.fmu").describe()
    assert fmu.fmi_version == "2.0"
    by_name = fmu.by_name
    for variable in python.variables:
        exported = by_name[variable.name]
        assert (exported.causality, exported.type, exported.shape, exported.unit) == \
               (variable.causality, variable.type, variable.shape, variable.unit), variable.name
        if variable.causality in ("parameter", "input"):  # outputs are calculated: no start in FMI 2.0
            assert np.allclose(exported.start, variable.start), variable.name
    for output in python.outputs():
        assert set(fmu.depends_on(output.name)) >= set(python.depends_on(output.name))


def test_port_mappings_survive_the_export(tmp_path):
    spec = {
        "units": {"src": {"fmu": "builtin:linear_ode_fmi3", "parameters": {"a": 0.0, "b": 0.0, "x0": 2.0}},
                  "ode": {"fmu": "builtin:linear_ode_fmi3", "ports": {"state": "y", "drive": "u"},
                          "parameters": {"a": 0.0, "x0": 0.0}}},
        "connections": [{"from": "src.y", "to": "ode.drive"}],
        "experiment": {"stop": 1.0, "step": 0.25},
        "objectives": {"state": {"signal": "ode.state", "reduce": "final"}},
    }
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    export_ssp(check_spec(tmp_path / "spec.json"), tmp_path / "mapped.ssp")
    from cosim import run

    direct, again = run(tmp_path / "spec.json"), run(tmp_path / "mapped.spec.json")
    assert direct.objectives == again.objectives == {"state": 2.0}  # 4 steps of 0.25 s, b = 1, u = 2


@pytest.mark.parametrize("cls", ["LinearOde", "Clock"])
def test_exported_fmu_passes_fmpy_validation(tmp_path, cls):
    # FMPy's checks as a user runs them on an FMU: every calculated output listed in ModelStructure/InitialUnknowns
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    assert main(["export-fmu", python_unit(cls), "-o", str(tmp_path / "unit.fmu")]) == 0
    assert validate_fmu(str(tmp_path / "unit.fmu")) == []
    description = read_model_description(str(tmp_path / "unit.fmu"), validate=True)
    outputs = sorted(v.name for v in description.modelVariables if v.causality == "output")
    assert outputs and sorted(u.variable.name for u in description.initialUnknowns) == outputs


@pytest.mark.parametrize("experiment", [
    {"algorithm": "jacobi", "coupled_model_exchange": False, "early_stop": "fail",
     "loop_solver": {"method": "fixed-point", "max_iterations": 20, "tolerance": 1e-9}},
    {"algorithm": "adaptive", "adaptive": {"rtol": 1e-5, "atol": 1e-7, "max_step": 0.2, "base": "jacobi"}},
])
def test_implementation_and_solver_settings_survive_the_export(tmp_path, experiment):
    # issue 25: the archive carries how each unit runs (implementation), a model-exchange unit's tolerance and
    # max_step (as OMSimulator 3's cvode solver assigned to its component), the step (also as OMSimulator 3's
    # oms_ma solver) and cosim's own experiment options, so reading it back (without the companion spec) gives
    # the same experiment
    spec = {
        "name": "solvers",
        "units": {"src": {"fmu": "builtin:linear_ode_fmi2", "parameters": {"a": 0.0, "b": 0.0, "x0": 2.0}},
                  "me": {"fmu": "builtin:linear_ode_fmi2", "interface": "model-exchange", "tolerance": 1e-8,
                         "max_step": 0.01, "parameters": {"a": -1.0, "b": 1.0, "x0": 0.0},
                         **({"record_events": True} if experiment["algorithm"] != "adaptive" else {})},
                  "me_default": {"fmu": "builtin:linear_ode_fmi3", "interface": "model-exchange",
                                 "coupled_model_exchange": False, "parameters": {"a": -2.0, "b": 1.0, "x0": 0.0}}},
        "connections": [{"from": "src.y", "to": "me.u"}, {"from": "src.y", "to": "me_default.u"}],
        "experiment": {"stop": 1.0, "step": 0.1, **experiment},
        "record": ["src.*", "me.*", "me_default.*"],  # as the SSP records: every unit's ports
    }
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    original = check_spec(tmp_path / "spec.json")
    archive = export_ssp(original, tmp_path / "solvers.ssp", spec_copy=False)
    with zipfile.ZipFile(archive) as zf:
        ssd = etree.fromstring(zf.read("SystemStructure.ssd"))
    components = {c.get("name"): c for c in ssd.iter(f"{{{NS['ssd']}}}Component")}
    assert {n: c.get("implementation") for n, c in components.items()} == \
        {"src": "CoSimulation", "me": "ModelExchange", "me_default": "ModelExchange"}
    infos = [e for e in ssd.iter() if isinstance(e.tag, str) and e.tag.endswith("}SimulationInformation")]
    definitions = {e.get("name"): dict(e.attrib) for e in infos if e.get("method")}
    assigned = {n: [e.get("name") for e in c.iter() if e in infos] for n, c in components.items()}
    assert definitions[assigned["me"][0]] == {"name": assigned["me"][0], "method": "cvode",
                                              "relativeTolerance": "1e-08", "maximumStepSize": "0.01"}
    assert definitions[assigned["me_default"][0]] == {"name": assigned["me_default"][0], "method": "cvode"}
    assert assigned["src"] == []
    assert [d["fixedStepSize"] for d in definitions.values() if d["method"] == "oms_ma"] == ["0.1"]

    again = check_spec(archive)
    assert again.spec.experiment == original.spec.experiment
    for name, unit in original.units.items():
        twin = again.units[name]
        assert (twin.unit_type.interface, twin.unit_type.solver_settings) == \
            (unit.unit_type.interface, unit.unit_type.solver_settings), name
        options = ("record_events", "coupled_model_exchange")  # cosim's own, in the component's org.cosim annotation
        assert {k: twin.spec.options.get(k) for k in options} == {k: unit.spec.options.get(k) for k in options}
    first, second = (Execution(s, record=True).run() for s in (original, again))
    assert first.ok and second.ok, (first.message, second.message)
    assert np.array_equal(first.traces.to_numpy(), second.traces.to_numpy())
    # me: der(x) = -x + 2 from x = 0: x(1) = 2 (1 - e^-1), integrated by CVode at rtol 1e-8
    assert second.traces["me.y"].iloc[-1] == pytest.approx(2 * (1 - np.exp(-1.0)), rel=1e-6)


def test_a_warm_start_survives_the_export_and_runs_the_same_from_the_ssp(tmp_path):
    # issue 26 item 5: experiment.warm_start travels in the org.cosim annotation; the SSP, read back alone, warms up
    # the same way, and a run with another tunable value from it equals the same run from the spec
    spec = {"name": "warm",
            "units": {"src": {"fmu": "builtin:linear_ode_fmi2", "parameters": {"a": 0.0, "b": 0.0, "x0": 2.0}},
                      "lag": {"fmu": "builtin:linear_ode_fmi3", "parameters": {"a": -1.0, "b": 1.0, "x0": 0.0}}},
            "connections": [{"from": "src.y", "to": "lag.u"}],
            "experiment": {"stop": 1.0, "step": 0.01, "warm_start": 0.5, "algorithm": "jacobi"},
            "record": ["src.*", "lag.*"]}
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    original = check_spec(tmp_path / "spec.json")
    archive = export_ssp(original, tmp_path / "warm.ssp", spec_copy=False)
    again = check_spec(archive)
    assert again.spec.experiment == original.spec.experiment and again.spec.experiment.warm_start == 0.5
    first, second = (run_point(s, {"lag.b": 3.0}, record=True) for s in (original, again))
    assert first.ok and second.ok, (first.message, second.message)
    assert (first.steps, second.steps) == (50, 50)
    assert np.array_equal(first.traces.to_numpy(), second.traces.to_numpy())
    # lag: x' = -x + 2 b, b = 1 to t = 0.5, then b = 3: x(1) = 6 + (x(0.5) - 6) e^-0.5, x(0.5) = 2 (1 - e^-0.5)
    x_half = 2 * (1 - np.exp(-0.5))
    assert second.traces["lag.y"].iloc[-1] == pytest.approx(6 + (x_half - 6) * np.exp(-0.5), abs=1e-12)


# --- connectors units (an SSP's system connectors as signals) become system connectors again -------------------

_SCALED_OUT = ('<ssd:Connection startElement="sub" startConnector="res" endElement="" endConnector="out">'
               '<ssc:LinearTransformation factor="2.0" offset="1.0"/></ssd:Connection>')


def _read_back(spec_path, exported):
    """Traces of the spec and of the exported archive read back through its companion spec."""
    first = _traces(spec_path)
    again = _traces(companion_spec_path(exported))
    assert list(again.traces.columns) == list(first.traces.columns)
    assert np.array_equal(again.traces.to_numpy(), first.traces.to_numpy())
    return again.traces


def test_scaled_and_constant_system_connectors_are_exported_as_system_connectors(tmp_path, capsys):
    # issue 25's leftover: default.out = 2 x sub.res + 1 (a LinearTransformation), default.k and default.sub.gain
    # constants (-0.5): a spec recording them has connectors units 'default' and 'default.sub', which cosim export
    # writes as the root system's and sub-system sub's connectors; read back, the same signals
    ssd = oms3_ssd().replace('<ssd:Connection startElement="sub" startConnector="res" endElement="" '
                             'endConnector="out"/>', _SCALED_OUT)
    write_archive(tmp_path / "scaled.ssp", oms3_files(ssd))
    (tmp_path / "spec.json").write_text(json.dumps({
        "system": "scaled.ssp", "experiment": {"step": 0.1, "algorithm": "jacobi"},
        "record": ["default.out", "default.k", "sub.gain", "sub.B.y"],
        "objectives": {"out_final": {"signal": "default.out", "reduce": "final"}}}))
    assert main(["export", str(tmp_path / "spec.json"), "-o", str(tmp_path / "flat.ssp")]) == 0
    with zipfile.ZipFile(tmp_path / "flat.ssp") as zf:
        ssd_out = etree.fromstring(zf.read("SystemStructure.ssd"))
    top = ssd_out.find(f"{{{NS['ssd']}}}System")
    assert top.get("name") == "default"  # the connectors units' root system
    assert [(c.get("name"), c.get("kind")) for c in top.find(f"{{{NS['ssd']}}}Connectors")] == \
        [("out", "output"), ("k", "parameter")]
    [into_out] = [c for c in top.iter(f"{{{NS['ssd']}}}Connection") if c.get("endConnector") == "out"]
    assert (into_out.get("startElement"), into_out.get("startConnector"), into_out.get("endElement")) == \
        ("sub.B", "y", None)
    assert dict(into_out.find(f"{{{NS['ssc']}}}LinearTransformation").attrib) == {"factor": "2.0", "offset": "1.0"}
    [sub] = [s for s in top.iter(f"{{{NS['ssd']}}}System") if s.get("name") == "sub"]
    assert [p.get("name") for p in sub.iter(f"{{{NS['ssv']}}}Parameter")] == ["gain"]
    assert sub.find(f".//{{{NS['ssv']}}}Real").get("value") == "-0.5"
    companion = json.loads((tmp_path / "flat.spec.json").read_text())
    assert "units" not in companion  # no unit of the companion: the connectors come from the SSP again
    traces = _read_back(tmp_path / "spec.json", tmp_path / "flat.ssp")
    for t, out, y in zip(traces["time"], traces["default.out"], traces["sub.B.y"]):
        assert y == pytest.approx(oms3_expected(t)["sub.B.y"], rel=1e-12, abs=1e-12)
        assert out == pytest.approx(2 * oms3_expected(t)["sub.B.y"] + 1, rel=1e-12, abs=1e-12)
    assert traces["default.k"].tolist() == traces["default.sub.gain"].tolist() == [-0.5] * 11
    assert "Traceback" not in capsys.readouterr().err


def test_connectors_units_of_a_spec_nested_two_deep_with_units_and_typed_constants(tmp_path):
    # a hand-written spec: Top.a.b.v = 3 x ramp.y + 1 in rpm (ramp.y = 2 t), constants of every type; Top.a.b
    # becomes system b inside system a inside the root system Top, the value passed on through a's connector b_v
    spec = {"name": "deep",
            "units": {"src": {"fmu": "builtin:linear_ode_fmi2", "parameters": {"a": 0.0, "b": 0.0, "x0": 2.0}},
                      "ramp": {"fmu": "builtin:linear_ode_fmi3", "parameters": {"a": 0.0, "b": 1.0, "x0": 0.0}},
                      "Top": {"connectors": "Top", "parameters": {"k": 7, "flag": True, "label": "x"}},
                      "Top.a.b": {"connectors": "Top.a.b", "inputs": {"v": "rpm"}, "parameters": {"gain": 0.25}}},
            "connections": [{"from": "src.y", "to": "ramp.u"},
                            {"from": "ramp.y", "to": "Top.a.b.v", "factor": 3.0, "offset": 1.0}],
            "experiment": {"stop": 1.0, "step": 0.1, "algorithm": "gauss-seidel"},
            "record": ["Top.a.b.v", "Top.k", "Top.flag", "Top.label", "Top.a.b.gain", "ramp.y"]}
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    exported = export_ssp(check_spec(tmp_path / "spec.json"), tmp_path / "deep.ssp")
    with zipfile.ZipFile(exported) as zf:
        ssd = etree.fromstring(zf.read("SystemStructure.ssd"))
    systems = {s.get("name"): s for s in ssd.iter(f"{{{NS['ssd']}}}System")}
    assert list(systems) == ["Top", "a", "b"]
    connectors = {n: [(c.get("name"), c.get("kind")) for c in s.findall(f"{{{NS['ssd']}}}Connectors/*")]
                  for n, s in systems.items()}
    assert connectors == {"Top": [("k", "parameter"), ("flag", "parameter"), ("label", "parameter")],
                          "a": [("b_v", "input")], "b": [("v", "output"), ("gain", "parameter")]}
    again = check_spec(companion_spec_path(exported))
    assert again.units["Top.a.b"].description.by_name["v"].unit == "rpm"
    traces = _read_back(tmp_path / "spec.json", exported)
    assert traces["ramp.y"].to_numpy() == pytest.approx(2 * traces["time"].to_numpy(), rel=1e-12, abs=1e-12)
    assert traces["Top.a.b.v"].to_numpy() == pytest.approx(6 * traces["time"].to_numpy() + 1, rel=1e-12)
    assert (traces["Top.k"].tolist(), traces["Top.flag"].tolist(), traces["Top.label"].tolist()) == \
        ([7] * 11, [True] * 11, ["x"] * 11)
    assert traces["Top.a.b.gain"].tolist() == [0.25] * 11


def test_connectors_units_under_two_root_systems_or_named_like_a_unit_are_refused(tmp_path, capsys):
    spec = {"units": {"src": {"fmu": "builtin:linear_ode_fmi2"},
                      "Top": {"connectors": "Top", "parameters": {"k": 1.0}},
                      "Other.x": {"connectors": "Other.x", "parameters": {"k": 2.0}},
                      "Top.src": {"connectors": "Top.src", "parameters": {"k": 3.0}}},
            "experiment": {"stop": 1.0, "step": 0.1}}
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    assert main(["export", str(tmp_path / "spec.json"), "-o", str(tmp_path / "x.ssp")]) == 2
    err = capsys.readouterr().err
    assert ("$.units.Other.x: the connectors unit 'Other.x' names the root system 'Other', another connectors unit "
            "'Top': an SSP has one root system") in err
    assert "$.units.Top.src: the connectors unit 'Top.src' becomes the sub-system 'src', which is also the name " \
           "of a unit" in err
    assert "Traceback" not in err and not (tmp_path / "x.ssp").exists()


def test_a_parameter_connector_a_design_names_is_exported_with_its_parameter_connections(tmp_path, capsys):
    # default.k (-0.5) feeds A.x0 = -4 k and, through sub.gain, sub.B.b = 2 k + 0.1; the design names default.k.
    # Exported, k feeds A.x0 and sub.B.b by connections with those LinearTransformations (their .ssv values left
    # out), so the companion spec's design sets them again: a point with k = 0.5 runs bit for bit the same
    ssd = oms3_ssd().replace(
        '<ssd:Connection startElement="" startConnector="k" endElement="sub" endConnector="gain"/>',
        '<ssd:Connection startElement="" startConnector="k" endElement="sub" endConnector="gain">'
        '<ssc:LinearTransformation factor="2.0" offset="0.1"/></ssd:Connection>'
        '<ssd:Connection startElement="" startConnector="k" endElement="A" endConnector="x0">'
        '<ssc:LinearTransformation factor="-4.0"/></ssd:Connection>')
    write_archive(tmp_path / "feeds.ssp", oms3_files(ssd))
    spec = {"system": "feeds.ssp", "experiment": {"step": 0.1, "algorithm": "jacobi"},
            "record": ["A.y", "sub.B.y", "default.k"],
            "design": {"parameters": {"default.k": {"values": [-0.5, 0.5]}}}}
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    original = check_spec(tmp_path / "spec.json")
    exported = export_ssp(original, tmp_path / "flat.ssp")
    with zipfile.ZipFile(exported) as zf:
        ssd_out = etree.fromstring(zf.read("SystemStructure.ssd"))
        sub_b = etree.fromstring(zf.read("resources/sub.B.ssv"))
    feeds = {(c.get("endElement"), c.get("endConnector")): dict(c.find(f"{{{NS['ssc']}}}LinearTransformation").attrib)
             for c in ssd_out.iter(f"{{{NS['ssd']}}}Connection") if c.get("startConnector") == "k"}
    assert feeds == {("sub.B", "b"): {"factor": "2.0", "offset": "0.1"}, ("A", "x0"): {"factor": "-4.0",
                                                                                       "offset": "0.0"}}
    assert [p.get("name") for p in sub_b.iter(f"{{{NS['ssv']}}}Parameter")] == ["a", "x0"]  # b comes from k
    again = check_spec(companion_spec_path(exported))
    for k in (-0.5, 0.5):
        first, second = (run_point(s, {"default.k": k}, record=True) for s in (original, again))
        assert first.ok and second.ok, (first.message, second.message)
        assert list(first.traces.columns) == list(second.traces.columns)
        assert np.array_equal(first.traces.to_numpy(), second.traces.to_numpy())
        assert second.traces["A.y"].iloc[-1] == pytest.approx(-4 * k, rel=1e-12)
        assert second.traces["sub.B.y"].iloc[-1] == pytest.approx((2 * k + 0.1) * -4 * k, rel=1e-12)
    # a spec value of a fed parameter that is not what the connector feeds it: an SSP holds one of them
    spec["units"] = {"sub.B": {"parameters": {"b": 5.0}}}
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    assert main(["export", str(tmp_path / "spec.json"), "-o", str(tmp_path / "other.ssp")]) == 2
    err = capsys.readouterr().err
    assert ("$.units.sub.B.parameters.b: 'sub.B.b' is 5.0 here, but the system connector 'default.k' feeds it "
            "-0.9: an SSP holds one of them") in err
    assert not (tmp_path / "other.ssp").exists()


def test_a_spec_without_connections_is_exported_without_an_empty_connections_element(tmp_path, capsys):
    """examples/bouncing_ball (one unit, nothing connected): the export wrote an empty ssd:Connections, which the
    SSP schema refuses (one Connection at least), and ended in a RuntimeError traceback (issue 38.7)."""
    spec = REPO / "examples" / "bouncing_ball" / "spec.json"
    out = tmp_path / "ball.ssp"
    assert main(["export", str(spec), "-o", str(out)]) == 0, capsys.readouterr().err
    with zipfile.ZipFile(out) as archive:
        ssd = etree.fromstring(archive.read("SystemStructure.ssd"))
    assert ssd.find(".//ssd:Connections", NS) is None
    assert len(ssd.findall(".//ssd:Component", NS)) == 1
    again, first = _traces(companion_spec_path(out)), _traces(spec)
    assert again.traces.equals(first.traces)  # the same FMU, the same master: the same numbers
