"""The decision room's 3-D view of re-run designs from a trace viewer's link frames (e.g. the Panda arm).

The room knows no mechanism: a unit package's :class:`~cosim.analysis.viewers.TraceViewer` may supply
``link_frames(traces)`` (:class:`~cosim.analysis.viewers.LinkFrames`: where its link frames are at each
sample, which links are joined by sticks, which link's path to draw).  After a re-run, :func:`motions` asks
the viewer that recognises the traces for the frames of every design (at most :data:`MAX_FRAMES` samples
each, evenly spaced in time, so a long run costs the page a bounded amount), and :class:`LinkView` draws them:

- each design a stick figure in its colour (the trace plots' colours), with its joints as dots and the
  path of its tool link as a thin line, all designs overlaid;
- an orthographic projection turned by dragging in the plot or with its azimuth and elevation sliders,
  computed in the browser by the same code as the Dimensions tab's 3-D scatter (:data:`.projection.PROJECT_JS`,
  :data:`.projection.TURN_JS`); metres scaled alike on every axis (one centre and one scale for all designs);
- a time slider (``arm-time``) and a play/pause toggle (``arm-play``): the browser picks each design's last
  sample at or before the slider's time (a design whose run ended keeps its last pose) and redraws; playing
  advances the slider in real time (:data:`TICK_MS` per tick) and starts again at the end.

Models a test or script may look for (``Bokeh.documents[0].get_model_by_name``): ``arm-view`` (the figure;
its ``tags[0]`` holds the ``centre`` and ``scale`` of the projection), ``arm-time``, ``arm-play``,
``arm-azimuth``, ``arm-elevation``, and per design ``arm-joints:<point id>`` (columns ``x``, ``y``, ``z`` in
metres, ``u``, ``v``, ``w`` scaled, ``px``, ``py`` projected, ``time`` the sample shown, ``link``),
``arm-sticks:<point id>``, ``arm-path:<point id>`` and ``arm-frames:<point id>`` (every sample's frames, flat,
sample-major: ``time``, ``x``, ``y``, ``z``).
"""

from __future__ import annotations

import html
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from bokeh.events import Pan
from bokeh.layouts import column, row
from bokeh.models import ColumnDataSource, CustomJS, HoverTool, Range1d
from bokeh.models.widgets import Div, Slider, Toggle
from bokeh.palettes import Category10_10
from bokeh.plotting import figure

from cosim.analysis.room import projection as P
from cosim.analysis.room.views import Backend
from cosim.analysis.viewers import (
    LinkFrames,
    rows_evenly_in_time,
    trace_times,
    viewer_for,
)

MAX_FRAMES = 300  # samples of a design's run sent to the page at most
TICK_MS = 50  # the play toggle's step: the slider advances by this much run time per tick (real time)
AZIMUTH, ELEVATION = -0.7, 0.35  # radians: the first view, from the front left and a little above
SIZE = 560  # px of the square plot
AXIS_LENGTH, AXIS_LABEL_AT = 0.2, 1.15  # the x, y, z axes: a fifth of the view's scale; labels just past their ends


@dataclass(frozen=True)
class Motion:
    """One design's link frames and how it is drawn: its id, its colour (as in the trace plots)."""

    point_id: str
    colour: str
    frames: LinkFrames


def sampled(traces: Any, limit: int = MAX_FRAMES) -> Any:
    """``traces`` when they have at most ``limit`` rows, else at most ``limit`` rows evenly spaced in time: at each
    of ``limit`` times from the first row's to the last's, the last row at or before it (so that event rows,
    which repeat a time, do not crowd the frames; the last row is always kept)."""
    if len(traces) <= limit:
        return traces
    return traces.iloc[rows_evenly_in_time(trace_times(traces), limit)]


