"""FMI conformance: our conformance FMUs (fmus/conformance/) run exactly as fmpy runs them, or are refused precisely.

Every FMU here is built from the project's C sources.  Each is run through
``cosim inspect`` and ``cosim run`` and compared, value for value, with fmpy's
own ``simulate_fmu`` (or fmpy's FMU3Slave where simulate_fmu cannot: String and
Binary values, structural parameters set in Configuration Mode) at the same step.
"""

from __future__ import annotations

import re
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.fmi3 import FMU3Slave

import cosim
from cosim.cli.exit_codes import run_exit_code
from cosim.cli.main import main
from cosim.fmus.conformance import available, ensure_built
from tests.helpers.tools import python_unit

INT_TYPES = ("int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64")


def cli(capsys, *args: str) -> tuple[int, str]:
    code = main(list(args))
    captured = capsys.readouterr()
    return code, captured.out + captured.err


@pytest.fixture(scope="module")
def types_fmu() -> Path:
    return ensure_built("types", 3)


def test_inspect_lists_every_fmi3_type_with_binary_start_in_hex(capsys, types_fmu):
    code, text = cli(capsys, "inspect", str(types_fmu))
    assert code == 0, text
    for kind in ("Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64", "Float32",
                 "Enumeration", "Boolean", "String", "Binary", "Clock"):
        assert re.search(rf"\s{kind}\s", text), kind
    assert re.search(r"data_in\s+input\s+Binary\s+scalar\s+0a0bfe", text)  # name causality type shape (unit) start
    assert re.search(r"u_uint64\s+input\s+UInt64\s+scalar\s+18446744073709551613", text)  # exact, not via a float


def test_every_type_runs_like_fmpy(write_spec, types_fmu):
    """Numbers against simulate_fmu; String and Binary against fmpy's slave read at every step."""
    outputs = [f"y_{t}" for t in INT_TYPES] + ["y_float32", "mode", "odd"]
    spec = {"units": {"t": {"fmu": str(types_fmu)}}, "experiment": {"stop": 0.5, "step": 0.1},
            "record": ["t.*"]}
    result = cosim.run(str(write_spec(spec)), record=True)
    assert result.ok, result.message
    ours = result.traces
    strings, binaries = [], []

    def read_non_numeric(time, recorder):
        strings.append(recorder.fmu.getString([26])[0])
        binaries.append(recorder.fmu.getBinary([28])[0].hex())
        return True

    reference = simulate_fmu(str(types_fmu), stop_time=0.5, output_interval=0.1, output=outputs,
                             step_finished=read_non_numeric)
    assert len(ours) == len(reference) == 6
    for name in outputs:
        expected = reference[name]
        got = ours[f"t.{name}"].to_numpy()
        if name == "y_float32":
            np.testing.assert_array_equal(got, expected.astype(np.float64))
        else:
            assert [int(v) for v in got] == [int(v) for v in expected], name  # exact, 64-bit included
    assert ours["t.y_uint64"].dtype == np.uint64 and ours["t.odd"].dtype == bool
    # the counters wrap in their own width at k = 3, as in C
    assert list(ours["t.y_int8"]) == [125, 126, 127, -128, -127, -126]
    assert list(ours["t.y_uint64"])[3] == 0
    assert list(ours["t.label"])[1:] == strings == [f"step {k}" for k in range(1, 6)]
    assert list(ours["t.data_out"])[1:] == binaries == [bytes([0x0a + k, 0x0b + k, (0xfe + k) % 256]).hex()
                                                         for k in range(1, 6)]


def test_binary_and_string_connections_and_values_from_the_spec(write_spec, types_fmu, tmp_path):
    spec = {"units": {"a": {"fmu": str(types_fmu), "start": {"name": "abc", "data_in": "00ff"}},
                      "b": {"fmu": str(types_fmu)}},
            "connections": [{"from": "a.data_out", "to": "b.data_in"}, {"from": "a.label", "to": "b.name"},
                            {"from": "a.y_uint64", "to": "b.u_uint64"}],
            "experiment": {"stop": 0.3, "step": 0.1},
            "record": ["a.data_out", "a.label", "b.data_out", "b.label", "b.y_uint64"]}
    path = write_spec(spec)
    out = tmp_path / "traces.parquet"
    assert main(["run", str(path), "--out", str(out)]) == 0
    traces = pd.read_parquet(out)
    # Gauss-Seidel: b gets a's outputs of the same step, then adds its own step count k
    assert list(traces["a.data_out"]) == ["00ff", "0100", "0201", "0302"]
    assert list(traces["b.data_out"])[1:] == ["0201", "0403", "0605"]
    assert list(traces["b.label"])[1:] == ["abc 1 1", "abc 2 2", "abc 3 3"]
    assert [int(v) for v in traces["b.y_uint64"]][1:] == [2**64 - 1, 1, 3]  # UInt64 through the master exactly


