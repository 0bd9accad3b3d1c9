"""Point-cloud figures of a results table (matplotlib, no pyplot state).

Every function draws onto a :class:`matplotlib.figure.Figure` it is given or
creates one, so the same code serves files (Agg), the HTML report and the Tk
explorer.  Points are drawn with at most two ``scatter`` calls (greyed, then
coloured), never one artist per point, so 17 061 points draw in well under a
second.  Artists carry a ``gid`` ('greyed', 'points', 'selected', 'front')
so callers and tests can find them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import PathCollection
from matplotlib.figure import Figure

from cosim.analysis.table import ResultsTable

GREY = (0.78, 0.78, 0.78, 0.5)
CMAP = "turbo"  # the thesis's violet-to-red scale


@dataclass
class CloudCounts:
    """How many rows a cloud drew coloured, greyed, and could not draw (a coordinate missing)."""

    coloured: int
    greyed: int
    missing: int


def scatter_cloud(fig: Figure, table: ResultsTable, x: str, y: str, z: str | None = None,
                  color: str | None = None, active: np.ndarray | None = None,
                  rows: np.ndarray | None = None, selected: int | None = None,
                  title: str | None = None) -> tuple[Axes, CloudCounts]:
    """Draw the cloud of ``rows`` (default all) into ``fig`` (cleared first); returns (axes, counts).

    ``active`` marks rows drawn in colour; the others are greyed.  The colour
    bar spans the active rows only, as in the thesis's figures.  ``selected``
    (a row position) is ringed in black.  Raises AnalysisError for an unknown column.
    """
    n = len(table.df)
    rows = np.ones(n, dtype=bool) if rows is None else np.asarray(rows, dtype=bool)
    active = np.ones(n, dtype=bool) if active is None else np.asarray(active, dtype=bool)
    names = [c for c in (x, y, z) if c]
    coords = [table.values(c) for c in names]
    cvals = table.values(color) if color else None  # read first: an unknown column raises before drawing
    drawable = rows & np.all([np.isfinite(c) for c in coords], axis=0)
    coloured = drawable & active
    greyed = drawable & ~active

    fig.clear()
    # mpl_toolkits (the 3-D axes) has no types: axes3d is Any to mypy, ax the Axes both kinds are
    axes3d = fig.add_subplot(111, projection="3d") if z else None
    ax: Axes = axes3d if axes3d is not None else fig.add_subplot(111)
    pts = lambda m: [c[m] for c in coords]  # noqa: E731 - tiny local selector
    size = _marker_size(int(drawable.sum()))
    kwargs: dict = {"s": size, "linewidths": 0, **({"depthshade": False} if z else {})}
    if greyed.any():
        _scatter(ax, pts(greyed), color=GREY, gid="greyed", **kwargs)
    kwargs["gid"] = "points"
    if color and cvals is not None:
        cv = cvals[coloured]
        finite = cv[np.isfinite(cv)]
        vmin, vmax = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        sc = _scatter(ax, pts(coloured), c=cv, cmap=CMAP, vmin=vmin, vmax=vmax, plotnonfinite=True, **kwargs)
        bar = fig.colorbar(sc, ax=ax, pad=0.1 if z else 0.02)
        bar.set_label(table.label(color))
    else:
        _scatter(ax, pts(coloured), color="tab:blue", **kwargs)
    ax.set_xlabel(table.label(x))
    ax.set_ylabel(table.label(y))
    if z and axes3d is not None:
        axes3d.set_zlabel(table.label(z))
    if selected is not None and 0 <= selected < n and drawable[selected]:
        sel = [np.array([c[selected]]) for c in coords]
        _scatter(ax, sel, s=max(4 * size, 80), facecolors="none", edgecolors="black", linewidths=1.5, gid="selected")
    if title:
        ax.set_title(title)
    counts = CloudCounts(int(coloured.sum()), int(greyed.sum()), int((rows & ~drawable).sum()))
    return ax, counts


def _scatter(ax: Axes, points: Sequence[np.ndarray], **style: Any) -> PathCollection:
    """``ax.scatter`` of ``points``: x and y, and z on a 3-D axes (Axes3D.scatter takes xs, ys, zs in that
    place); ``style``: scatter's keywords, as matplotlib takes them."""
    return ax.scatter(*points, **style)


def _marker_size(n: int) -> float:
    """Smaller markers for bigger clouds, so 17 000 points stay readable."""
    return float(np.clip(3000.0 / max(n, 1), 4.0, 40.0))


def draw_front(ax, table: ResultsTable, x: str, y: str, front: np.ndarray, senses: Sequence[str] = ("min", "min")):
    """Mark the Pareto-front rows over a 2-D cloud and join them as a step line (in ``x`` order)."""
    xs, ys = table.values(x)[front], table.values(y)[front]
    order = np.argsort(xs, kind="stable")
    ax.plot(xs[order], ys[order], color="black", linewidth=1.0, drawstyle="steps-post", gid="front-line")
    ax.scatter(xs, ys, s=40, facecolors="red", edgecolors="black", linewidths=0.8, zorder=5, gid="front",
               label=f"Pareto front ({int(front.sum())})")
    ax.legend(loc="best")


def new_figure(width: float = 7.0, height: float = 5.0) -> Figure:
    """A figure not registered with pyplot (safe headless and in threads)."""
    fig = Figure(figsize=(width, height), dpi=100)
    return fig


def save(fig: Figure, path) -> None:
    """Write ``fig`` to ``path``; the format follows the suffix (png, svg, pdf)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    if fig.canvas is None or type(fig.canvas).__name__ == "FigureCanvasBase":
        FigureCanvasAgg(fig)
    fig.savefig(path, bbox_inches="tight")