def motions(runs: Sequence[Any]) -> tuple[list[Motion], str]:
    """The link frames of each re-run design (``runs``: :class:`~cosim.analysis.rerun.Rerun`), through the viewer
    that recognises the first design's traces; and a note for the page (empty when all went well or when no
    viewer supplies link frames: then there is no 3-D view and nothing to say).

    A viewer that fails is reported in the note and costs the 3-D view only, never the re-run's traces."""
    with_traces = [(k, run) for k, run in enumerate(runs)
                   if run.result.traces is not None and len(run.result.traces)]
    if not with_traces:
        return [], ""
    viewer, _ = viewer_for(with_traces[0][1].result.traces)
    if viewer is None or viewer.link_frames is None:
        return [], ""
    out: list[Motion] = []
    for k, run in with_traces:
        try:
            frames = viewer.link_frames(sampled(run.result.traces))
        except Exception as exc:  # a plug-in's bug: the traces are still shown
            warnings.warn(f"trace viewer '{viewer.name}' failed on the link frames of {run.point_id}: {exc}",
                          stacklevel=2)
            return [], f"no 3-D view: the trace viewer '{viewer.name}' failed: {exc}"
        if frames is not None and len(frames.time):
            out.append(Motion(str(run.point_id), Category10_10[k % 10], frames))
    return out, ""


def strokes(segments: Sequence[tuple[int, int]]) -> list[int]:
    """The segments as polylines: link indices, -1 between two strokes; a segment that starts where the previous
    one ended continues its stroke (a chain of n links is one stroke of n indices)."""
    out: list[int] = []
    for a, b in segments:
        if out and out[-1] == a:
            out.append(b)
        else:
            if out:
                out.append(-1)
            out += [a, b]
    return out


def frame_at(times: np.ndarray, t: float) -> int:
    """The sample shown at time ``t``: the last one at or before it (the first before the run starts)."""
    return max(int(np.searchsorted(times, t + 1e-12, side="right")) - 1, 0)


# shows each design at the time slider's value: its last sample at or before it; then projects what changed.
# Arguments: time (slider), frames, joints, sticks (lists of sources, one per design), links (per design),
# strokes (per design: link indices, -1 between strokes), centre, scale, azimuth, elevation
SHOW_JS = """
const t = time.value;
const sources = [];
for (let d = 0; d < frames.length; d++) {
  const f = frames[d].data, L = links[d], n = f.time.length / L;
  let lo = 0, hi = n - 1;  // the last sample at or before t
  while (lo < hi) {
    const mid = (lo + hi + 1) >> 1;
    if (f.time[mid * L] <= t + 1e-12) lo = mid; else hi = mid - 1;
  }
  const j0 = lo * L, old = joints[d].data;
  const x = f.x.slice(j0, j0 + L), y = f.y.slice(j0, j0 + L), z = f.z.slice(j0, j0 + L);
  const u = Array.from(x, (q) => (q - centre[0]) / scale), v = Array.from(y, (q) => (q - centre[1]) / scale),
        w = Array.from(z, (q) => (q - centre[2]) / scale);
  joints[d].data = {...old, x: Array.from(x), y: Array.from(y), z: Array.from(z), u: u, v: v, w: w,
                    time: new Array(L).fill(f.time[j0])};
  const s = strokes[d], su = [], sv = [], sw = [];
  for (const i of s) {
    su.push(i < 0 ? NaN : u[i]); sv.push(i < 0 ? NaN : v[i]); sw.push(i < 0 ? NaN : w[i]);
  }
  sticks[d].data = {...sticks[d].data, u: su, v: sv, w: sw};
  sources.push(joints[d], sticks[d]);
}
""" + P.PROJECT_JS

# the play toggle: while active, advance the time slider by `dt` every `ms` (up to the end, then from the start);
# stops when toggled off or when its view left the page (a new re-run)
PLAY_JS = """
if (cb_obj.active) {
  cb_obj.label = "❚❚ pause";
  if (cb_obj._timer == null) {
    cb_obj._timer = setInterval(() => {
      if (!cb_obj.active || cb_obj.document == null) { clearInterval(cb_obj._timer); cb_obj._timer = null; return; }
      // the run's end is shown (also when it is not a whole number of steps away), then the start again
      const now = time.value;
      time.value = now >= time.end - 1e-12 ? time.start : Math.min(now + dt, time.end);
    }, ms);
  }
} else {
  cb_obj.label = "▶ play";
  if (cb_obj._timer != null) { clearInterval(cb_obj._timer); cb_obj._timer = null; }
}
"""