def test_binary_into_a_float_is_refused_and_reductions_need_numbers(capsys, write_spec, types_fmu):
    spec = {"units": {"a": {"fmu": str(types_fmu)}, "b": {"fmu": str(types_fmu)}},
            "connections": [{"from": "a.data_out", "to": "b.u_float32"}, {"from": "a.clock", "to": "b.u_int8"}],
            "experiment": {"stop": 0.3, "step": 0.1}, "record": ["a.clock"],
            "objectives": {"l": {"signal": "a.label", "reduce": "final"}}}
    path = write_spec(spec)
    code, text = cli(capsys, "validate", str(path))
    assert code == 2 and "Traceback" not in text
    assert f"{path}: $.connections[0]: type mismatch: 'a.data_out' is Binary, 'b.u_float32' is Real" in text
    assert "Binary connects only to Binary" in text
    assert f"{path}: $.connections[1]: 'a.clock' -> 'b.u_int8' connects an FMI 3.0 Clock" in text
    assert f"{path}: $.record[0]: 'a.clock' is an FMI 3.0 Clock" in text
    assert (f"{path}: $.objectives.l.signal: 'a.label' is String: only numeric signals (Real, Integer, Boolean) "
            "reduce to an objective") in text


def _fmpy_structural(path: Path, n: int, m: int, step: float, stop: float) -> list[tuple[list[float], list[float]]]:
    """y and z at every communication point, by fmpy's slave with n and m set in Configuration Mode."""
    md = read_model_description(str(path))
    unzipped = Path(fmpy_extract(path))
    slave = FMU3Slave(guid=md.guid, unzipDirectory=str(unzipped), modelIdentifier="structural", instanceName="s")
    slave.instantiate()
    slave.enterConfigurationMode()
    slave.setUInt64([1, 2], [n, m])
    slave.exitConfigurationMode()
    slave.enterInitializationMode(startTime=0.0, stopTime=stop)
    slave.exitInitializationMode()
    rows, n_steps = [], int(round(stop / step))
    for k in range(n_steps + 1):
        rows.append((list(slave.getFloat64([5], nValues=n)), list(slave.getFloat64([6], nValues=n * m))))
        if k < n_steps:
            # as simulate_fmu does: communication points k*step, the last one the stop time itself
            following = stop if k + 1 == n_steps else (k + 1) * step
            slave.doStep(currentCommunicationPoint=k * step, communicationStepSize=following - k * step)
    slave.terminate()
    slave.freeInstance()
    return rows


def fmpy_extract(path: Path) -> str:
    from fmpy import extract

    return extract(str(path))


@pytest.mark.parametrize("n, m", [(3, 2), (5, 3)])
def test_structural_parameters_size_arrays(capsys, write_spec, n, m):
    fmu = ensure_built("structural", 3)
    parameters = {} if (n, m) == (3, 2) else {"n": n, "m": m}
    spec = {"units": {"s": {"fmu": str(fmu), "parameters": parameters}},
            "experiment": {"stop": 0.3, "step": 0.1}, "record": ["s.y", "s.z"]}
    path = write_spec(spec)
    code, text = cli(capsys, "inspect", str(path))
    assert code == 0 and "s: FMI 3.0" in text
    result = cosim.run(str(path), record=True)
    assert result.ok, result.message
    traces = result.traces
    assert [c for c in traces.columns if c.startswith("s.y")] == [f"s.y[{i}]" for i in range(1, n + 1)]
    assert len([c for c in traces.columns if c.startswith("s.z")]) == n * m
    expected = _fmpy_structural(fmu, n, m, 0.1, 0.3)
    for k, (y, z) in enumerate(expected):
        assert traces.loc[k, [f"s.y[{i}]" for i in range(1, n + 1)]].tolist() == y
        assert traces.loc[k, [f"s.z[{i}]" for i in range(1, n * m + 1)]].tolist() == z
    t = traces["time"].to_numpy()
    np.testing.assert_array_equal(traces[f"s.y[{n}]"].to_numpy(), 2.0 * n + n * t)  # y = k u + (i+1) t, u = i+1


