"""Event rows in the traces of model-exchange units (issue 25 item 15, ``"record_events": true``).

The bouncing ball (fmus/bouncing_ball, integrated by cosim with CVode) dropped from h0 at rest hits the floor
at t_1 = sqrt(2 h0 / g) with speed sqrt(2 g h0) and leaves it with e times that speed; each flight after bounce
k lasts 2 e^k sqrt(2 h0 / g).  The event rows are compared with those times and speeds, computed here.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from cosim.cli.main import main
from cosim.errors import SpecError
from cosim.execution.run import Execution
from cosim.system.validate import check_spec

G, E, H0, STOP, STEP = 9.81, 0.7, 1.0, 2.0, 0.1


def _bounces(stop: float) -> list[tuple[float, float]]:
    """(time, speed at impact) of every bounce before ``stop``, from free fall (not by cosim)."""
    out, t, speed = [], math.sqrt(2 * H0 / G), math.sqrt(2 * G * H0)
    while t < stop:
        out.append((t, speed))
        speed *= E
        t += 2 * speed / G
    return out


def _spec(version: int, record_events: bool = True, algorithm: str = "gauss-seidel") -> dict:
    return {
        "units": {"ball": {"fmu": f"builtin:bouncing_ball_fmi{version}", "tolerance": 1e-10, "max_step": 0.01,
                           "parameters": {"h0": H0, "e": E, "g": G}, "record_events": record_events},
                  # a co-simulation unit beside it: y = t (a = 0, b = 1, u = 1 held), exact at every step
                  "clock": {"fmu": "builtin:linear_ode_fmi2", "parameters": {"a": 0.0, "b": 1.0, "x0": 0.0},
                            "start": {"u": 1.0}}},
        "experiment": {"stop": STOP, "step": STEP, "algorithm": algorithm},
        "record": ["ball.h", "ball.v", "ball.bounces", "clock.y"],
        "objectives": {"v_max": {"signal": "ball.v", "reduce": "max"}, "v_min": {"signal": "ball.v", "reduce": "min"},
                       "bounces": {"signal": "ball.bounces", "reduce": "final"}},
    }


def _run(tmp_path, spec: dict, name: str = "spec.json"):
    (tmp_path / name).write_text(json.dumps(spec))
    result = Execution(check_spec(tmp_path / name), record=True).run()
    assert result.ok, result.message
    return result


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_each_bounce_adds_a_row_before_and_after_it_at_the_bounce_time(tmp_path, version, algorithm):
    with_events = _run(tmp_path, _spec(version, True, algorithm), "events.json")
    without = _run(tmp_path, _spec(version, False, algorithm), "plain.json")
    traces, plain = with_events.traces, without.traces
    grid = [k * STEP for k in range(round(STOP / STEP) + 1)]
    assert plain["time"].tolist() == pytest.approx(grid, abs=1e-12)
    times = traces["time"].to_numpy()
    assert np.all(np.diff(times) >= 0)  # in time order; an event's two rows share its time

    on_grid = np.isin(np.arange(len(traces)), [int(i) for i in np.flatnonzero(
        np.min(np.abs(times[:, None] - np.array(grid)[None, :]), axis=1) < 1e-12)])
    # the communication rows are the rows of the run without event rows, bit for bit
    assert np.array_equal(traces[on_grid].to_numpy(), plain.to_numpy())
    events = traces[~on_grid].reset_index(drop=True)
    expected = _bounces(STOP)
    assert len(expected) == 4 and len(events) == 2 * len(expected)
    for k, (t_bounce, speed) in enumerate(expected, start=1):
        before, after = events.iloc[2 * k - 2], events.iloc[2 * k - 1]
        assert before["time"] == after["time"] == pytest.approx(t_bounce, abs=1e-6)
        assert before["ball.v"] == pytest.approx(-speed, rel=1e-5)  # falling
        assert after["ball.v"] == pytest.approx(E * speed, rel=1e-5)  # leaving the floor
        assert abs(before["ball.h"]) < 1e-6 and abs(after["ball.h"]) < 1e-6
        assert (before["ball.bounces"], after["ball.bounces"]) == (k - 1, k)
        # the other unit is not read inside the ball's step: its column holds the last row's value
        last = traces[(traces["time"] < t_bounce) & on_grid].iloc[-1]
        assert before["clock.y"] == after["clock.y"] == last["clock.y"]
        assert last["clock.y"] == pytest.approx(math.floor(t_bounce / STEP) * STEP, rel=1e-12)
    # objectives reduce the communication points only
    assert with_events.objectives == without.objectives


def test_event_rows_reach_the_traces_file_of_cosim_run(tmp_path):
    (tmp_path / "spec.json").write_text(json.dumps(_spec(3)))
    assert main(["run", str(tmp_path / "spec.json"), "--out", str(tmp_path / "traces.csv")]) == 0
    table = pd.read_csv(tmp_path / "traces.csv")
    assert len(table) == round(STOP / STEP) + 1 + 2 * len(_bounces(STOP))
    first = table[(table["time"] > 0.4) & (table["time"] < 0.5)]
    assert first["time"].tolist() == pytest.approx([_bounces(STOP)[0][0]] * 2, abs=1e-6)


def test_record_events_is_refused_for_a_co_simulation_unit_and_under_the_adaptive_algorithm(tmp_path):
    spec = _spec(3)
    spec["units"]["clock"]["record_events"] = True
    (tmp_path / "cs.json").write_text(json.dumps(spec))
    with pytest.raises(SpecError) as caught:
        check_spec(tmp_path / "cs.json")
    [problem] = caught.value.problems
    assert (problem.path, problem.message) == (
        "$.units.clock.record_events", "'clock' runs as co-simulation: its events happen inside the FMU, where "
                                       "cosim does not see them")
    assert "model-exchange" in problem.fix
    spec = _spec(3, algorithm="adaptive")
    (tmp_path / "adaptive.json").write_text(json.dumps(spec))
    with pytest.raises(SpecError) as caught:
        check_spec(tmp_path / "adaptive.json")
    [problem] = caught.value.problems
    assert problem.path == "$.units.ball.record_events" and "repeats the steps it rejects" in problem.message
    spec = _spec(3)
    spec["experiment"]["warm_start"] = 0.5
    (tmp_path / "warm.json").write_text(json.dumps(spec))
    with pytest.raises(SpecError) as caught:
        check_spec(tmp_path / "warm.json")
    assert [p.path for p in caught.value.problems] == ["$.units.ball.record_events"]
    assert "warm-up's samples" in caught.value.problems[0].message


def test_a_unit_integrated_in_a_group_records_its_events_too(tmp_path):
    # the ball's height drives a model-exchange linear_ode (y' = h): both are integrated together by one CVode
    # (a group), which handles the ball's events; the ball's rows are as when it is integrated alone
    spec = _spec(3)
    spec["units"]["area"] = {"fmu": "builtin:linear_ode_fmi3", "interface": "model-exchange", "tolerance": 1e-10,
                             "parameters": {"a": 0.0, "b": 1.0, "x0": 0.0}}
    spec["connections"] = [{"from": "ball.h", "to": "area.u"}]
    spec["record"].append("area.y")
    (tmp_path / "group.json").write_text(json.dumps(spec))
    system = check_spec(tmp_path / "group.json")
    assert [sorted(g.members) for g in system.model_exchange.groups] == [["area", "ball"]]
    traces = Execution(system, record=True).run().traces
    times = traces["time"].to_numpy()
    events = traces[np.min(np.abs(times[:, None] - np.arange(0, STOP + STEP / 2, STEP)[None, :]), axis=1) > 1e-12]
    assert events["time"].tolist() == pytest.approx([t for t, _ in _bounces(STOP) for _ in range(2)], abs=1e-6)
    assert events["ball.v"].tolist() == pytest.approx([v for _, s in _bounces(STOP) for v in (-s, E * s)], rel=1e-5)
    # area does not record events: its column keeps the last row's value, the integral of h up to t = 0.4
    # (h0 t - g t^3 / 6), though the group integrated it to the bounce with the ball
    assert events["area.y"].iloc[0] == pytest.approx(H0 * 0.4 - G * 0.4 ** 3 / 6, rel=1e-6)


def test_every_member_of_a_group_asking_for_it_is_read_at_the_events(tmp_path):
    spec = _spec(3)
    spec["units"]["area"] = {"fmu": "builtin:linear_ode_fmi3", "interface": "model-exchange", "tolerance": 1e-10,
                             "parameters": {"a": 0.0, "b": 1.0, "x0": 0.0}, "record_events": True}
    spec["connections"] = [{"from": "ball.h", "to": "area.u"}]
    spec["record"].append("area.y")
    (tmp_path / "group.json").write_text(json.dumps(spec))
    traces = Execution(check_spec(tmp_path / "group.json"), record=True).run().traces
    times = traces["time"].to_numpy()
    events = traces[np.min(np.abs(times[:, None] - np.arange(0, STOP + STEP / 2, STEP)[None, :]), axis=1) > 1e-12]
    assert len(events) == 2 * len(_bounces(STOP))
    # area.y at the first bounce, read there: the integral of h from 0 to t1 = h0 t1 - g t1^3 / 6
    t1 = _bounces(STOP)[0][0]
    assert events["area.y"].iloc[0] == events["area.y"].iloc[1] == pytest.approx(H0 * t1 - G * t1 ** 3 / 6, rel=1e-6)
