"""The objective reductions of every point of a lock-step group at once.

A lock-step group (:mod:`cosim.execution.lockstep`) holds the samples of K points in one array (samples x
rows x columns), each point's up to its own last sample.  Reducing them point by point with
:class:`~cosim.master.observers.ObjectiveReducer` costs a dozen numpy calls per point; here each reduction
is a few numpy calls for the whole group, with the same values bit for bit:

- ``final`` / ``initial``: the point's last / first sample;
- ``max`` / ``min`` / ``time_of_max`` / ``time_of_min``: over the point's samples, those after its end
  replaced by -inf / +inf (which never win over a sample, NaN included; an all -inf prefix gives index 0 either
  way), reduced along the samples one after another as numpy reduces a point's (samples x columns) array;
- ``integral`` / ``integral_abs``: the trapezoid terms of ``np.trapezoid`` (``d * (y[k+1] + y[k]) / 2.0``)
  summed by a running sum along the samples, read at each point's last term: numpy sums a (samples x
  columns) array along the samples one row after another from 0.0, and so does the running sum once its
  first term has had 0.0 added (which only turns -0.0 into 0.0, as numpy's sum does).

That order argument needs at least two kept columns: numpy sums a single column as a 1-D array, pairwise.
:func:`reduce_group` returns None then, or for a reduction not listed here; the caller reduces point by point.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cosim.master.observers import ObjectiveReducer

GROUP_REDUCTIONS = frozenset(
    {"final", "initial", "max", "min", "time_of_max", "time_of_min", "integral", "integral_abs"})


def reduce_group(reducer: ObjectiveReducer, times: np.ndarray, data: np.ndarray,
                 ends: np.ndarray) -> list[dict[str, Any]] | None:
    """``reducer.results()`` of each point i, as if loaded with ``times[:ends[i] + 1]`` and
    ``data[:ends[i] + 1, i, :]`` (``data``: samples x rows x all probe columns, ``ends``: per point the index
    of its last sample); None when this cannot give the same values (module docstring).

    Each reduction reads only the columns of the objectives that use it (numpy reduces every column on its
    own, so the others do not change its values).
    """
    objectives = reducer.objectives
    if len(reducer.columns) < 2 or any(reduce not in GROUP_REDUCTIONS for _, reduce in objectives):
        return None
    index = reducer._index
    kept = np.arange(data.shape[2])[index] if isinstance(index, slice) else np.asarray(index)
    n = len(ends)
    last = int(ends.max())
    t = times[:last + 1]
    points = np.arange(n)
    after = (np.arange(last + 1)[:, None] > ends[None, :])[:, :, None]  # samples past each point's end
    # per reduction: the probe columns it reads, and per objective where its values are among them
    columns: dict[str, list[int]] = {}
    where: list[tuple[str, list[int]]] = []
    for (name, reduce), part in zip(objectives, reducer._slices):
        mine = columns.setdefault(reduce, [])
        positions = []
        for column in kept[part]:
            if column not in mine:
                mine.append(int(column))
            positions.append(mine.index(column))
        where.append((reduce, positions))
    reduced: dict[str, np.ndarray] = {}
    with np.errstate(divide="ignore", invalid="ignore"):
        for reduce, cols in columns.items():
            if reduce in ("final", "initial"):  # one sample per point: no copy of the others
                reduced[reduce] = data[ends if reduce == "final" else 0, points][:, cols]
            else:
                reduced[reduce] = _reduce(reduce, t, data[:last + 1, :n, cols], ends, after, points)
    results = []
    for i in range(n):
        out: dict[str, Any] = {}
        for (name, _), (reduce, positions) in zip(objectives, where):
            values = reduced[reduce][i, positions]
            out[name] = float(values[0]) if len(values) == 1 else values
        results.append(out)
    return results


def _reduce(reduce: str, t: np.ndarray, x: np.ndarray, ends: np.ndarray, after: np.ndarray,
            points: np.ndarray) -> np.ndarray:
    """One reduction of every point: points x kept columns."""
    result: np.ndarray
    if reduce in ("max", "time_of_max"):
        masked = np.where(after, -np.inf, x)
        result = masked.max(axis=0) if reduce == "max" else t[masked.argmax(axis=0)]
    elif reduce in ("min", "time_of_min"):
        masked = np.where(after, np.inf, x)
        result = masked.min(axis=0) if reduce == "min" else t[masked.argmin(axis=0)]
    elif len(t) < 2:  # every point has one sample: np.trapezoid is not called (the reducer's zeros)
        result = np.zeros(x.shape[1:])
    else:
        y = np.abs(x) if reduce == "integral_abs" else x
        d = np.diff(t)[:, None, None]
        terms = d * (y[1:] + y[:-1]) / 2.0
        terms[0] += 0.0
        result = np.cumsum(terms, axis=0)[np.maximum(ends - 1, 0), points]
        result[ends == 0] = 0.0  # a point with one sample integrates to zero
    return result