def test_structural_parameter_size_is_checked_and_not_a_design_parameter(capsys, write_spec):
    fmu = ensure_built("structural", 3)
    spec = {"units": {"s": {"fmu": str(fmu), "parameters": {"n": 4}, "start": {"u": [1, 2, 3]}},
                      "g": {"python": python_unit("Clock")}},
            "connections": [{"from": "g.vec", "to": "s.u"}],
            "experiment": {"stop": 0.3, "step": 0.1},
            "design": {"parameters": {"s.n": {"values": [2, 3]}}}}
    path = write_spec(spec)
    code, text = cli(capsys, "validate", str(path))
    assert code == 2
    assert f"{path}: $.units.s.start.u: 'u' has 4 elements, got 3 values" in text
    assert "size mismatch: 'g.vec' has 3 element(s), 's.u' has 4" in text
    assert "'n' of unit 's' is a structural parameter" in text


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("step", [0.2, 0.4])
def test_stair_ends_the_run_early_like_fmpy(write_spec, version, step):
    fmu = ensure_built("stair", version)
    spec = {"units": {"stair": {"fmu": str(fmu)}}, "experiment": {"stop": 10.0, "step": step},
            "record": ["stair.*"], "objectives": {"top": {"signal": "stair.counter", "reduce": "final"},
                                                  "t_top": {"signal": "stair.counter", "reduce": "time_of_max"}}}
    result = cosim.run(str(write_spec(spec)), record=True)
    reference = simulate_fmu(str(fmu), stop_time=10.0, output_interval=step)
    assert result.ok and result.message.startswith("stopped early: unit 'stair' ended the simulation"), result.message
    assert result.end_time == pytest.approx(reference["time"][-1], abs=1e-12)
    # FMI 2.0 reports the last successful time (9 s); FMI 3.0 without early return completes its step
    assert reference["time"][-1] == pytest.approx(9.0 if version == 2 or step == 0.2 else 9.2)
    np.testing.assert_allclose(result.traces["time"], reference["time"], rtol=0, atol=1e-12)
    assert list(result.traces["stair.counter"]) == list(reference["counter"])
    assert result.objectives["top"] == 10.0
    assert list(result.traces["stair.phase"])[-2:] == ["climbing", "top"]


def test_early_stop_can_be_a_failure(write_spec):
    spec = {"units": {"stair": {"fmu": str(ensure_built("stair", 2))}},
            "experiment": {"stop": 10.0, "step": 0.5, "early_stop": "fail"},
            "objectives": {"top": {"signal": "stair.counter", "reduce": "final"}}}
    result = cosim.run(str(write_spec(spec)))
    assert result.status == "failed" and run_exit_code(result) == 1
    assert "stopped early" in result.message and "early_stop is 'fail'" in result.message
    assert result.end_time == 9.0


def test_a_clocks_fmu_is_refused_as_scheduled_execution(capsys, write_spec):
    spec = {"units": {"c": {"fmu": str(ensure_built("clocks", 3))}}, "experiment": {"stop": 1, "step": 0.1}}
    path = write_spec(spec)
    code, text = cli(capsys, "validate", str(path))
    assert code == 2
    assert "does not support co-simulation (scheduled execution (FMI 3.0 clocks) only)" in text
    assert "model exchange only" not in text


def test_string_outputs_in_a_recorded_table_do_not_break_a_player(write_spec, tmp_path):
    table = tmp_path / "rec.csv"
    pd.DataFrame({"time": [0.0, 1.0], "x": [1.0, 3.0], "label": ["a", "b"]}).to_csv(table, index=False)
    spec = {"units": {"p": {"player": "rec.csv"}}, "experiment": {"stop": 1.0, "step": 0.5}, "record": ["p.*"]}
    result = cosim.run(str(write_spec(spec)), record=True)
    assert result.ok, result.message
    assert list(result.traces.columns) == ["time", "p.x"] and list(result.traces["p.x"]) == [1.0, 2.0, 3.0]
    spec["units"]["p"]["columns"] = ["label"]
    with pytest.raises(cosim.SpecError, match="column\\(s\\) label are not numbers"):
        cosim.build_system(cosim.load_spec(write_spec(spec, "s2.json")))


