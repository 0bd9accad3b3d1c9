"""The geometry of the decision room's views of many columns (no bokeh here): the parallel coordinates' lines
and the 3-D scatter's projection.

**3-D scatter.** Bokeh draws in two dimensions, so the room projects: each of the three columns is scaled to
[-1, 1] over its bounds (u, v, w), turned by the azimuth ``a`` about the vertical w axis and seen from the
elevation ``e`` (orthographic):

    px = u cos a - v sin a
    py = w cos e + (u sin a + v cos a) sin e

The browser recomputes the projection when the azimuth or elevation changes (:data:`PROJECT_JS`, the same
formula), so turning the view needs no round trip to the server; :func:`project` is what the server draws
first and what the tests check the page against.

**Parallel coordinates.** Axis k at x = k, each column scaled to [0, 1] over its bounds; a design is a
polyline through its values, drawn as one line with NaN between designs (one glyph for any number of them).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

SAMPLE = 20_000  # designs drawn by these views at most: a larger table shows a random sample of them


def scaled(values: np.ndarray, lo: float, hi: float, to: tuple[float, float] = (0.0, 1.0)) -> np.ndarray:
    """``values`` mapped linearly from [lo, hi] onto ``to`` (a constant column onto the middle); NaN stays."""
    a, b = to
    if hi <= lo:
        return np.where(np.isnan(values), np.nan, (a + b) / 2)
    return a + (b - a) * (values - lo) / (hi - lo)


def project(u: np.ndarray, v: np.ndarray, w: np.ndarray, azimuth: float, elevation: float
            ) -> tuple[np.ndarray, np.ndarray]:
    """The screen coordinates of points (u, v, w) seen from ``azimuth`` and ``elevation`` (radians)."""
    ca, sa, ce, se = np.cos(azimuth), np.sin(azimuth), np.cos(elevation), np.sin(elevation)
    return u * ca - v * sa, w * ce + (u * sa + v * ca) * se


# the same as project(), over each of the sources' u, v, w into its px, py; `sources` (a list of
# ColumnDataSources), `azimuth` and `elevation` (sliders) are the CustomJS arguments.  Used by the 3-D scatter
# (dimensions.py) and the 3-D view of a viewer's link frames (animation.py).
PROJECT_JS = """
const a = azimuth.value, e = elevation.value;
const ca = Math.cos(a), sa = Math.sin(a), ce = Math.cos(e), se = Math.sin(e);
for (const s of sources) {
  const d = s.data, n = d.u.length;
  const px = new Float64Array(n), py = new Float64Array(n);
  for (let i = 0; i < n; i++) {
    px[i] = d.u[i] * ca - d.v[i] * sa;
    py[i] = d.w[i] * ce + (d.u[i] * sa + d.v[i] * ca) * se;
  }
  s.data = {...d, px: px, py: py};
}
"""

# a drag in a 3-D view turns it: horizontal pixels turn the azimuth (wrapped to [-pi, pi]), vertical ones the
# elevation (clipped to [-pi/2, pi/2]); a Pan event's CustomJS with the `azimuth` and `elevation` sliders
TURN_JS = """
const clip = (v, lo, hi) => Math.min(hi, Math.max(lo, v));
let a = azimuth.value + cb_obj.delta_x * 0.01;
a = a > Math.PI ? a - 2 * Math.PI : (a < -Math.PI ? a + 2 * Math.PI : a);
azimuth.value = a;
elevation.value = clip(elevation.value + cb_obj.delta_y * 0.01, -Math.PI / 2, Math.PI / 2);
"""

def axes_ends() -> dict[str, list]:
    """The corner and the far end of each axis: (corner, u end), (corner, v end), (corner, w end) as points
    u, v, w (6 points: a segment is points 2k and 2k + 1)."""
    return {"u": [-1.0, 1.0, -1.0, -1.0, -1.0, -1.0], "v": [-1.0, -1.0, -1.0, 1.0, -1.0, -1.0],
            "w": [-1.0, -1.0, -1.0, -1.0, -1.0, 1.0]}


def parallel_lines(columns: Sequence[np.ndarray], bounds: Sequence[tuple[float, float]], rows: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) of the polylines of ``rows`` through the axes of ``columns`` (each scaled over its bounds), one
    NaN between two designs: k points and a NaN per row."""
    k = len(columns)
    if not len(rows) or not k:
        return np.zeros(0), np.zeros(0)
    y = np.full((len(rows), k + 1), np.nan)
    for j, (values, (lo, hi)) in enumerate(zip(columns, bounds)):
        y[:, j] = scaled(values[rows], lo, hi)
    x = np.tile(np.append(np.arange(k, dtype=float), np.nan), len(rows))
    return x, y.reshape(-1)


def sample(n: int, limit: int = SAMPLE, seed: int = 0) -> np.ndarray:
    """Row positions drawn by the views of many columns: every row up to ``limit``, else a random ``limit`` of
    them (sorted, the same for every tab)."""
    if n <= limit:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, size=limit, replace=False))
