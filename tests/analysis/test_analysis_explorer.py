"""The explorer: its state without a window, and the real Tk window on a virtual X screen (Xvfb).

The window test starts its own Xvfb on a free display with ``-fbdir``, so the
screen is also an XWD image file; the screenshot is that file converted to
PNG (``explorer-screenshot.png`` in the test's temporary folder, and in
``$COSIM_SCREENSHOTS`` when set).  Needs Debian's ``xvfb`` package.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cosim.analysis.explorer import SLIDER_STEPS, ExplorerState
from cosim.analysis.table import AnalysisError, load_results
from tests.analysis.test_analysis_table import make_sweep_table
from tests.helpers.tools import python_unit
from tests.helpers.xwd import xwd_to_rgb

# -- state, no window --------------------------------------------------------------------------------------


def test_state_defaults_ranges_greyed_and_selection(tmp_path):
    table = load_results(make_sweep_table(tmp_path / "s"))
    state = ExplorerState(table)
    assert (state.x, state.y, state.color, state.z) == ("traj.q_via[2]", "traj.q_via[4]", "energy", None)
    n = len(table.df)
    assert state.greyed().size == 0 and state.coloured().size == n
    q2 = table.values("traj.q_via[2]")
    state.set_range_steps("traj.q_via[2]", SLIDER_STEPS // 2, SLIDER_STEPS)
    assert state.ranges["traj.q_via[2]"].lo == pytest.approx(-40.0)
    assert np.array_equal(state.greyed(), np.flatnonzero(q2 < -40))
    # narrowing an objective greys the rows without a value too (failed rows)
    state.set_range("energy", 0, 60)
    e = table.values("energy")
    assert np.array_equal(state.coloured(), np.flatnonzero((q2 >= -40) & (e <= 60)))
    # slider ends are exactly the bounds: the extreme rows stay coloured
    state.reset_ranges()
    state.set_range_steps("traj.q_via[4]", 0, SLIDER_STEPS)
    assert state.narrowed() == [] and state.greyed().size == 0
    # picking: nearest within the radius, else nothing changes
    screen = np.array([[10.0, 10.0], [50.0, 50.0], [100.0, 10.0]])
    rows = np.array([4, 9, 17])
    assert state.pick(screen, rows, (47.0, 55.0)) == 9 and state.selected == 9
    assert state.pick(screen, rows, (300.0, 300.0)) is None and state.selected == 9
    assert state.selected_values()["point_id"] == table.df["point_id"][9]
    # axes with missing values: those rows are not drawn
    state.set_axis("x", "energy")
    assert state.drawable().sum() == n - 3
    with pytest.raises(AnalysisError, match="Did you mean 'energy'"):
        state.set_axis("color", "enrgy")
    state.set_axis("color", "")
    assert state.color is None


def test_state_works_for_a_foreign_table(tmp_path):
    path = tmp_path / "foreign.csv"
    pd.DataFrame({"a": [1, 2, 3], "b": [3.0, np.nan, 1.0], "name": ["x", "y", "z"]}).to_csv(path, index=False)
    state = ExplorerState(load_results(path))
    assert state.columns == ["a", "b"] and (state.x, state.y, state.color) == ("a", "b", None)
    assert state.drawable().tolist() == [True, False, True]


# -- the real window under Xvfb ---------------------------------------------------------------------------





def pump(root, until=lambda: True, timeout=10.0):
    """Run Tk's event loop until ``until()`` holds or ``timeout`` seconds passed; returns ``until()``.

    A check on Tk's own timer, every 10 ms, ends the loop. ``root.update()`` in a loop, as before, returns only
    once no event is due: an animation whose frames take longer to draw than its 50 ms interval (a loaded
    machine) kept it from returning until the animation's loop ended (19 minutes, two test runs side by side at
    load 16-28).
    """
    deadline = time.monotonic() + timeout
    raised = []

    def check():
        try:
            done = until() or time.monotonic() > deadline
        except BaseException as exc:  # noqa: BLE001 - raised below, after the loop; Tk would only print it
            raised.append(exc)
            done = True
        if done:
            root.quit()
        else:
            root.after(10, check)

    root.after(10, check)
    root.mainloop()
    if raised:
        raise raised[0]
    return until()


def linear_ode_sweep(folder: Path, write_spec) -> Path:
    """A tiny real sweep table: dy/dt = a*y, y(0) = 1, over a in {-2, -1, -0.5}; metadata names the spec."""
    spec = {"name": "decay", "units": {"ode": {"python": python_unit("LinearOde"), "parameters": {"x0": 1.0}}},
            "experiment": {"start": 0.0, "stop": 1.0, "step": 0.01}, "record": ["ode.y"],
            "objectives": {"y_end": {"signal": "ode.y", "reduce": "final", "unit": "1", "sense": "minimize"}},
            "design": {"parameters": {"ode.a": {"values": [-2.0, -1.0, -0.5]}}}}
    spec_path = write_spec(spec)
    folder.mkdir(parents=True, exist_ok=True)
    a = np.array([-2.0, -1.0, -0.5])
    pd.DataFrame({"point_id": ["pa", "pb", "pc"], "ode.a": a, "y_end": np.exp(a), "status": "ok", "message": "",
                  "run_time": 0.01, "worker": "w"}).to_parquet(folder / "results.parquet", index=False)
    (folder / "metadata.json").write_text(json.dumps({"spec_path": str(spec_path), "spec": spec}))
    return folder / "results.parquet"


def test_explorer_window_slider_click_rerun_and_screenshot(xvfb, tmp_path, write_spec):
    import tkinter as tk

    from cosim.analysis.explorer import ExplorerWindow

    display, framebuffer = xvfb
    table = load_results(make_sweep_table(tmp_path / "s"))
    root = tk.Tk()
    try:
        root.geometry("1100x900+0+0")
        window = ExplorerWindow(root, ExplorerState(table))
        pump(root, timeout=1.0)
        assert root.winfo_viewable()
        q2, q4 = table.values("traj.q_via[2]"), table.values("traj.q_via[4]")

        # move the lower slider of q_via[2] to its middle: points left of -40 deg turn grey
        lo, hi, shown, _ = window.sliders["traj.q_via[2]"]
        lo.set(SLIDER_STEPS // 2)
        assert pump(root, lambda: window.state.greyed().size > 0 and window._pending is None)
        expected_grey = np.flatnonzero(q2 < -40)
        assert np.array_equal(window.state.greyed(), expected_grey)
        assert shown.cget("text").startswith("-40")
        greyed = [c for c in window.ax.collections if c.get_gid() == "greyed"][0]
        coloured = [c for c in window.ax.collections if c.get_gid() == "points"][0]
        assert len(greyed.get_offsets()) == expected_grey.size
        assert len(coloured.get_offsets()) == len(table.df) - expected_grey.size

        # "Reset ranges" brings every point back, then the slider is moved again
        window.reset_button.invoke()
        assert pump(root, lambda: window._pending is None) and window.state.greyed().size == 0
        assert int(lo.get()) == 0 and window.state.narrowed() == []
        lo.set(SLIDER_STEPS // 2)
        assert pump(root, lambda: np.array_equal(window.state.greyed(), expected_grey) and window._pending is None)

        # click a coloured point through Tk's own event queue
        row = int(np.flatnonzero((q2 == 20) & (q4 == 70))[0])
        x, y = window.screen_position(row)
        widget = window.canvas.get_tk_widget()
        # the Tk backend maps widget pixels to display pixels 1:1, y flipped
        tk_x, tk_y = int(round(x)), int(round(widget.winfo_height() - y))
        widget.event_generate("<Motion>", x=tk_x, y=tk_y, warp=True)
        widget.event_generate("<ButtonPress-1>", x=tk_x, y=tk_y)
        widget.event_generate("<ButtonRelease-1>", x=tk_x, y=tk_y)
        assert pump(root, lambda: window.state.selected is not None)
        assert window.state.selected == row
        ring = [c for c in window.ax.collections if c.get_gid() == "selected"]
        assert ring and tuple(ring[0].get_offsets()[0]) == (20.0, 70.0)
        value_label = window.sliders["energy"][3]
        assert value_label.cget("fg") == "red"
        assert float(value_label.cget("text")) == pytest.approx(table.values("energy")[row], rel=1e-5)

        # in 3-D (z chosen in its combobox) a click picks the point projected nearest to it
        window.choosers["z"].set("energy")
        window.choosers["z"].event_generate("<<ComboboxSelected>>")
        assert pump(root, lambda: window.ax.name == "3d")
        other = int(np.flatnonzero((q2 == 0) & (q4 == 30))[0])
        x, y = window.screen_position(other)
        tk_x, tk_y = int(round(x)), int(round(widget.winfo_height() - y))
        widget.event_generate("<ButtonPress-1>", x=tk_x, y=tk_y)
        widget.event_generate("<ButtonRelease-1>", x=tk_x, y=tk_y)
        assert pump(root, lambda: window.state.selected == other), window.state.selected
        window.choosers["z"].set("")
        window.choosers["z"].event_generate("<<ComboboxSelected>>")
        assert pump(root, lambda: window.ax.name != "3d")

        # the figure can be saved; the whole screen is captured from Xvfb's frame buffer
        window.save_figure(str(tmp_path / "explorer-figure.png"))
        assert (tmp_path / "explorer-figure.png").read_bytes()[:4] == b"\x89PNG"
        pump(root, timeout=0.3)
        image = xwd_to_rgb(framebuffer)
        import matplotlib.image

        shot = tmp_path / "explorer-screenshot.png"
        matplotlib.image.imsave(shot, image)
        if os.environ.get("COSIM_SCREENSHOTS"):
            Path(os.environ["COSIM_SCREENSHOTS"]).mkdir(parents=True, exist_ok=True)
            shutil.copy(shot, Path(os.environ["COSIM_SCREENSHOTS"]) / shot.name)
        window_px = image[:900, :1100].reshape(-1, 3)
        assert len(np.unique(window_px, axis=0)) > 200  # a drawn colour map, not an empty screen
        # the greyed points' colour (0.78 grey blended on white) is on screen
        assert np.any(np.all(np.abs(window_px.astype(int) - 227) <= 3, axis=1))
    finally:
        root.destroy()


def test_explorer_reruns_the_selected_design_and_shows_its_traces(xvfb, tmp_path, write_spec):
    import tkinter as tk

    from cosim.analysis.explorer import ExplorerWindow

    table = load_results(linear_ode_sweep(tmp_path / "decay", write_spec))
    root = tk.Tk()
    try:
        window = ExplorerWindow(root, ExplorerState(table))
        pump(root, timeout=0.5)
        window.state.select(1)  # a = -1
        window.rerun_button.invoke()
        assert pump(root, lambda: bool(window.trace_windows), timeout=120), window.status.cget("text")
        win = window.trace_windows[0]
        assert "pb" in win.title() and "ok" in win.title()
        lines = [line for ax in win.figure.axes for line in ax.get_lines()]
        y = next(line for line in lines if line.get_label() == "y")
        t, v = y.get_xdata(), y.get_ydata()
        assert t[-1] == pytest.approx(1.0) and v[-1] == pytest.approx(np.exp(-1.0), rel=1e-6)
        assert win.animation is None  # no joint angles, no arm
    finally:
        root.destroy()


def test_explorer_animates_the_arm_of_a_rerun_robot_design(xvfb, tmp_path, panda_viewer):
    import tkinter as tk

    from cosim.analysis.explorer import ExplorerWindow
    from tests.analysis.test_analysis_traces import PICK_AND_PLACE, robot_table

    if not PICK_AND_PLACE.exists():
        pytest.skip("examples/pick_and_place/spec.json is not there")
    root = tk.Tk()
    try:
        window = ExplorerWindow(root, ExplorerState(load_results(robot_table(tmp_path / "pp"))))
        window.state.select(0)
        window.rerun_button.invoke()
        assert pump(root, lambda: bool(window.trace_windows), timeout=120), window.status.cget("text")
        win = window.trace_windows[0]
        assert [a.get_ylabel() for a in win.figure.axes] == ["joint angles [rad]", "joint torques [N m]",
                                                             "electric power [W]"]
        assert win.animation is not None
        arm = next(line for line in win.arm_figure.axes[0].get_lines() if line.get_gid() == "arm")
        first = np.array(arm.get_data_3d())
        # The animation runs on Tk's timer.  Look at the arm at every draw, not only when root.update()
        # returns: on a busy machine a draw takes longer than the 50 ms frame interval, so update() keeps
        # finding a due timer and returns only at the end of a loop, back at the first frame.
        poses = []
        win.arm_figure.canvas.mpl_connect("draw_event", lambda event: poses.append(np.array(arm.get_data_3d())))
        assert pump(root, lambda: any(not np.allclose(p, first) for p in poses), timeout=90)
    finally:
        root.destroy()


def test_explore_without_a_display_is_a_usage_error(tmp_path):
    path = make_sweep_table(tmp_path / "s")
    env = {k: v for k, v in os.environ.items() if k != "DISPLAY"}
    done = subprocess.run([sys.executable, "-m", "cosim.cli.main", "explore", str(path), "--tk"], env=env,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "cannot open a window" in done.stderr and "Traceback" not in done.stderr


def test_the_trace_window_of_a_rerun_with_event_rows_draws_each_bounce_as_a_step(xvfb, tmp_path):
    # record_events: the bouncing ball's re-run has two rows at each bounce's time (tests/analysis/test_event_trace_viewers)
    import tkinter as tk

    from cosim.analysis.explorer import ExplorerWindow
    from tests.analysis.test_event_trace_viewers import HEIGHTS, assert_steps, ball_study

    table = load_results(ball_study(tmp_path / "ball"))
    root = tk.Tk()
    try:
        window = ExplorerWindow(root, ExplorerState(table))
        pump(root, timeout=0.5)
        window.state.select(1)
        window.rerun_button.invoke()
        assert pump(root, lambda: bool(window.trace_windows), timeout=120), window.status.cget("text")
        win = window.trace_windows[0]
        assert "h2" in win.title() and "ok" in win.title()  # dropped from 2 m
        [v] = [line for ax in win.figure.axes for line in ax.get_lines() if line.get_label() == "v"]
        assert_steps(np.asarray(v.get_xdata()), np.asarray(v.get_ydata()), HEIGHTS[1])
    finally:
        root.destroy()
