"""A run whose stop equals its start is an initialization-only run (issue 33: vendor forms as given).

OMSimulator runs its testsuite's equationPair (an algebraic loop of two equation FMUs) with stopTime = 0: the units
are initialized, the loop solved at the start, and the values printed. cosim refused ``stop == start`` ("stop (0)
must be after start (0)"). Now such a run initializes the units, records their outputs once at t = start, reduces
the objectives from that one sample (final, min, max and mean are the value; an integral is 0) and terminates them,
on every command and on both the Python master and the native kernel; stop < start stays refused.
"""

from __future__ import annotations

import json
import logging
import zipfile

import pandas as pd
import pytest

from cosim import Execution, build_system, load_spec
from cosim.cli.main import main
from cosim.errors import SpecError
from cosim.fmus.build import ensure_built
from tests.units.test_vendor_numerics import X1_OMS, X1_ROOTS, equation_pair

OBJECTIVES = {"y_end": {"signal": "ode.y", "reduce": "final"}, "y_int": {"signal": "ode.y", "reduce": "integral"},
              "y_max": {"signal": "ode.y", "reduce": "max"}, "y_min": {"signal": "ode.y", "reduce": "min"},
              "y_mean": {"signal": "ode.y", "reduce": "mean"}}


def decay_at_rest(kernel: str, start: float = 0.5) -> dict:
    """x' = a x from x0 = 3: at t = start, before any step, y = 3 whatever a is."""
    return {"name": "init_only", "units": {"ode": {"fmu": "builtin:linear_ode_fmi3", "parameters": {"x0": 3.0}}},
            "experiment": {"start": start, "stop": start, "step": 0.01, "kernel": kernel},
            "record": ["ode.y"], "objectives": OBJECTIVES,
            "design": {"parameters": {"ode.a": {"values": [-1.0, -2.0]}}}}


@pytest.mark.parametrize("kernel", ["python", "native"])
def test_stop_equal_to_start_initializes_records_once_and_reduces_that_sample(write_spec, kernel):
    system = build_system(load_spec(write_spec(decay_at_rest(kernel))))
    result = Execution(system, record=True).run()
    assert result.ok, result.message
    assert result.steps == 0 and list(result.traces["time"]) == [0.5] and list(result.traces["ode.y"]) == [3.0]
    assert result.objectives == {"y_end": 3.0, "y_int": 0.0, "y_max": 3.0, "y_min": 3.0, "y_mean": 3.0}


def test_the_run_says_it_is_initialization_only_once_and_a_sweep_gives_rows(write_spec, tmp_path, capsys, caplog):
    path = write_spec(decay_at_rest("auto"))
    caplog.set_level(logging.WARNING, logger="cosim")
    assert main(["run", str(path), "--out", str(tmp_path / "t.csv")]) == 0
    notes = [r.getMessage() for r in caplog.records if "initialization-only run" in r.getMessage()]
    assert len(notes) == 1 and "$.experiment: stop = start = 0.5 s" in notes[0]
    assert pd.read_csv(tmp_path / "t.csv").to_dict("list") == {"time": [0.5], "ode.y": [3.0]}
    assert main(["sweep", str(path), "--out", str(tmp_path / "out"), "--workers", "1", "-q"]) == 0
    rows = pd.read_parquet(tmp_path / "out" / "results.parquet")
    assert list(rows["status"]) == ["ok", "ok"] and list(rows["y_end"]) == [3.0, 3.0]
    assert list(rows["y_int"]) == [0.0, 0.0]


def test_stop_before_start_is_still_refused_with_the_fix(write_spec):
    spec = decay_at_rest("auto")
    spec["experiment"]["stop"] = 0.25
    with pytest.raises(SpecError) as error:
        load_spec(write_spec(spec))
    (problem,) = [p for p in error.value.problems if p.path == "$.experiment.stop"]
    assert "stop (0.25) must not be before start (0.5)" in problem.message
    assert "equal: an initialization-only run" in problem.fix


@pytest.mark.parametrize("version", [2, 3])
def test_the_equation_pair_at_stop_time_zero_gives_what_omsimulator_prints(write_spec, version):
    """equationPair.py: stopTime 0, then x1 printed as 4.5572: the loop is solved at initialization."""
    spec = equation_pair(version)
    spec["experiment"].update(stop=0.0)
    system = build_system(load_spec(write_spec(spec)))
    result = Execution(system, record=True).run()
    assert result.ok, result.message
    x1 = result.traces["equation2.y"].to_numpy()
    assert len(x1) == 1 and f"{x1[0]:.4f}" == X1_OMS and abs(x1[0] - X1_ROOTS[0]) < 1e-9


PAIR_SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
  xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" name="equationPair" version="1.0">
  <ssd:System name="model">
    <ssd:Elements>
      <ssd:Component name="equation1" source="resources/equation1.fmu">
        <ssd:Connectors>
          <ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
      <ssd:Component name="equation2" source="resources/equation2.fmu">
        <ssd:Connectors>
          <ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="equation2" startConnector="y" endElement="equation1" endConnector="u"/>
      <ssd:Connection startElement="equation1" startConnector="y" endElement="equation2" endConnector="u"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="0"/>
</ssd:SystemStructureDescription>
"""


def test_an_ssp_with_stop_time_equal_to_start_time_runs_as_given(tmp_path, capsys):
    """The SSP as OMSimulator's test sets it up (DefaultExperiment stopTime 0), its two FMUs' parameters set by a
    spec beside it: one row at t = 0 holding the root the tool prints."""
    ssp = tmp_path / "equationPair.ssp"
    with zipfile.ZipFile(ssp, "w") as archive:
        archive.writestr("SystemStructure.ssd", PAIR_SSD)
        for name in ("equation1", "equation2"):
            archive.write(ensure_built("algebraic", 2), f"resources/{name}.fmu")
    pair = equation_pair(2)
    spec = {"system": {"ssp": str(ssp)},
            "units": {name: {"parameters": unit["parameters"]} for name, unit in pair["units"].items()},
            "record": ["equation2.y"]}
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    out = tmp_path / "out.csv"
    assert main(["run", str(tmp_path / "spec.json"), "--out", str(out)]) == 0, capsys.readouterr()
    traces = pd.read_csv(out)
    assert list(traces["time"]) == [0.0] and f"{traces['equation2.y'][0]:.4f}" == X1_OMS
