"""How strongly each design parameter drives each objective.

Two measures per (parameter, objective) pair, over the rows where both have a value:

- **Spearman's rank correlation** rho in [-1, 1]: a monotonic trend and its
  direction (+1: the objective always grows with the parameter).
- **Correlation ratio** eta^2 in [0, 1]: the share of the objective's variance
  explained by the parameter alone, Var(E[Y|X]) / Var(Y).  On a full grid it
  is the first-order (main-effect) Sobol index; it also sees non-monotonic
  effects that rho misses (a U-shape has rho ~ 0 but eta^2 ~ 1).  Parameters
  with more than ``max_levels`` distinct values are grouped into that many
  quantile bins.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd


@dataclass(frozen=True)
class Influence:
    parameter: str
    objective: str
    spearman: float
    eta2: float
    n: int


def spearman(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman's rho of two equal-length arrays without NaN (NaN when either is constant or n < 3)."""
    if len(x) < 3:
        return float("nan")
    rx = pd.Series(x).rank().to_numpy()
    ry = pd.Series(y).rank().to_numpy()
    if rx.std() == 0 or ry.std() == 0:
        return float("nan")
    return float(np.corrcoef(rx, ry)[0, 1])


def correlation_ratio(x: np.ndarray, y: np.ndarray, max_levels: int = 20) -> float:
    """eta^2 of y grouped by x (levels, or quantile bins when x has many values); NaN for constant y."""
    if len(y) < 2 or np.var(y) == 0:
        return float("nan")
    levels = np.unique(x)
    if len(levels) > max_levels:
        edges = np.unique(np.quantile(x, np.linspace(0, 1, max_levels + 1)))
        groups = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    else:
        groups = np.searchsorted(levels, x)
    counts = np.bincount(groups)
    sums = np.bincount(groups, weights=y)
    used = counts > 0
    means = sums[used] / counts[used]
    between = np.sum(counts[used] * (means - y.mean()) ** 2)
    return float(between / np.sum((y - y.mean()) ** 2))


def influences(table, parameters: list[str], objectives: list[str], rows: np.ndarray | None = None) -> list[Influence]:
    """Both measures for every parameter x objective pair, over ``rows`` (default: ok rows)."""
    rows = table.ok_mask() if rows is None else rows
    out = []
    for p in parameters:
        x_all = table.values(p)
        for o in objectives:
            y_all = table.values(o)
            keep = rows & np.isfinite(x_all) & np.isfinite(y_all)
            x, y = x_all[keep], y_all[keep]
            out.append(Influence(p, o, spearman(x, y), correlation_ratio(x, y), int(keep.sum())))
    return out
