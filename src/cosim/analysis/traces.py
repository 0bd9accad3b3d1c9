"""Figures of one run's traces.

:func:`trace_groups` picks what to show: the panels of the first trace viewer
that recognises the traces (:mod:`cosim.analysis.viewers`; e.g. the Panda arm's
joint angles, torques and power, supplied by :mod:`cosim.models.panda_viewer`),
else every recorded signal grouped by port.  :func:`animation` is that
viewer's animation, if it has one.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from cosim.analysis.viewers import viewer_for

_ELEMENT = re.compile(r"^(.*)\[(\d+)\]$")


def _port(column: str) -> str:
    m = _ELEMENT.match(column)
    return m.group(1) if m else column


def trace_groups(traces: pd.DataFrame) -> list[tuple[str, list[str]]]:
    """(title, columns) per panel: a viewer's panels when one recognises the traces, else one panel per port
    (at most 8)."""
    _, panels = viewer_for(traces)
    if panels:
        return panels
    ports: dict[str, list[str]] = {}
    for c in traces.columns:
        # only numbers and Booleans plot over time; String and Binary (hex) columns are left out
        if str(c) != "time" and (pd.api.types.is_numeric_dtype(traces[c]) or pd.api.types.is_bool_dtype(traces[c])):
            ports.setdefault(_port(str(c)), []).append(str(c))
    return [(name, cols) for name, cols in list(ports.items())[:8]]


def traces_figure(fig: Figure, traces: pd.DataFrame, title: str = "") -> list:
    """One panel per group of :func:`trace_groups` over time (fig cleared first); returns the axes."""
    fig.clear()
    groups = trace_groups(traces)
    t = traces["time"].to_numpy() if "time" in traces.columns else np.arange(len(traces))
    axes = []
    for k, (name, cols) in enumerate(groups):
        ax = fig.add_subplot(len(groups), 1, k + 1)
        for c in cols:
            ax.plot(t, traces[c].to_numpy(dtype=float), linewidth=1.0, label=c.rsplit(".", 1)[-1])
        ax.set_ylabel(name)
        if len(cols) <= 8:
            ax.legend(fontsize="x-small", ncol=min(len(cols), 4), loc="upper right")
        axes.append(ax)
    if axes:
        axes[-1].set_xlabel("time [s]")
        if title:
            axes[0].set_title(title)
    return axes


def animation(fig: Figure, traces: pd.DataFrame) -> Any:
    """The animation of the viewer that recognises ``traces``, drawn into ``fig``; None when there is none.

    Keep a reference to the returned animation, or it stops.
    """
    viewer, _ = viewer_for(traces)
    if viewer is None or viewer.animation is None:
        return None
    return viewer.animation(fig, traces)
