"""The decision room's 3-D view of re-run designs from a trace viewer's link frames, and figures as SVG, in a
real browser (Debian's chromium through selenium, as tests/analysis/room/test_room_browser.py).

The arm: a real sweep of the pick-and-place spec (examples/pick_and_place/spec.json: the Panda arm's
trajectory, pinocchio's inverse dynamics and the energy FMU) over two designs; both re-run in the page; the
3-D view's drawn joints are checked against pinocchio's forward kinematics of the joint angles the page's
trace plots hold, at the sample the view shows for its time slider, before and after the slider moves and
while play runs; the drawn screen positions against the projection computed here.  Without the arm (a decay
ODE) the same re-run draws traces and no 3-D view.  Chromium's console must have no SEVERE entry.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest

from cosim.analysis.room import browser as B
from cosim.analysis.table import load_results
from tests.helpers.paths import REPO
from tests.helpers.tools import python_unit

PICK_AND_PLACE = REPO / "examples" / "pick_and_place" / "spec.json"
pytestmark = pytest.mark.usefixtures("panda_viewer")  # the room shows the arm only through the plug-in

DESIGNS = [(-50.0, 70.0), (0.0, 0.0)]  # q2[2], q2[4] in degrees: two different paths over the shoulder


def sweep(folder: Path, spec: dict) -> Path:
    import cosim

    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "spec.json"
    path.write_text(json.dumps(spec, indent=2))
    cosim.sweep(path, workers=1, out=folder / "out", quiet=True)
    return folder / "out"


@pytest.fixture(scope="module")
def arm_study(tmp_path_factory):
    """A real sweep of the pick-and-place spec over the grid of DESIGNS' values (its units resolved as in the
    example: built-in models and the energy FMU)."""
    spec = json.loads(PICK_AND_PLACE.read_text())
    a, b = list(spec["design"]["parameters"])
    spec["design"] = {"parameters": {a: {"values": sorted({x for x, _ in DESIGNS})},
                                     b: {"values": sorted({y for _, y in DESIGNS})}}}  # 4 designs, 2 shown
    return sweep(tmp_path_factory.mktemp("arm"), spec)


def console_severe(driver) -> list[str]:
    return [entry["message"] for entry in driver.get_log("browser") if entry["level"] == "SEVERE"]


def select_and_rerun(driver, rows: list[int]) -> None:
    """Select ``rows`` in the cloud (as its box tool does), re-run them from the Selection tab and wait for the
    traces (failing with the page's status when the re-run failed)."""
    driver.execute_script(f"Bokeh.documents[0].get_model_by_name('cloud-source').selected.indices = {rows};")
    B.show_tab(driver, 2)
    B.wait_for(driver, "return doc.is_idle && doc.get_model_by_name('selected').text.includes('"
                       f"{len(rows)} design(s) selected');")
    B.click_widget(driver, "rerun")
    status = B.wait_for(driver, "const s = doc.get_model_by_name('rerun-status').text, "
                                "c = doc.get_model_by_name('traces'); "
                                "return s.includes('failed') || (c.children.length && doc.is_idle && "
                                "!doc.get_model_by_name('rerun').disabled) ? s : null;")
    assert "failed" not in status, status


def page_q(driver, point_id: str) -> tuple[np.ndarray, np.ndarray]:
    """(time, q (samples, 7)) of design ``point_id`` as the page's joint-angle plot draws them."""
    got = driver.execute_script(
        B.LIVE_JS + "const f = live('trace:robot.q'); const out = {};"
        "for (const r of f.renderers) out[r.name] = [Array.from(r.data_source.data.x), "
        "Array.from(r.data_source.data.y)]; return out;")
    t = np.array(got[f"trace:robot.q[1]:{point_id}"][0], dtype=float)
    q = np.column_stack([np.array(got[f"trace:robot.q[{j}]:{point_id}"][1], dtype=float) for j in range(1, 8)])
    return t, q


def forward_kinematics(q: np.ndarray) -> np.ndarray:
    """Base, joints 1..7 and the tool point (9, 3) by pinocchio, from the model the robot unit simulates."""
    import pinocchio as pin

    from cosim.models.panda_model import cached_model, ee_frame_id

    model = cached_model()
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    tool = pin.updateFramePlacement(model, data, ee_frame_id(model)).translation
    return np.vstack([np.zeros(3), [data.oMi[j].translation for j in range(1, 8)], tool])


def shown(driver, ids: list[str]) -> dict:
    """The view's time, angles, projection constants and each design's drawn joints."""
    return driver.execute_script(B.LIVE_JS + """
        const ids = arguments[0], out = {designs: {}};
        out.time = live('arm-time').value;
        out.azimuth = live('arm-azimuth').value;
        out.elevation = live('arm-elevation').value;
        out.tags = live('arm-view').tags[0];
        for (const id of ids) {
          const d = live('arm-joints:' + id).data;
          out.designs[id] = Object.fromEntries(['x', 'y', 'z', 'px', 'py', 'time'].map((k) => [k, Array.from(d[k])]));
          const s = live('arm-sticks:' + id).data;
          out.designs[id].sticks = [Array.from(s.px), Array.from(s.py)];
        }
        return out;""", ids)


def check_pose(driver, ids: list[str], traces: dict) -> dict:
    """Each design's drawn joints are pinocchio's forward kinematics of the page's q at the sample shown for the
    slider's time (the last one at or before it); their screen positions the projection of the view's angles."""
    got = shown(driver, ids)
    centre, scale = np.array(got["tags"]["centre"]), got["tags"]["scale"]
    ca, sa = np.cos(got["azimuth"]), np.sin(got["azimuth"])
    ce, se = np.cos(got["elevation"]), np.sin(got["elevation"])
    for point_id in ids:
        t, q = traces[point_id]
        d = got["designs"][point_id]
        k = max(int(np.searchsorted(t, got["time"] + 1e-12, side="right")) - 1, 0)
        assert d["time"] == [t[k]] * 9
        xyz = np.column_stack([d["x"], d["y"], d["z"]])
        assert np.abs(xyz - forward_kinematics(q[k])).max() < 1e-9
        u, v, w = ((xyz - centre) / scale).T
        assert np.allclose(d["px"], u * ca - v * sa, atol=1e-12)
        assert np.allclose(d["py"], w * ce + (u * sa + v * ca) * se, atol=1e-12)
        assert np.allclose(d["sticks"][0], d["px"]) and np.allclose(d["sticks"][1], d["py"])  # one chain
    return got


def test_the_arm_of_rerun_designs_in_3d_with_time_slider_play_and_svg(browser, room, arm_study, tmp_path):  # noqa: F811
    table = load_results(arm_study)
    df = table.df
    assert len(df) == 4 and (df["status"] == "ok").all()
    targets = [c for c in df.columns if c.startswith("traj.waypoints")]
    rows = [int(np.flatnonzero((df[targets[0]] == a) & (df[targets[1]] == b))[0]) for a, b in DESIGNS]
    ids = [str(df["point_id"].iloc[r]) for r in rows]
    link, _ = room(arm_study)
    B.load(browser, link)
    browser.get_log("browser")  # what loading the page said is checked at the end with the rest
    select_and_rerun(browser, rows)
    assert B.wait_for(browser, "return doc.get_model_by_name('arm-view') !== null && doc.is_idle;")
    traces = {i: page_q(browser, i) for i in ids}
    assert all(len(t) > 100 for t, _ in traces.values())
    # issue 39.3 as the page draws it: the y axis names the port and its unit, the legend the designs and then
    # each joint as recorded, and each joint has a shade and dash of its own within its design's colour
    axis, legend, styles = browser.execute_script(B.LIVE_JS + """
const f = live('trace:robot.q');
const legend = f.right.find((r) => r.items !== undefined);
const value = (p) => (p !== null && typeof p === 'object' && 'value' in p) ? p.value : p;  // a bokeh value spec
const label = (i) => value(i.label);
return [f.left[0].axis_label, legend.items.map(label),
        f.renderers.map((r) => [r.name, value(r.glyph.line_color), JSON.stringify(value(r.glyph.line_dash))])];""")
    assert axis == "robot.q [rad]"
    assert legend == [*ids, *[f"robot.q[{j}]" for j in range(1, 8)]]
    by_line = {name: (colour, dash) for name, colour, dash in styles}
    for i in ids:
        assert len({by_line[f"trace:robot.q[{j}]:{i}"] for j in range(1, 8)}) == 7
    assert {by_line[f"trace:robot.q[1]:{i}"][0] for i in ids} == {"#1f77b4", "#ff7f0e"}  # Category10's first two
    assert not np.allclose(traces[ids[0]][1][len(traces[ids[0]][0]) // 2], traces[ids[1]][1][len(traces[ids[1]][0]) // 2])

    # the first pose: both designs at the start (q1 = 0: the arm upright), then the slider to another time
    first = check_pose(browser, ids, traces)
    assert first["time"] == pytest.approx(0.0)
    B.set_and_wait(browser, "arm-time", "value", 0.8,
                   f"return doc.get_model_by_name('arm-joints:{ids[0]}').data.time[0];")
    moved = check_pose(browser, ids, traces)
    assert moved["time"] == 0.8
    assert not np.allclose(moved["designs"][ids[0]]["x"], first["designs"][ids[0]]["x"])
    # the two designs' arms differ at 0.8 s (different via points), each equal to its own kinematics above
    assert not np.allclose(moved["designs"][ids[0]]["z"], moved["designs"][ids[1]]["z"])
    B.show_tab(browser, 2)

    # play: a real click starts it, the slider advances by 0.05 s a tick (from the end it starts again), a second
    # click stops it where it is
    B.click_widget(browser, "arm-play")
    later = B.wait_for(browser, "const t = doc.get_model_by_name('arm-time').value; return t >= 0.9 ? t : null;")
    ticks = (later - 0.8) / 0.05
    assert ticks >= 2 and abs(ticks - round(ticks)) < 1e-9  # whole ticks of 0.05 s from 0.8
    B.click_widget(browser, "arm-play")
    assert B.wait_for(browser, "return !doc.get_model_by_name('arm-play').active && doc.is_idle;")
    time.sleep(0.3)  # a tick due at the click has run
    paused = check_pose(browser, ids, traces)
    assert paused["time"] != moved["time"]
    time.sleep(0.3)
    assert shown(browser, ids)["time"] == paused["time"]  # no tick after the pause

    # play through the end: the slider reaches the run's end, shows it, and goes on from the start
    end = browser.execute_script("return Bokeh.documents[0].get_model_by_name('arm-time').end;")
    B.set_and_wait(browser, "arm-time", "value", end - 0.12,
                   f"return doc.get_model_by_name('arm-joints:{ids[0]}').data.time[0];")
    browser.execute_script("const s = Bokeh.documents[0].get_model_by_name('arm-time'); window.seen = [];"
                           "window.watch = setInterval(() => window.seen.push(s.value), 5);")
    B.click_widget(browser, "arm-play")
    B.wait_for(browser, "const t = doc.get_model_by_name('arm-time').value; return t < 0.2 ? true : null;")
    B.click_widget(browser, "arm-play")
    assert B.wait_for(browser, "return !doc.get_model_by_name('arm-play').active && doc.is_idle;")
    seen = browser.execute_script("clearInterval(window.watch); return window.seen;")
    values = list(dict.fromkeys(seen))  # each value the slider held, in order
    wrap = next(k for k in range(1, len(values)) if values[k] < values[k - 1])
    assert values[wrap - 1] == end and values[wrap] == 0.0, values  # the last frame, then the first
    assert all(b > a for a, b in zip(values[:wrap - 1], values[1:wrap]))  # forward until then
    B.set_and_wait(browser, "arm-time", "value", end,
                   f"return doc.get_model_by_name('arm-joints:{ids[0]}').data.time[0];")
    at_end = check_pose(browser, ids, traces)  # each design's last sample, its kinematics drawn
    assert [at_end["designs"][i]["time"][0] for i in ids] == [traces[i][0][-1] for i in ids]

    # a real drag in the view turns it; the drawn joints follow the projection
    B.drag(browser, (-1.0, 0.0), (0.5, 0.0), "arm-view")
    turned = check_pose(browser, ids, traces)
    assert turned["azimuth"] != paused["azimuth"]

    # figures as PNG by default, as SVG after the switch: each plot's save button writes its file
    downloads = tmp_path / "downloads"
    downloads.mkdir()
    browser.execute_cdp_cmd("Browser.setDownloadBehavior", {"behavior": "allow", "downloadPath": str(downloads)})
    png = B.save_figure(browser, "arm-view", downloads)
    assert png.name == "cosim-arm-view.png" and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    B.click_widget(browser, "svg-figures")
    assert B.wait_for(browser, B.LIVE_JS + "return doc.is_idle && live('viewer').children.length && "
                               "live('arm-view').output_backend === 'svg' && "
                               "live('trace:robot.q').output_backend === 'svg';")
    again = check_pose(browser, ids, traces)  # drawn anew at the same time and angles
    assert (again["time"], again["azimuth"]) == (turned["time"], turned["azimuth"])
    for name in ("arm-view", "trace:robot.q"):
        svg = B.save_figure(browser, name, downloads)
        text = svg.read_text()
        assert svg.name == "cosim-" + name.replace(":", "_").replace(".", "_") + ".svg"
        assert text.startswith("<svg") and "</svg>" in text
        assert text.count("<path") > 7  # the lines are drawn as paths (seven joint angles, or the sticks)
    assert console_severe(browser) == []


def test_a_study_without_the_arm_has_no_3d_view(browser, room, tmp_path):  # noqa: F811
    out = sweep(tmp_path / "decay", {
        "name": "decay", "units": {"ode": {"python": python_unit("LinearOde")}},
        "experiment": {"start": 0.0, "stop": 1.0, "step": 0.01}, "record": ["ode.y"],
        "objectives": {"y_end": {"signal": "ode.y", "reduce": "final", "sense": "minimize"}},
        "design": {"parameters": {"ode.a": {"values": [-2.0, -1.0]}}}})
    link, _ = room(out)
    B.load(browser, link)
    browser.get_log("browser")
    select_and_rerun(browser, [0, 1])
    names = browser.execute_script(
        "const out = []; for (const m of Bokeh.documents[0]._all_models.values()) "
        "{ if (m.name && m.name.startsWith('arm')) out.push(m.name); } return out;")
    assert names == []
    assert browser.execute_script("return Bokeh.documents[0].get_model_by_name('viewer').children.length;") == 0
    assert browser.execute_script("return Bokeh.documents[0].get_model_by_name('traces').children.map("
                                  "(f) => f.name);") == ["trace:ode.y"]
    assert console_severe(browser) == []
