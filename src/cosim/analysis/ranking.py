"""Ranking designs by weighted objectives: the weighted sum and TOPSIS.

Both take a matrix of objective values (rows: designs, columns: objectives), a
sense per objective ('min' or 'max') and a non-negative weight per objective,
and return one score per row, higher is better; rows with a missing value in
any objective get NaN and rank last.

- **Weighted sum** (simple additive weighting, the MAUT form with linear
  utilities): each objective is scaled to [0, 1] between the worst (0) and
  the best (1) value among the rows given, and the score is the weighted mean
  of these utilities.  An objective with one value only is 1 for every row.
- **TOPSIS** (Hwang and Yoon 1981): each column is divided by its Euclidean
  norm and multiplied by its weight; the score is the closeness
  d- / (d+ + d-) of a row to the ideal point (best value in every column)
  against the anti-ideal point (worst in every column).  Scores lie in
  [0, 1]; the ideal row, when it exists, scores 1.

Both depend on which rows are given (the scaling and the ideal point are
theirs): ranking only the designs a filter keeps ranks them among themselves.

Written in numpy rather than taken from an MCDM library (pymcdm, pyDecision):
the two methods are a dozen lines each, and cosim's own NaN and sense
handling would wrap any library call anyway.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

METHODS = {"weighted_sum": "weighted sum", "topsis": "TOPSIS"}


def check_inputs(values: np.ndarray, senses: Sequence[str], weights: Sequence[float]) -> tuple[np.ndarray, np.ndarray,
                                                                                                   np.ndarray]:
    """(values as a float matrix, +1 for 'max' / -1 for 'min' per column, weights summing to 1).

    Raises ValueError when the shapes disagree, a sense is unknown, a weight is negative or not finite, or
    every weight is zero.
    """
    values = np.asarray(values, dtype=float)
    if values.ndim != 2:
        raise ValueError("values must be a 2-D array (designs x objectives)")
    k = values.shape[1]
    if len(senses) != k or len(weights) != k:
        raise ValueError(f"{k} objective column(s) but {len(senses)} sense(s) and {len(weights)} weight(s)")
    signs = []
    for s in senses:
        if str(s).lower() in ("min", "minimize"):
            signs.append(-1.0)
        elif str(s).lower() in ("max", "maximize"):
            signs.append(1.0)
        else:
            raise ValueError(f"unknown sense '{s}': use min or max")
    w = np.asarray(weights, dtype=float)
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise ValueError(f"weights must be finite and >= 0, got {list(weights)}")
    if k and w.sum() == 0:
        raise ValueError("at least one weight must be above 0")
    return values, np.array(signs), (w / w.sum() if k else w)


def utilities(values: np.ndarray, senses: Sequence[str]) -> np.ndarray:
    """Each objective scaled to [0, 1] over the complete rows: 1 the best value, 0 the worst (NaN rows stay NaN).

    The weighted sum's utilities; also what a radar chart of designs shows.
    """
    values, signs, _ = check_inputs(values, senses, [1.0] * np.asarray(values).shape[1])
    out = np.full(values.shape, np.nan)
    complete = np.all(np.isfinite(values), axis=1)
    if not complete.any():
        return out
    gains = values[complete] * signs  # larger is better in every column now
    lo, hi = gains.min(axis=0), gains.max(axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    out[complete] = np.where(hi > lo, (gains - lo) / span, 1.0)
    return out


def weighted_sum(values: np.ndarray, senses: Sequence[str], weights: Sequence[float]) -> np.ndarray:
    """Weighted mean of the utilities (module docstring); NaN for rows with a missing value."""
    _, _, w = check_inputs(values, senses, weights)
    return utilities(values, senses) @ w


def topsis(values: np.ndarray, senses: Sequence[str], weights: Sequence[float]) -> np.ndarray:
    """TOPSIS closeness to the ideal point (module docstring); NaN for rows with a missing value."""
    values, signs, w = check_inputs(values, senses, weights)
    out = np.full(len(values), np.nan)
    complete = np.all(np.isfinite(values), axis=1)
    if not complete.any():
        return out
    x = values[complete]
    norm = np.sqrt((x ** 2).sum(axis=0))
    v = x / np.where(norm > 0, norm, 1.0) * w
    best = np.where(signs > 0, v.max(axis=0), v.min(axis=0))
    worst = np.where(signs > 0, v.min(axis=0), v.max(axis=0))
    d_best = np.sqrt(((v - best) ** 2).sum(axis=1))
    d_worst = np.sqrt(((v - worst) ** 2).sum(axis=1))
    total = d_best + d_worst
    out[complete] = np.where(total > 0, d_worst / np.where(total > 0, total, 1.0), 1.0)  # all rows equal: all ideal
    return out


def scores(values: np.ndarray, senses: Sequence[str], weights: Sequence[float], method: str) -> np.ndarray:
    """The scores of ``method`` ('weighted_sum' or 'topsis'); raises ValueError for another name."""
    if method == "weighted_sum":
        return weighted_sum(values, senses, weights)
    if method == "topsis":
        return topsis(values, senses, weights)
    raise ValueError(f"unknown ranking method '{method}': use one of {', '.join(METHODS)}")


def rank_order(score: np.ndarray) -> np.ndarray:
    """Positions of ``score`` best first (ties in their given order), NaN scores last."""
    score = np.asarray(score, dtype=float)
    key = np.where(np.isnan(score), np.inf, -score)
    return np.argsort(key, kind="stable")