def _without_dependencies(source: Path, target: Path) -> Path:
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(target, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = re.sub(rb'\s+dependencies="[^"]*"', b"", data)
            zout.writestr(item, data)
    return target


def test_undeclared_dependencies_are_named_in_the_loop_message_and_can_be_declared(capsys, write_spec, built_fmu,
                                                                                   tmp_path):
    _without_dependencies(built_fmu("gain_array", 2), tmp_path / "gain.fmu")  # written beside the spec
    spec = {"units": {"g1": {"fmu": "gain.fmu"}, "g2": {"fmu": "gain.fmu"}},
            "connections": [{"from": "g1.y", "to": "g2.u"}, {"from": "g2.y", "to": "g1.u"}],
            "experiment": {"stop": 0.3, "step": 0.1}}
    path = write_spec(spec)
    code, text = cli(capsys, "validate", str(path))
    assert code == 0, text  # a loop of Real signals is solved (tests/master/test_algebraic_loops.py), not refused
    code, text = cli(capsys, "inspect", str(path))
    assert code == 0
    assert ("loop through units g1, g2: tearing" in text
            and "unit(s) g1, g2 declare no dependencies for their outputs, so every output is assumed to depend "
                "directly on every input" in text)
    assert '"feedthrough"' in text
    # where the loop cannot be solved (a master algorithm that does not solve loops) validate names the assumption
    spec["experiment"]["algorithm"] = "jacobi-delayed"
    code, text = cli(capsys, "validate", str(write_spec(spec, "delayed.json")))
    assert code == 2
    assert ("algebraic loop through units g1, g2" in text
            and "unit(s) g1, g2 declare no dependencies for their outputs, so every output is assumed to depend "
                "directly on every input" in text)
    assert '"feedthrough"' in text
    spec["units"]["g2"]["feedthrough"] = {"y": []}
    code, text = cli(capsys, "validate", str(write_spec(spec)))
    assert code == 0, text
    code, text = cli(capsys, "inspect", str(write_spec(spec)))
    assert code == 0 and "algebraic loops: none" in text
    spec["units"]["g2"]["feedthrough"] = {"yy": ["u", "v"]}
    code, text = cli(capsys, "validate", str(write_spec(spec)))
    assert code == 2 and "$.units.g2.feedthrough.yy: 'yy' is not an output of unit 'g2'" in text


def test_range_message_without_a_maximum(capsys, write_spec):
    spec = {"units": {"e": {"fmu": "builtin:motor_gear_energy_fmi3", "parameters": {"r_terminal": -1.0}}},
            "experiment": {"stop": 0.1, "step": 0.1}}
    code, text = cli(capsys, "validate", str(write_spec(spec)))
    assert code == 2 and "-1.0 is outside the range of 'r_terminal' [0, inf]" in text


def test_inspect_counts_fmi2_arrays_once_and_reports_needs_execution_tool(capsys, write_spec, built_fmu, tmp_path):
    spec = {"units": {"g": {"fmu": str(built_fmu("gain_array", 2))}}, "experiment": {"stop": 0.1, "step": 0.1}}
    code, text = cli(capsys, "inspect", str(write_spec(spec)))
    assert code == 0 and "(1 inputs, 1 outputs)" in text
    tool = tmp_path / "tool.fmu"
    with zipfile.ZipFile(built_fmu("gain_array", 3)) as zin, zipfile.ZipFile(tool, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = re.sub(rb'needsExecutionTool="false"', b'needsExecutionTool="true"', data)
                if b"needsExecutionTool" not in data:
                    data = data.replace(b"<CoSimulation", b'<CoSimulation needsExecutionTool="true"', 1)
            zout.writestr(item, data)
    code, text = cli(capsys, "inspect", str(tool))
    assert code == 0 and "needsExecutionTool: the FMU drives its exporting tool" in text


def test_fmi_call_names_follow_the_fmi_version():
    from cosim.units.fmu.fmi2 import Fmi2Unit
    from cosim.units.fmu.fmi3 import Fmi3Unit

    assert Fmi2Unit.call_name(Fmi2Unit, "Set", "Enumeration") == "fmi2SetInteger"
    assert Fmi3Unit.call_name(Fmi3Unit, "Set", "Enumeration") == "fmi3SetInt64"
    assert Fmi3Unit.call_name(Fmi3Unit, "Get", "Binary") == "fmi3GetBinary"


def test_a_python_unit_can_end_the_run_early(write_spec):
    spec = {"units": {"e": {"python": python_unit("EndsAtHalf")}}, "experiment": {"stop": 1.0, "step": 0.1},
            "record": ["e.n"], "objectives": {"n": {"signal": "e.n", "reduce": "final"}}}
    result = cosim.run(str(write_spec(spec)), record=True)
    assert result.ok and result.message == "stopped early: unit 'e' reached its end at t=0.5 (stop time 1)"
    assert list(result.traces["e.n"]) == [0, 1, 2, 3, 4, 5] and result.objectives["n"] == 5.0


def test_reference_check_script_on_our_own_fmus(tmp_path):
    """cosim.cli.reference_check (used on the Modelica Reference FMUs, see docs/fmi-support.md)."""
    from cosim.cli.reference_check import check

    stair = check(ensure_built("stair", 3), tmp_path)
    assert stair["result"] == "exact" and "to t=9, stopped early" in stair["detail"]
    structural = check(ensure_built("structural", 3), tmp_path)
    assert structural["result"] == "exact" and structural["detail"].startswith("2 outputs, 11 samples")
    clocks = check(ensure_built("clocks", 3), tmp_path)
    assert clocks["result"] == "refused" and "scheduled execution (FMI 3.0 clocks) only" in clocks["detail"]


def test_reference_check_stops_an_fmu_that_runs_too_long(tmp_path, capsys):
    """Issue 39: docs/fmi-support.md's check command hung on the Reference FMU Roberts (a default experiment of
    1e10 internal solver steps); each FMU now has --timeout seconds and is reported 'timed out', the rest go on."""
    import time

    from cosim.cli.reference_check import check_bounded
    from cosim.cli.reference_check import main as reference_main

    started = time.monotonic()
    # 1e8 steps: hours; a bound of 2 s stops it as surely as 8 did (the child spent the whole bound on CPU)
    row = check_bounded(ensure_built("structural", 3), tmp_path, 1e5, 1e-3, 2.0)
    assert time.monotonic() - started < 60
    assert row["result"] == "timed out" and row["fmi"] == "3.0"
    assert row["detail"] == ("no result within 2 s over --stop 100000, --step 0.001; give a shorter --stop "
                             "(or a longer --timeout)")
    # within the bound the same FMU is checked as before
    assert reference_main([str(ensure_built("structural", 3)), "--timeout", "120"]) == 0
    assert "exact" in capsys.readouterr().out


@pytest.mark.parametrize("name, version", [(n, v) for n, versions in sorted(available().items()) for v in versions])
def test_every_conformance_fmu_goes_through_cosim_inspect(capsys, name, version):
    code, text = cli(capsys, "inspect", str(ensure_built(name, version)))
    if name == "clocks":  # scheduled execution only: refused, with the reason
        assert code == 2 and "scheduled execution (FMI 3.0 clocks) only" in text
    else:
        assert code == 0 and f"FMI {version}.0 co-simulation" in text and "Traceback" not in text


def test_trace_figures_leave_text_columns_out(write_spec):
    from matplotlib.figure import Figure

    from cosim.analysis.traces import trace_groups, traces_figure

    spec = {"units": {"t": {"fmu": str(ensure_built("types", 3))}}, "experiment": {"stop": 0.3, "step": 0.1},
            "record": ["t.*"]}
    traces = cosim.run(str(write_spec(spec)), record=True).traces
    names = [c for _, cols in trace_groups(traces) for c in cols]
    assert "t.label" not in names and "t.data_out" not in names and "t.y_int8" in names
    assert len(traces_figure(Figure(), traces)) == len(trace_groups(traces))
