"""Traces with event rows (``"record_events": true``: two rows at each event's time, see tests/execution/test_record_events.py)
in the code that shows or replays traces: a re-run keeps every row, the plots (matplotlib for the Tk explorer and
``traces_figure``, Bokeh for the room) draw each bounce as a vertical step, and a player of such a table replays the
value after the event at its time, with no division by zero between equal times.

The bouncing ball (fmus/bouncing_ball, integrated by CVode) dropped from h0 at rest: bounce times and speeds come
from free fall, computed here (not by cosim).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd
import pytest

from cosim.analysis.rerun import port_groups, rerun_rows
from cosim.analysis.table import load_results
from cosim.analysis.traces import traces_figure
from cosim.cli.main import main
from cosim.units.player import PlayerUnitType
from cosim.units.protocol import ElementRef
from tests.execution.test_record_events import STEP, STOP, E, G, _spec

matplotlib.use("Agg")
HEIGHTS = (1.0, 2.0)  # both bounce a few times before STOP (from 0.5 m it comes to rest before 2 s)


def bounces(h0: float, stop: float = STOP) -> list[tuple[float, float]]:
    """(time, speed at impact) of every bounce of a ball dropped from ``h0`` before ``stop``, by free fall."""
    out, t, speed = [], math.sqrt(2 * h0 / G), math.sqrt(2 * G * h0)
    while t < stop and len(out) < 100:
        out.append((t, speed))
        speed *= E
        t += 2 * speed / G
    return out


def ball_study(folder: Path) -> Path:
    """A results table of two drop heights of the ball (as a sweep writes it), its metadata naming the spec."""
    folder.mkdir(parents=True, exist_ok=True)
    spec = _spec(3)
    spec["design"] = {"parameters": {"ball.h0": {"values": list(HEIGHTS)}}}
    (folder / "spec.json").write_text(json.dumps(spec))
    pd.DataFrame({"point_id": ["h1", "h2"], "ball.h0": list(HEIGHTS), "status": "ok", "message": "",
                  "run_time": 0.01, "worker": "w"}).to_parquet(folder / "results.parquet", index=False)
    (folder / "metadata.json").write_text(json.dumps({"spec_path": str(folder / "spec.json"), "spec": spec}))
    return folder / "results.parquet"


@pytest.fixture(scope="module")
def reruns(tmp_path_factory):
    return rerun_rows(load_results(ball_study(tmp_path_factory.mktemp("ball"))), [0, 1])


def assert_steps(t: np.ndarray, v: np.ndarray, h0: float) -> None:
    """Every bounce of ``h0`` is two consecutive points of the line at its time: falling, then rising (a vertical
    step); every communication point is there too."""
    expected = bounces(h0)
    assert len(t) == round(STOP / STEP) + 1 + 2 * len(expected)
    for t_bounce, speed in expected:
        [i] = np.flatnonzero(np.isclose(t[:-1], t_bounce, atol=1e-6) & (t[:-1] == t[1:]))
        assert v[i] == pytest.approx(-speed, rel=1e-5) and v[i + 1] == pytest.approx(E * speed, rel=1e-5)


def test_a_rerun_keeps_the_event_rows_and_traces_figure_draws_each_bounce_as_a_step(reruns):
    for run, h0 in zip(reruns, HEIGHTS):
        assert run.result.ok, run.result.message
        traces = run.result.traces
        assert_steps(traces["time"].to_numpy(), traces["ball.v"].to_numpy(), h0)
        fig = matplotlib.figure.Figure()
        axes = traces_figure(fig, traces, title=run.point_id)  # what the Tk explorer shows
        [v_line] = [line for ax in axes for line in ax.get_lines() if line.get_label() == "v"]
        assert_steps(np.asarray(v_line.get_xdata()), np.asarray(v_line.get_ydata()), h0)
        [count] = [line for ax in axes for line in ax.get_lines() if line.get_label() == "bounces"]
        x, y = np.asarray(count.get_xdata()), np.asarray(count.get_ydata())
        for k, (t_bounce, _) in enumerate(bounces(h0), start=1):  # the count steps up at the bounce's time
            [i] = np.flatnonzero(np.isclose(x[:-1], t_bounce, atol=1e-6) & (x[:-1] == x[1:]))
            assert (y[i], y[i + 1]) == (k - 1, k)


def test_the_rooms_trace_figures_draw_each_bounce_as_a_step(reruns):
    from cosim.analysis.room import views as V

    recorded = [c for c in reruns[0].result.traces.columns if c != "time"]
    figures = {f.name: f for f in V.trace_figures(port_groups(recorded), reruns)}
    for run, h0 in zip(reruns, HEIGHTS):
        [line] = [r for r in figures["trace:ball.v"].renderers if r.name == f"trace:ball.v:{run.point_id}"]
        data = line.data_source.data
        assert_steps(np.asarray(data["x"]), np.asarray(data["y"]), h0)


@pytest.mark.parametrize("interpolation", ["linear", "hold", "nearest"])
def test_a_player_of_traces_with_event_rows_plays_the_value_after_each_event_at_its_time(tmp_path, interpolation):
    (tmp_path / "spec.json").write_text(json.dumps(_spec(3)))
    assert main(["run", str(tmp_path / "spec.json"), "--out", str(tmp_path / "events.parquet")]) == 0
    table = pd.read_parquet(tmp_path / "events.parquet")
    player = PlayerUnitType(tmp_path / "events.parquet", columns=["ball.v"], interpolation=interpolation)
    unit = player.instantiate("replay")
    selection = unit.select([ElementRef("ball.v")])

    def played(t: float) -> float:
        unit.setup(t, None)
        return unit.get(selection)[0]

    for t_bounce, speed in bounces(1.0):  # _spec drops the ball from 1 m
        [t_event] = table["time"][np.isclose(table["time"], t_bounce, atol=1e-6)].unique()
        assert played(float(t_event)) == pytest.approx(E * speed, rel=1e-5)  # after the event, at its time
        # just before it: the row before the event (linear: all but equal to it; nearest: it), or held from the
        # communication point before that (hold)
        before = played(float(np.nextafter(t_event, 0.0)))
        falling, earlier = table["ball.v"][table["time"] == t_event].iloc[0], table["ball.v"][table["time"] < t_event]
        assert falling == pytest.approx(-speed, rel=1e-5)
        assert before == {"linear": pytest.approx(falling, rel=1e-12), "nearest": falling,
                          "hold": earlier.iloc[-1]}[interpolation]
    grid = np.linspace(0.0, STOP, 2001)
    values = np.array([played(float(t)) for t in grid])
    assert np.all(np.isfinite(values))
    lo, hi = table["ball.v"].min(), table["ball.v"].max()
    assert np.all((values >= lo - 1e-12) & (values <= hi + 1e-12))
