"""Traces of a re-run Panda design: panels chosen from the signals, forward kinematics of the stick figure."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd
import pytest

from cosim.analysis.rerun import rerun
from cosim.analysis.table import load_results
from cosim.analysis.traces import animation, trace_groups, traces_figure
from cosim.models.panda_viewer import arm_animation, arm_points
from tests.helpers.paths import REPO

matplotlib.use("Agg")
pytestmark = pytest.mark.usefixtures("panda_viewer")  # the engine shows robot signals only through it

PICK_AND_PLACE = REPO / "examples" / "pick_and_place" / "spec.json"


def robot_table(folder: Path) -> Path:
    """Two design points of the pick-and-place study as a sweep table naming its spec."""
    folder.mkdir(parents=True, exist_ok=True)
    spec = json.loads(PICK_AND_PLACE.read_text())
    targets = list(spec["design"]["parameters"])
    pd.DataFrame({"point_id": ["p0", "p1"], targets[0]: [-50.0, 0.0], targets[1]: [70.0, 0.0],
                  "status": "ok"}).to_parquet(folder / "results.parquet", index=False)
    (folder / "metadata.json").write_text(json.dumps({"spec_path": str(PICK_AND_PLACE), "spec": spec}))
    return folder / "results.parquet"


@pytest.fixture(scope="module")
def robot_run(tmp_path_factory):
    if not PICK_AND_PLACE.exists():
        pytest.skip("examples/pick_and_place/spec.json is not there")
    table = load_results(robot_table(tmp_path_factory.mktemp("pp")))
    result, values = rerun(table, 0)
    assert result.ok, result.message
    return result, values


def test_rerun_of_a_robot_design_records_everything_and_groups_robot_signals(robot_run):
    result, values = robot_run
    assert list(values.values()) == [-50.0, 70.0]
    traces = result.traces
    groups = dict(trace_groups(traces))
    assert groups["joint angles [rad]"] == [f"robot.q[{i}]" for i in range(1, 8)]
    assert groups["joint torques [N m]"] == [f"robot.tau[{i}]" for i in range(1, 8)]
    assert any("p_el" in c for c in groups["electric power [W]"])
    fig = matplotlib.figure.Figure()
    axes = traces_figure(fig, traces, title="p0")
    assert [a.get_ylabel() for a in axes] == list(groups)
    assert len(axes[0].get_lines()) == 7 and axes[-1].get_xlabel() == "time [s]"
    q_line = axes[0].get_lines()[1]
    assert np.allclose(q_line.get_ydata(), traces["robot.q[2]"])


def test_stick_figure_tool_point_is_the_recorded_end_effector(robot_run):
    traces = robot_run[0].traces
    q = traces[[f"robot.q[{i}]" for i in range(1, 8)]].to_numpy()
    ee = traces[[f"robot.ee_pos[{i}]" for i in range(1, 4)]].to_numpy()
    pts = arm_points(q[::20])
    assert pts.shape == (len(q[::20]), 9, 3)
    assert np.allclose(pts[:, 8], ee[::20], atol=1e-9)
    assert np.allclose(pts[:, 0], 0.0) and np.allclose(pts[:, 1, 2], 0.333)  # base, then joint 1 at 0.333 m


def test_arm_animation_moves_the_arm(robot_run):
    traces = robot_run[0].traces
    fig = matplotlib.figure.Figure()
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    anim = arm_animation(fig, traces, frames=10)
    fig.canvas.draw()
    arm = next(line for line in fig.axes[0].get_lines() if line.get_gid() == "arm")
    start = np.array(arm.get_data_3d())
    anim._func(9)  # the last frame
    end = np.array(arm.get_data_3d())
    assert start.shape == (3, 9) and not np.allclose(start, end)
    q_end = traces[[f"robot.q[{i}]" for i in range(1, 8)]].to_numpy()[-1]
    assert np.allclose(end.T, arm_points(q_end)[0])
    assert arm_animation(fig, traces.drop(columns=["robot.q[3]"])) is None


def test_the_engine_shows_robot_signals_only_through_the_viewer_plug_in(robot_run, panda_viewer):
    """Without the Panda viewer the same traces get one panel per port and no animation; with it, its panels."""
    import ast

    from cosim.analysis.viewers import unregister_viewer

    traces = robot_run[0].traces
    fig = matplotlib.figure.Figure()
    assert dict(trace_groups(traces))["joint angles [rad]"][0] == "robot.q[1]"
    anim = animation(fig, traces)
    assert anim is not None
    unregister_viewer(panda_viewer.name)
    groups = dict(trace_groups(traces))
    assert "joint angles [rad]" not in groups and groups["robot.q"] == [f"robot.q[{i}]" for i in range(1, 8)]
    assert animation(fig, traces) is None
    engine = REPO / "src" / "cosim"
    for path in (p for p in engine.rglob("*.py") if "models" not in p.relative_to(engine).parts):  # no engine module imports the robot models
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
                assert not any(n.split(".")[:1] == ["models"] or n.startswith("cosim.models") for n in names), path


def test_arm_animation_frames_are_evenly_spaced_in_time_when_event_rows_repeat_a_time(robot_run):
    # event rows ("record_events") repeat a time: a burst of 300 rows at one time early in the run must not take
    # the animation's frames (frames by row number showed that instant 6 times out of 10)
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    traces = robot_run[0].traces
    at = len(traces) // 10
    with_events = pd.concat([traces.iloc[:at], traces.iloc[[at] * 300], traces.iloc[at:]], ignore_index=True)
    times = with_events["time"].to_numpy()
    duration = times[-1] - times[0]
    fig = matplotlib.figure.Figure()
    FigureCanvasAgg(fig)
    anim = arm_animation(fig, with_events, frames=10)
    shown = []
    for k in range(10):
        anim._func(k)
        shown.append(float(fig.axes[0].get_title().split()[2]))
    step = float(np.max(np.diff(traces["time"].to_numpy())))
    expected = np.linspace(times[0], times[-1], 10)
    # each frame at the last row at or before its time: within one communication step of it (and its title's 0.01)
    assert np.all(np.abs(np.array(shown) - expected) <= step + 0.005), (shown, expected)
    assert shown.count(round(float(times[at]), 2)) <= 1 and duration > 1.0


def test_link_frames_of_the_arm_are_its_forward_kinematics_at_every_sample(robot_run):
    """The viewer's frames for the browser: base, joints and tool at each sample, one chain, the tool's path."""
    from cosim.models.panda_viewer import VIEWER

    traces = robot_run[0].traces
    frames = VIEWER.link_frames(traces.iloc[::10])
    q = traces[[f"robot.q[{i}]" for i in range(1, 8)]].to_numpy()[::10]
    assert np.array_equal(frames.time, traces["time"].to_numpy()[::10])
    assert np.array_equal(frames.points, arm_points(q))
    assert frames.segments == tuple((k, k + 1) for k in range(8)) and frames.path == 8
    assert frames.labels[0] == "base" and frames.labels[-1] == "tool"
    assert VIEWER.link_frames(traces.drop(columns=["robot.q[7]"])) is None


def test_link_frames_that_do_not_fit_together_name_the_mistake():
    from cosim.analysis.viewers import LinkFrames

    points = np.zeros((4, 3, 3))
    with pytest.raises(ValueError, match=r"points must be \(samples, links, 3\) for 5 times"):
        LinkFrames(np.arange(5.0), points, ((0, 1),))
    with pytest.raises(ValueError, match="a segment names a link outside 0..2"):
        LinkFrames(np.arange(4.0), points, ((0, 3),))
    with pytest.raises(ValueError, match="path link 5"):
        LinkFrames(np.arange(4.0), points, ((0, 1),), path=5)
    with pytest.raises(ValueError, match="2 labels for 3 links"):
        LinkFrames(np.arange(4.0), points, ((0, 1),), labels=("a", "b"))


def test_the_room_draws_segments_as_strokes_and_shows_the_sample_at_or_before_a_time():
    from cosim.analysis.room.animation import frame_at, strokes

    assert strokes([(0, 1), (1, 2), (2, 3)]) == [0, 1, 2, 3]  # a chain: one stroke
    assert strokes([(0, 1), (1, 2), (1, 3), (3, 4)]) == [0, 1, 2, -1, 1, 3, 4]  # a branch starts a stroke
    times = np.array([0.0, 0.1, 0.2, 0.3])
    assert [frame_at(times, t) for t in (-1.0, 0.0, 0.15, 0.2, 0.3, 9.0)] == [0, 0, 1, 2, 3, 3]


def test_the_room_sends_rows_evenly_spaced_in_time_even_where_event_rows_repeat_a_time():
    from cosim.analysis.room.animation import sampled

    t = np.concatenate([np.linspace(0.0, 1.0, 1001)[:101], np.full(500, 0.1), np.linspace(0.0, 1.0, 1001)[101:]])
    traces = pd.DataFrame({"time": t, "y": np.arange(len(t))})
    rows = sampled(traces, 11)
    # at each of 0, 0.1, ..., 1 the last row at or before it (after the burst of event rows at 0.1)
    assert rows["time"].tolist() == pytest.approx(np.linspace(0.0, 1.0, 11).tolist())
    assert rows["y"].tolist()[1] == 600 and rows["y"].iloc[-1] == len(t) - 1
    short = traces.iloc[:50]
    assert sampled(short, 100) is short


def test_the_rooms_motions_come_from_the_viewer_and_a_failing_one_costs_only_the_3d_view(robot_run):
    """motions(): the Panda viewer's frames of each re-run design in its trace colour; a viewer whose link_frames
    raises gives no motions and a note naming it (with a warning), and LinkView's first pose is the projection
    of the frames at the run's start."""
    from bokeh.palettes import Category10_10

    from cosim.analysis.rerun import Rerun
    from cosim.analysis.room import projection as P
    from cosim.analysis.room.animation import AZIMUTH, ELEVATION, LinkView, motions
    from cosim.analysis.viewers import TraceViewer, register_viewer, unregister_viewer

    result, values = robot_run
    runs = [Rerun(0, "p0", values, result), Rerun(1, "p1", values, result)]
    found, note = motions(runs)
    assert note == "" and [m.point_id for m in found] == ["p0", "p1"]
    assert [m.colour for m in found] == list(Category10_10[:2])
    q = result.traces[[f"robot.q[{i}]" for i in range(1, 8)]].to_numpy()
    assert np.array_equal(found[0].frames.points, arm_points(q))  # fewer rows than MAX_FRAMES: every one
    view = LinkView(found)
    joints = view.sources["p0"]["joints"].data
    u, v, w = ((arm_points(q[0])[0] - view.centre) / view.scale).T
    px, py = P.project(u, v, w, AZIMUTH, ELEVATION)
    assert np.allclose(joints["px"], px) and np.allclose(joints["py"], py) and joints["time"][0] == 0.0
    # the view is as wide as the farthest drawn point from its centre (5 % margin): every frame of both designs
    # stays inside it at any angle, and the arm fills it (not the unit cube's corners, 1.8, as before)
    every = (np.concatenate([m.frames.points.reshape(-1, 3) for m in found]) - view.centre) / view.scale
    reach = view.figure.x_range.end
    assert (view.figure.x_range.start, view.figure.y_range.start, view.figure.y_range.end) == (-reach, -reach, reach)
    axes = view.scaled(np.vstack([np.zeros(3), np.diag([0.23 * view.scale] * 3)]))  # origin, axis labels
    farthest = np.max(np.linalg.norm(np.vstack([every, axes]), axis=1))
    assert reach == pytest.approx(1.05 * farthest, rel=1e-12) and reach < 1.8
    for azimuth in np.linspace(-np.pi, np.pi, 9):
        for elevation in np.linspace(-np.pi / 2, np.pi / 2, 5):
            px, py = P.project(*every.T, azimuth, elevation)
            assert np.all(np.abs(px) <= reach) and np.all(np.abs(py) <= reach)

    def broken(traces):
        raise RuntimeError("no kinematics here")

    unregister_viewer("panda")
    register_viewer(TraceViewer("broken", lambda traces: [("all", ["robot.q[1]"])], link_frames=broken))
    try:
        with pytest.warns(UserWarning, match="trace viewer 'broken' failed on the link frames of p0"):
            found, note = motions(runs)
        assert found == [] and note == "no 3-D view: the trace viewer 'broken' failed: no kinematics here"
    finally:
        unregister_viewer("broken")


