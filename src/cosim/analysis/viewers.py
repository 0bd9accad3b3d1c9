"""Trace viewers: how a run's traces are shown, supplied by the packages that know the units.

The engine shows any run as time plots, one panel per port.  A unit package
that knows more about its signals (a robot arm's joint angles, its geometry)
supplies a :class:`TraceViewer`: panels that group its signals and, if it
can, an animation.  The explorer asks every registered viewer, in order, and
uses the first that recognises the traces.

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

ENTRY_POINT_GROUP = "cosim.viewers"


@dataclass(frozen=True)
class TraceViewer:
    """How to show the traces of a kind of system.

    ``panels(traces)`` returns ``[(title, columns), ...]`` when the viewer
    recognises the traces (a pandas DataFrame with a ``time`` column), else
    None.  ``animation(figure, traces)`` draws into a matplotlib figure and
    returns the animation object (keep a reference to it), or None.
    """

    name: str
    panels: Callable[[Any], list[tuple[str, list[str]]] | None]
    animation: Callable[[Any, Any], Any] | None = None


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
