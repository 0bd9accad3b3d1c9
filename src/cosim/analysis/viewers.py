"""Trace viewers: how a run's traces are shown, supplied by the packages that know the units.

The engine shows any run as time plots, one panel per port.  A unit package
that knows more about its signals (a robot arm's joint angles, its geometry)
supplies a :class:`TraceViewer`: panels that group its signals and, if it
can, an animation: a matplotlib one for the desktop window (``animation``)
and, for the browser's decision room, the positions of its link frames over
the run (``link_frames``, returning :class:`LinkFrames`), which the room draws
as a turnable 3-D stick figure with a time slider.  The explorer and the room
ask every registered viewer, in order, and use the first that recognises the
traces.

Viewers come from :func:`register_viewer` and from the ``cosim.viewers`` entry
point group (a distribution declares ``[project.entry-points."cosim.viewers"]
panda = "cosim.models.panda_viewer:VIEWER"``).  A viewer that fails to load is
skipped with a warning: showing traces must never fail because of one.
"""

from __future__ import annotations

import threading
import warnings
from dataclasses import dataclass
from importlib import metadata
from typing import Any, Callable

import numpy as np

ENTRY_POINT_GROUP = "cosim.viewers"


@dataclass(frozen=True)
class LinkFrames:
    """Where a mechanism's link frames are over a run, for a 3-D stick figure.

    ``time`` (samples,) in seconds, never decreasing (event rows repeat a time); ``points`` (samples, links,
    3) the frames' origins in metres in one world frame whose third axis points up; ``segments`` the pairs of
    link indices drawn as sticks; ``path`` the index of the link whose path over the run is drawn too (a tool
    point), or None; ``labels`` one name per link (shown when hovering), or empty.

    Raises ValueError when the shapes do not fit together (checked here, so a plug-in's mistake names itself
    instead of drawing nonsense in a page).
    """

    time: np.ndarray
    points: np.ndarray
    segments: tuple[tuple[int, int], ...]
    path: int | None = None
    labels: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        time = np.asarray(self.time, dtype=float)
        points = np.asarray(self.points, dtype=float)
        object.__setattr__(self, "time", time)
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "segments", tuple((int(a), int(b)) for a, b in self.segments))
        object.__setattr__(self, "labels", tuple(str(label) for label in self.labels))
        if points.ndim != 3 or points.shape[2] != 3 or points.shape[0] != time.shape[0] or time.ndim != 1:
            raise ValueError(f"link frames: points must be (samples, links, 3) for {time.shape[0]} times, "
                             f"got {points.shape}")
        links = points.shape[1]
        if any(not (0 <= i < links) for pair in self.segments for i in pair):
            raise ValueError(f"link frames: a segment names a link outside 0..{links - 1}: {self.segments}")
        if self.path is not None and not 0 <= self.path < links:
            raise ValueError(f"link frames: path link {self.path} is outside 0..{links - 1}")
        if self.labels and len(self.labels) != links:
            raise ValueError(f"link frames: {len(self.labels)} labels for {links} links")


@dataclass(frozen=True)
class TraceViewer:
    """How to show the traces of a kind of system.

    ``panels(traces)`` returns ``[(title, columns), ...]`` when the viewer
    recognises the traces (a pandas DataFrame with a ``time`` column), else
    None.  ``animation(figure, traces)`` draws into a matplotlib figure and
    returns the animation object (keep a reference to it), or None.
    ``link_frames(traces)`` returns the :class:`LinkFrames` of the run at the
    traces' samples (the browser animates them), or None when the traces
    lack what it needs; the caller passes as many samples as it wants drawn.
    """

    name: str
    panels: Callable[[Any], list[tuple[str, list[str]]] | None]
    animation: Callable[[Any, Any], Any] | None = None
    link_frames: Callable[[Any], LinkFrames | None] | None = None


def trace_times(traces: Any) -> np.ndarray:
    """The ``time`` column of ``traces`` as floats, or the row numbers when it has none."""
    if "time" in traces.columns:
        return traces["time"].to_numpy(dtype=float)
    return np.arange(len(traces), dtype=float)


def rows_evenly_in_time(times: np.ndarray, count: int) -> np.ndarray:
    """The rows shown as ``count`` frames evenly spaced in time from the first row to the last: per frame the
    last row at or before its time (after an event at that time: event rows repeat a time, times never
    decrease), the last row always, each row once.  Viewers animate these rows, so that a burst of event rows
    at one instant does not crowd the frames."""
    if len(times) == 0:
        return np.zeros(0, dtype=int)
    at = np.linspace(times[0], times[-1], max(count, 1))
    rows = np.searchsorted(times, at, side="right") - 1
    rows[-1] = len(times) - 1
    return np.unique(np.clip(rows, 0, len(times) - 1))


_LOCK = threading.Lock()
_VIEWERS: dict[str, TraceViewer] = {}
_entry_points_loaded = False


def register_viewer(viewer: TraceViewer) -> TraceViewer:
    """Make ``viewer`` available to the explorer and to :func:`viewers` (replacing one of the same name)."""
    with _LOCK:
        _VIEWERS[viewer.name] = viewer
    return viewer


def unregister_viewer(name: str) -> None:
    """Forget the viewer ``name`` (for tests)."""
    with _LOCK:
        _VIEWERS.pop(name, None)


def viewers() -> list[TraceViewer]:
    """Every viewer: the registered ones and those of installed distributions."""
    global _entry_points_loaded
    with _LOCK:
        if not _entry_points_loaded:
            _entry_points_loaded = True
            for entry in metadata.entry_points(group=ENTRY_POINT_GROUP):
                try:
                    viewer = entry.load()
                except Exception as exc:  # a broken plug-in costs its own viewer only
                    warnings.warn(f"trace viewer '{entry.name}' ({entry.value}) cannot be loaded: {exc}",
                                  stacklevel=2)
                    continue
                if isinstance(viewer, TraceViewer):
                    _VIEWERS.setdefault(viewer.name, viewer)
        return list(_VIEWERS.values())


def viewer_for(traces: Any) -> tuple[TraceViewer | None, list[tuple[str, list[str]]] | None]:
    """The first viewer that recognises ``traces`` and its panels, or (None, None)."""
    for viewer in viewers():
        try:
            panels = viewer.panels(traces)
        except Exception as exc:  # a viewer's bug must not hide the traces
            warnings.warn(f"trace viewer '{viewer.name}' failed: {exc}", stacklevel=2)
            continue
        if panels:
            return viewer, panels
    return None, None
