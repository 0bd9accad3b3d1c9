"""The point cloud of a large table as an image of bins, computed on the server (no bokeh here).

A page cannot draw 10^6 points (sending them alone takes longer than a user waits), so above
:data:`cosim.analysis.room.app.AGGREGATE_ABOVE` rows the room sends an image instead: the visible x-y
rectangle cut into ``width x height`` bins (about two screen pixels each), each bin coloured by what it holds:

- kept ok designs: the mean of the colour column over them, on the colour map (without a colour column, one
  plain colour);
- else kept designs of another status (failed, timeout, crashed): the colour of the most frequent one;
- else designs the filters drop: grey;
- else transparent.

Zooming or panning re-bins the new rectangle, so the image stays as sharp as points.  The binning is two
``np.bincount`` calls per layer over the rows' bin indices: ~0.1 s for 10^6 rows on the project's machine,
which is why this is numpy and not datashader (its numba, dask and xarray would be new dependencies for the
same image).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

TRANSPARENT = 0


@dataclass(frozen=True)
class Grid:
    """The rectangle [x0, x1] x [y0, y1] cut into ``width`` x ``height`` bins."""

    x0: float
    x1: float
    y0: float
    y1: float
    width: int
    height: int

    def bin_of(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The flat bin index (row-major, y up) of each point; -1 outside the rectangle or where x or y is NaN."""
        with np.errstate(invalid="ignore"):
            fx = (x - self.x0) / (self.x1 - self.x0) * self.width
            fy = (y - self.y0) / (self.y1 - self.y0) * self.height
            inside = (fx >= 0) & (fx <= self.width) & (fy >= 0) & (fy <= self.height)
        ix = np.minimum(np.where(inside, fx, 0).astype(np.int64), self.width - 1)  # the right edge is inside
        iy = np.minimum(np.where(inside, fy, 0).astype(np.int64), self.height - 1)
        return np.where(inside, iy * self.width + ix, -1)


def grid_around(x: np.ndarray, y: np.ndarray, width: int, height: int, pad: float = 0.02) -> Grid:
    """A grid over the finite range of ``x`` and ``y`` widened by ``pad`` of it on each side (a constant column
    gets a unit-wide range)."""
    def span(v: np.ndarray) -> tuple[float, float]:
        finite = v[np.isfinite(v)]
        lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        if hi <= lo:
            lo, hi = lo - 0.5, hi + 0.5
        d = (hi - lo) * pad
        return lo - d, hi + d

    (x0, x1), (y0, y1) = span(x), span(y)
    return Grid(x0, x1, y0, y1, width, height)


def rgba(hex_colour: str, alpha: int = 255) -> np.uint32:
    """'#rrggbb' as the uint32 of one RGBA pixel the way bokeh's image_rgba reads it (bytes R, G, B, A)."""
    r, g, b = (int(hex_colour[i:i + 2], 16) for i in (1, 3, 5))
    return np.uint32(r | g << 8 | b << 16 | alpha << 24)


def image(grid: Grid, cells: np.ndarray, kept_ok: np.ndarray, kept_other: np.ndarray, dropped: np.ndarray,
          colour: np.ndarray | None, colour_range: tuple[float, float], palette: Sequence[str], plain: str,
          status_codes: np.ndarray, status_colours: Sequence[str], grey: str) -> tuple[np.ndarray, np.ndarray]:
    """(the RGBA image, height x width uint32; the count of rows per bin, all layers) of the module docstring.

    ``cells`` are the rows' bins (:meth:`Grid.bin_of`); the three masks split the rows into layers;
    ``colour`` (or None) the colour column, mapped linearly over ``colour_range`` onto ``palette``;
    ``status_codes`` the index into ``status_colours`` of each row's status (for rows not ok).
    """
    n_bins = grid.width * grid.height
    out = np.full(n_bins, TRANSPARENT, dtype=np.uint32)
    inside = cells >= 0

    def count(mask: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        rows = inside & mask
        return np.bincount(cells[rows], weights=None if weights is None else weights[rows], minlength=n_bins)

    out[count(dropped) > 0] = rgba(grey)
    other = inside & kept_other
    if other.any() and len(status_colours):
        by_status = np.stack([np.bincount(cells[other & (status_codes == k)], minlength=n_bins)
                              for k in range(len(status_colours))])
        has = by_status.sum(axis=0) > 0
        lut = np.array([rgba(c) for c in status_colours], dtype=np.uint32)
        out[has] = lut[by_status.argmax(axis=0)[has]]
    ok_count = count(kept_ok)
    has_ok = ok_count > 0
    if colour is None:
        out[has_ok] = rgba(plain)
    else:
        finite = np.isfinite(colour)
        coloured = count(kept_ok & finite)
        mean = np.divide(count(kept_ok & finite, np.where(finite, colour, 0.0)), coloured,
                         out=np.full(n_bins, np.nan), where=coloured > 0)
        lo, hi = colour_range
        lut = np.array([rgba(c) for c in palette], dtype=np.uint32)
        scaled = (mean - lo) / (hi - lo if hi > lo else 1.0) * len(lut)  # NaN where no finite colour
        k = np.clip(np.nan_to_num(scaled, nan=-1.0), -1, len(lut) - 1).astype(np.int64)
        out[has_ok] = np.where(k[has_ok] >= 0, lut[np.maximum(k[has_ok], 0)], rgba(plain))
    everything = np.bincount(cells[inside], minlength=n_bins)
    return out.reshape(grid.height, grid.width), everything.reshape(grid.height, grid.width)


def nearest(x: np.ndarray, y: np.ndarray, rows: np.ndarray, px: float, py: float, grid: Grid,
            radius_bins: float = 3.0) -> int | None:
    """The row among ``rows`` (a mask) nearest to (px, py), distances measured in bins (so both axes count
    alike); None when none lies within ``radius_bins``."""
    sx = grid.width / (grid.x1 - grid.x0)
    sy = grid.height / (grid.y1 - grid.y0)
    candidates = np.flatnonzero(rows & np.isfinite(x) & np.isfinite(y))
    if not candidates.size:
        return None
    d2 = ((x[candidates] - px) * sx) ** 2 + ((y[candidates] - py) * sy) ** 2
    best = int(np.argmin(d2))
    return int(candidates[best]) if d2[best] <= radius_bins ** 2 else None

