"""An SSP without ssd:DefaultExperiment or step size runs as OMSimulator runs it (issue 33, item 3): start 0,
stop 1 s, step 1e-3 s (OMSimulator's flag defaults, src/OMSimulatorLib/Flags.h), with one note naming the values
and the options that change them.  The SSP is tests/data/ssp/oms3.ssd (OMSimulator 3's form) with its
DefaultExperiment and oms_ma step removed, around linear_ode built from src/cosim/fmus/."""

from __future__ import annotations

import json
import logging
import re

import pandas as pd
import pytest

from cosim.cli.main import main
from tests.helpers.ssp_fixtures import oms3_expected, oms3_files, oms3_ssd, write_archive


@pytest.fixture(autouse=True)
def _cosim_notes_reach_caplog(caplog):
    """cosim's notes are INFO records of the 'cosim' loggers; an in-process `cosim` command run earlier in this
    worker may have set that logger's level higher (cli.main does, for its own terminal): set it for each test."""
    caplog.set_level(logging.INFO, logger="cosim")

def _bare_ssd() -> str:
    ssd = re.sub(r"<ssd:DefaultExperiment.*?</ssd:DefaultExperiment>", "", oms3_ssd(), flags=re.S)
    ssd = ssd.replace('fixedStepSize="0.1"', 'fixedStep_removed="0.1"')
    assert "DefaultExperiment" not in ssd and "fixedStepSize" not in ssd
    return ssd


def _notes(caplog) -> str:
    text = "\n".join(r.getMessage() for r in caplog.records)
    caplog.clear()
    return text


def test_an_ssp_without_default_experiment_runs_with_omsimulators_defaults(tmp_path, caplog):
    path = write_archive(tmp_path / "bare.ssp", oms3_files(_bare_ssd()))
    out = tmp_path / "t.csv"
    assert main(["run", str(path), "--out", str(out)]) == 0
    traces = pd.read_csv(out)
    assert len(traces) == 1001 and traces["time"].iloc[-1] == pytest.approx(1.0, abs=1e-12)
    assert traces["time"].iloc[1] == pytest.approx(1e-3, rel=1e-9)
    want = oms3_expected(1.0)
    assert traces["sub.B.y"].iloc[-1] == pytest.approx(want["sub.B.y"], rel=1e-9)
    assert traces["A.y"].iloc[-1] == want["A.y"]
    err = _notes(caplog)
    note = ("the SSP gives no stop time (ssd:DefaultExperiment stopTime) and no step size (OMSimulator "
            "FixedStepMaster or oms_ma fixedStepSize, OSP FixedStepAlgorithm): run with OMSimulator's defaults, "
            "stop 1 s, step 0.001 s; --stop / --step (or a spec's \"experiment\") change them")
    assert err.count(note) == 1, err


def test_the_command_line_and_a_spec_change_the_defaults(tmp_path, caplog):
    path = write_archive(tmp_path / "bare.ssp", oms3_files(_bare_ssd()))
    out = tmp_path / "t.csv"
    assert main(["run", str(path), "--stop", "2", "--out", str(out)]) == 0
    traces = pd.read_csv(out)
    assert len(traces) == 2001 and traces["sub.B.y"].iloc[-1] == pytest.approx(oms3_expected(2.0)["sub.B.y"])
    err = _notes(caplog)
    assert "no stop time" not in err and err.count("no step size") == 1 and "step 0.001 s; --step" in err
    (tmp_path / "spec.json").write_text(json.dumps({"system": "bare.ssp", "experiment": {"step": 0.25},
                                                    "record": ["sub.B.y"]}))
    assert main(["run", str(tmp_path / "spec.json"), "--out", str(out)]) == 0
    traces = pd.read_csv(out)
    assert traces["time"].tolist() == [0.0, 0.25, 0.5, 0.75, 1.0]
    err = _notes(caplog)
    assert "stop 1 s; --stop" in err and "no step size" not in err