def test_the_rooms_trace_legend_has_one_entry_per_design_beside_the_plot(robot_run):
    """An array port (robot.q, 7 elements) of two designs: 14 lines, a legend of 2 entries (each hides its
    design's 7 lines on a click) placed right of the plot so that it covers no curve; the hover names the line."""
    from bokeh.models import HoverTool

    from cosim.analysis.rerun import Rerun, port_groups
    from cosim.analysis.room import views as V

    result, values = robot_run
    units = {"robot.q": "rad"}
    runs = [Rerun(0, "p0", values, result, units), Rerun(1, "p1", values, result, units)]
    recorded = [c for c in result.traces.columns if c != "time"]
    figures = {f.name: f for f in V.trace_figures(port_groups(recorded), runs)}
    fig = figures["trace:robot.q"]
    [legend] = fig.legend
    assert legend in fig.right and legend not in fig.center
    # issue 39: the designs, then the elements by name; the y axis carries the unit
    elements = [f"robot.q[{i}]" for i in range(1, 8)]
    assert [item.label.value for item in legend.items] == ["p0", "p1", *elements]
    for item, design in zip(legend.items, ("p0", "p1")):
        assert sorted(r.name for r in item.renderers) == sorted(f"trace:robot.q[{i}]:{design}" for i in range(1, 8))
    for item, element in zip(legend.items[2:], elements):
        assert [r.name for r in item.renderers] == [f"trace:{element}:p0", f"trace:{element}:p1"]
    assert legend.click_policy == "hide"
    assert fig.yaxis[0].axis_label == "robot.q [rad]"
    # each element its own dash and shade within its design's colour family; the designs' families differ
    lines = {r.name: r.glyph for r in fig.renderers}
    styles = {(lines[f"trace:{e}:p0"].line_color, str(lines[f"trace:{e}:p0"].line_dash)) for e in elements}
    assert len(styles) == 7
    assert lines["trace:robot.q[1]:p0"].line_color == V.Category10_10[0]
    assert lines["trace:robot.q[1]:p1"].line_color == V.Category10_10[1]
    assert lines["trace:robot.q[7]:p0"].line_color != lines["trace:robot.q[7]:p1"].line_color
    [hover] = [t for t in fig.tools if isinstance(t, HoverTool)]
    assert ("line", "$name") in hover.tooltips


def test_port_units_names_each_ports_unit_as_the_spec_calls_it():
    """The units the room's trace axes carry (issue 39): the drive_energy example's FMU and Python unit."""
    from cosim.analysis.rerun import port_units
    from cosim.spec.loader import load_spec
    from cosim.system.builder import build_system

    system = build_system(load_spec(REPO / "examples" / "drive_energy" / "spec.json"))
    units = port_units(system)
    assert units["energy.tau"] == "N.m" and units["energy.e_total"] == "J" and units["energy.omega"] == "rad/s"
    assert "energy.tau[1]" not in units  # the port, not its elements
