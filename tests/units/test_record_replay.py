"""Record and replay in one line: `cosim run spec.json --out rec.parquet`, then `"unit": {"player": "rec.parquet"}`.

The recording holds every output (the spec needs no `record` list), Booleans stay Booleans, and the spec is
otherwise unchanged: the replaced unit's input connections and parameter values are not needed, its signals
keep their names (no `energy.energy.e_total`), and a sweep explains why it cannot vary a replayed unit.
"""

from __future__ import annotations

import json

import pandas as pd
import pytest

import cosim
from cosim.cli.main import main
from cosim.studies.sweep import Sweep, SweepError
from tests.helpers.tools import python_unit
from tests.units.test_fmu_units import energy_spec


def whole_system() -> dict:
    spec = energy_spec({"fmu": "builtin:motor_gear_energy_fmi3", "parameters": {"gear_ratio": 120}})
    del spec["record"]  # nothing asked: `run --out` records every output
    spec["design"] = {"parameters": {"energy.gear_ratio": {"values": [100, 120]}}}
    return spec


def test_run_out_records_every_output_and_says_so(write_spec, tmp_path, capsys):
    rec = tmp_path / "rec.parquet"
    assert main(["run", str(write_spec(whole_system())), "--out", str(rec)]) == 0
    out = capsys.readouterr().out
    assert "recording every output of drive, energy (the spec has no 'record' list)" in out
    traces = pd.read_parquet(rec)
    for column in ("drive.tau[7]", "drive.omega[1]", "energy.e_total", "energy.p_total", "energy.e_el[3]"):
        assert column in traces.columns, column
    assert f"traces: {rec} (2001 rows, {len(traces.columns) - 1} signals: drive.tau[1]," in out


@pytest.mark.parametrize("replaced", ["drive", "energy"])
def test_a_player_replaces_a_recorded_unit_with_the_spec_otherwise_unchanged(write_spec, tmp_path, replaced):
    whole = whole_system()
    rec = tmp_path / "rec.parquet"
    assert main(["run", str(write_spec(whole, "whole.json")), "--out", str(rec)]) == 0
    replay = json.loads(json.dumps(whole))
    # the one-line change: parameters, connections into it, objectives on it and the design all stay
    replay["units"][replaced] = {"player": "rec.parquet", **{k: v for k, v in whole["units"][replaced].items()
                                                              if k == "parameters"}}
    a = cosim.run(str(write_spec(whole, "whole.json")), record=False)
    b = cosim.run(str(write_spec(replay, "replay.json")), record=True)
    assert a.ok and b.ok, b.message
    assert b.objectives.keys() == a.objectives.keys()
    for name, value in a.objectives.items():
        assert b.objectives[name] == pytest.approx(value, rel=1e-9, abs=1e-12), name
    # recording the replayed unit again gives the recorded names, not '<unit>.<unit>.<port>'
    again = cosim.build_system(cosim.load_spec(write_spec(replay, "replay.json"))).recording_all_outputs()
    names = set(again.recorded)
    assert f"{replaced}.{replaced}." not in " ".join(names)
    assert (f"{replaced}.e_total" if replaced == "energy" else f"{replaced}.tau[1]") in " ".join(names)
    # a sweep cannot vary the replayed unit, and says why
    if replaced == "energy":
        with pytest.raises(SweepError, match=r"unit 'energy' is a player of rec.parquet .* would vary nothing"):
            Sweep(write_spec(replay, "replay.json"), out=tmp_path / "sweep")


def test_a_recorded_boolean_replays_as_a_boolean_that_can_stop_the_run(write_spec, tmp_path):
    clock = {"units": {"clock": {"python": python_unit("Clock"), "parameters": {"t_end": 0.35}}},
             "experiment": {"stop": 1.0, "step": 0.1, "stop_when": "clock.done"}}
    rec = tmp_path / "rec.parquet"
    assert main(["run", str(write_spec(clock, "clock.json")), "--out", str(rec)]) == 0
    traces = pd.read_parquet(rec)
    assert traces["clock.done"].dtype == bool and traces["clock.done"].tolist()[-1]
    replay = {**clock, "units": {"clock": {"player": "rec.parquet", "parameters": {"t_end": 0.35}}},
              "experiment": {"stop": 1.0, "step": 0.05, "stop_when": "clock.done"},
              "record": ["clock.done"], "objectives": {"t_stop": {"signal": "clock.time", "reduce": "final"}}}
    result = cosim.run(str(write_spec(replay, "replay.json")))
    assert result.ok, result.message
    # stepped at 0.05 s: linear interpolation would make 'done' 0.5 at t = 0.35 and stop early; held, it
    # becomes true at the recorded sample t = 0.4, where the recorded clock also stopped
    assert result.end_time == pytest.approx(0.4)
    assert result.traces["clock.done"].dtype == bool