class LinkView:
    """The 3-D view of ``motions`` (module docstring); ``layout`` is what the page shows, ``backend`` the plot's
    output backend ("canvas", or "svg" to save the view as SVG); ``at``, ``azimuth`` and ``elevation`` the
    time and angles first shown (the run's start and :data:`AZIMUTH`, :data:`ELEVATION` by default).

    Raises ValueError without motions."""

    def __init__(self, motions: Sequence[Motion], backend: Backend = "canvas", at: float | None = None,
                 azimuth: float = AZIMUTH, elevation: float = ELEVATION):
        if not motions:
            raise ValueError("a 3-D view needs the link frames of at least one design")
        self.motions = list(motions)
        every = np.concatenate([m.frames.points.reshape(-1, 3) for m in self.motions])
        lo, hi = np.nanmin(every, axis=0), np.nanmax(every, axis=0)
        self.centre = (lo + hi) / 2
        self.scale = float(max(np.max(hi - lo) / 2, 1e-9))  # the same on every axis: metres look alike
        start = min(float(m.frames.time[0]) for m in self.motions)
        end = max(float(m.frames.time[-1]) for m in self.motions)
        steps = [np.diff(m.frames.time) for m in self.motions if len(m.frames.time) > 1]
        step = float(min(s[s > 0].min() for s in steps if (s > 0).any())) if any((s > 0).any() for s in steps) \
            else 1.0
        end = end if end > start else start + step
        at = start if at is None else min(max(float(at), start), end)
        self.angles = (float(azimuth), float(elevation))
        self.time = Slider(title="time [s]", start=start, end=end, value=at, step=step, name="arm-time",
                           width=SIZE - 100, format="0[.]000")
        self.play = Toggle(label="▶ play", active=False, name="arm-play", width=90)
        self.azimuth = Slider(title="azimuth [rad]", start=-np.pi, end=np.pi, step=0.01, value=self.angles[0],
                              name="arm-azimuth", width=270)
        self.elevation = Slider(title="elevation [rad]", start=-np.pi / 2, end=np.pi / 2, step=0.01,
                                value=self.angles[1], name="arm-elevation", width=270)
        reach = self.reach()
        self.figure = figure(name="arm-view", width=SIZE, height=SIZE, x_range=Range1d(start=-reach, end=reach),
                             y_range=Range1d(start=-reach, end=reach),
                             tools="save", match_aspect=True, output_backend=backend,
                             title="re-run designs in 3-D (drag to turn)",
                             tags=[{"centre": [float(c) for c in self.centre], "scale": self.scale}])
        self.figure.axis.visible = False
        self.figure.grid.visible = False
        self.figure.toolbar.logo = None
        self.sources: dict[str, dict[str, ColumnDataSource]] = {}
        self._draw_axes()
        for m in self.motions:
            self._draw(m, at)
        self._wire()
        self.layout = column(self.figure, row(self.play, self.time), row(self.azimuth, self.elevation),
                             name="arm-box")

    # -- the models ----------------------------------------------------------------------------------------------
    def scaled(self, points: np.ndarray) -> np.ndarray:
        """Points (..., 3) in metres as the view's u, v, w."""
        return (np.asarray(points, dtype=float) - self.centre) / self.scale

    def reach(self) -> float:
        """Half the width of the view: every drawn point (links, paths, axes and their labels) at every time stays
        inside it at every angle, with a margin of 5 %.  The projection is a rotation dropping one axis, so a
        point's distance from the view's centre is at most its u, v, w's length."""
        label = AXIS_LENGTH * AXIS_LABEL_AT * self.scale
        drawn = np.concatenate([np.concatenate([m.frames.points.reshape(-1, 3) for m in self.motions]),
                                np.zeros((1, 3)), np.diag([label] * 3)])
        return 1.05 * float(max(np.nanmax(np.linalg.norm(self.scaled(drawn), axis=1)), 1e-9))

    def _projected(self, u: np.ndarray, v: np.ndarray, w: np.ndarray) -> dict[str, np.ndarray]:
        px, py = P.project(u, v, w, *self.angles)
        return {"u": u, "v": v, "w": w, "px": px, "py": py}

    def state(self) -> dict[str, float]:
        """The time and angles the page shows now (its sliders, as the browser last reported them)."""
        return {"at": float(self.time.value), "azimuth": float(self.azimuth.value),
                "elevation": float(self.elevation.value)}

    def _draw_axes(self) -> None:
        """x, y, z from the world origin, a fifth of the view long, each with its label."""
        length = AXIS_LENGTH * self.scale
        ends = np.array([[0, 0, 0], [length, 0, 0], [np.nan] * 3, [0, 0, 0], [0, length, 0], [np.nan] * 3,
                         [0, 0, 0], [0, 0, length]], dtype=float)
        uvw = self.scaled(ends)
        axes = ColumnDataSource(self._projected(*uvw.T), name="arm-axes")
        labels_uvw = self.scaled(np.diag([length * AXIS_LABEL_AT] * 3))
        labels = ColumnDataSource({**self._projected(*labels_uvw.T), "label": ["x", "y", "z"]},
                                  name="arm-axis-labels")
        self.figure.line("px", "py", source=axes, color="#888888", line_width=1)
        self.figure.text("px", "py", text="label", source=labels, text_font_size="9pt", text_color="#666666",
                         text_align="center", text_baseline="middle")
        self.fixed = [axes, labels]

    def _draw(self, m: Motion, at: float) -> None:
        f = m.frames
        links = f.points.shape[1]
        k = frame_at(f.time, at)
        flat = f.points.reshape(-1, 3)
        frames = ColumnDataSource({"time": np.repeat(f.time, links), "x": flat[:, 0], "y": flat[:, 1],
                                   "z": flat[:, 2]}, name=f"arm-frames:{m.point_id}")
        now = f.points[k]
        uvw = self.scaled(now)
        joints = ColumnDataSource({**self._projected(*uvw.T), "x": now[:, 0], "y": now[:, 1], "z": now[:, 2],
                                   "time": np.full(links, f.time[k]),
                                   "link": list(f.labels) or [str(j) for j in range(links)]},
                                  name=f"arm-joints:{m.point_id}")
        order = strokes(f.segments)
        stick_uvw = np.array([uvw[i] if i >= 0 else [np.nan] * 3 for i in order]).reshape(-1, 3)
        sticks = ColumnDataSource(self._projected(*stick_uvw.T), name=f"arm-sticks:{m.point_id}")
        self.sources[m.point_id] = {"frames": frames, "joints": joints, "sticks": sticks}
        if f.path is not None:
            path = ColumnDataSource(self._projected(*self.scaled(f.points[:, f.path]).T), name=f"arm-path:{m.point_id}")
            self.figure.line("px", "py", source=path, color=m.colour, line_width=1, alpha=0.6,
                             name=f"arm-path-line:{m.point_id}")
            self.fixed.append(path)
        self.figure.line("px", "py", source=sticks, color=m.colour, line_width=4, alpha=0.9,
                         legend_label=m.point_id, name=f"arm-sticks-line:{m.point_id}")
        dots = self.figure.scatter("px", "py", source=joints, size=7, color=m.colour,
                                   name=f"arm-joints-dots:{m.point_id}")
        self.figure.add_tools(HoverTool(renderers=[dots], tooltips=[("design", m.point_id), ("link", "@link"),
                                                                    ("x, y, z [m]", "@x{0.000}, @y{0.000}, @z{0.000}"),
                                                                    ("t [s]", "@time{0.000}")]))
        self.figure.legend.location = "top_left"
        self.figure.legend.label_text_font_size = "8pt"

    def _wire(self) -> None:
        frames = [s["frames"] for s in self.sources.values()]
        joints = [s["joints"] for s in self.sources.values()]
        sticks = [s["sticks"] for s in self.sources.values()]
        angles = {"azimuth": self.azimuth, "elevation": self.elevation}
        self.time.js_on_change("value", CustomJS(args={
            "time": self.time, "frames": frames, "joints": joints, "sticks": sticks,
            "links": [int(m.frames.points.shape[1]) for m in self.motions],
            "strokes": [strokes(m.frames.segments) for m in self.motions],
            "centre": [float(c) for c in self.centre], "scale": self.scale, **angles}, code=SHOW_JS))
        turn = CustomJS(args={"sources": [*self.fixed, *joints, *sticks], **angles}, code=P.PROJECT_JS)
        self.azimuth.js_on_change("value", turn)
        self.elevation.js_on_change("value", turn)
        self.figure.js_on_event(Pan, CustomJS(args=angles, code=P.TURN_JS))
        self.play.js_on_change("active", CustomJS(args={"time": self.time, "dt": TICK_MS / 1000, "ms": TICK_MS},
                                                  code=PLAY_JS))


def note(text: str) -> Div:
    """A line of the Selection tab saying why there is no 3-D view (``text`` is plain: a viewer's message may
    quote a spec or an FMU, so it is escaped)."""
    return Div(text=f"<i>{html.escape(text)}</i>", name="arm-note", width=760)
