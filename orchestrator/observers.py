"""Observers: what watches a run without changing it.

An observer gets three calls: ``initialized(t, values)`` once the units are
initialized, ``step(t, values)`` after each communication step and
``finished(t)`` at the end.  ``values`` is one numpy vector holding every
probed scalar, in the order of the ``columns`` the observer was given.

:class:`TraceRecorder` keeps full traces; :class:`ObjectiveReducer` reduces
signals to numbers on the fly, so a sweep never holds a whole trace.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from .expressions import Expression
from .spec import ObjectiveSpec


class Observer:
    """Base class with no-op hooks."""

    def initialized(self, t: float, values: np.ndarray) -> None:
        pass

    def step(self, t: float, values: np.ndarray) -> None:
        pass

    def finished(self, t: float) -> None:
        pass


class TraceRecorder(Observer):
    """Records the chosen columns at every communication point.

    ``capacity`` is the expected number of samples; storage grows if needed.
    """

    def __init__(self, all_columns: Sequence[str], recorded: Sequence[str], capacity: int = 1024):
        self.columns = list(recorded)
        self._index = np.array([list(all_columns).index(c) for c in recorded], dtype=int)
        self._data = np.empty((max(capacity, 1), len(self.columns) + 1))
        self._n = 0

    def _append(self, t: float, values: np.ndarray) -> None:
        if self._n == len(self._data):
            self._data = np.concatenate([self._data, np.empty_like(self._data)])
        row = self._data[self._n]
        row[0] = t
        row[1:] = values[self._index]
        self._n += 1

    def initialized(self, t: float, values: np.ndarray) -> None:
        self._append(t, values)

    def step(self, t: float, values: np.ndarray) -> None:
        self._append(t, values)

    def frame(self) -> Any:
        """The traces as a pandas DataFrame: a 'time' column and one per signal."""
        import pandas as pd

        return pd.DataFrame(self._data[: self._n], columns=["time", *self.columns])


class ObjectiveReducer(Observer):
    """Computes every signal reduction of the spec's objectives while the run goes.

    Integrals use the trapezoidal rule over the communication points; ``mean``
    and ``rms`` are time averages (integral over duration).  ``time_of_max``
    and ``time_of_min`` give the first time the extreme is reached.  An array
    signal gives one value per element.
    """

    def __init__(self, all_columns: Sequence[str], objectives: Sequence[tuple[ObjectiveSpec, Sequence[str]]]):
        self.objectives = [o for o, _ in objectives]
        columns = list(all_columns)
        self._slices = []
        flat: list[int] = []
        for _, cols in objectives:
            start = len(flat)
            flat.extend(columns.index(c) for c in cols)
            self._slices.append(slice(start, len(flat)))
        self._index = np.array(flat, dtype=int)
        n = len(flat)
        self._first = np.full(n, np.nan)
        self._last = np.full(n, np.nan)
        self._min = np.full(n, np.inf)
        self._max = np.full(n, -np.inf)
        self._t_min = np.full(n, np.nan)
        self._t_max = np.full(n, np.nan)
        self._integral = np.zeros(n)
        self._integral_abs = np.zeros(n)
        self._integral_sq = np.zeros(n)
        self._t0 = self._t_prev = None

    def initialized(self, t: float, values: np.ndarray) -> None:
        x = values[self._index]
        self._first = x.copy()
        self._t0 = t
        self._update(t, x)

    def step(self, t: float, values: np.ndarray) -> None:
        x = values[self._index]
        dt = t - self._t_prev
        prev = self._last
        self._integral += 0.5 * dt * (prev + x)
        self._integral_abs += 0.5 * dt * (np.abs(prev) + np.abs(x))
        self._integral_sq += 0.5 * dt * (prev * prev + x * x)
        self._update(t, x)

    def _update(self, t: float, x: np.ndarray) -> None:
        lower = x < self._min
        self._min[lower] = x[lower]
        self._t_min[lower] = t
        higher = x > self._max
        self._max[higher] = x[higher]
        self._t_max[higher] = t
        nan = np.isnan(x)  # a NaN sample poisons min/max so it cannot hide
        self._min[nan] = self._max[nan] = np.nan
        self._last = x.copy()
        self._t_prev = t

    def results(self) -> dict[str, Any]:
        """Objective name -> value (float, or a numpy array for an array signal)."""
        duration = (self._t_prev - self._t0) if self._t0 is not None else 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            table = {
                "final": self._last, "initial": self._first, "min": self._min, "max": self._max,
                "integral": self._integral, "integral_abs": self._integral_abs,
                "mean": self._integral / duration if duration > 0 else self._last,
                "rms": np.sqrt(self._integral_sq / duration) if duration > 0 else np.abs(self._last),
                "time_of_max": self._t_max, "time_of_min": self._t_min,
            }
        out: dict[str, Any] = {}
        for objective, part in zip(self.objectives, self._slices):
            values = table[objective.reduce][part]  # type: ignore[index]
            out[objective.name] = float(values[0]) if len(values) == 1 else values.copy()
        return out


def evaluate_expressions(objectives: Sequence[ObjectiveSpec], values: Mapping[str, Any]) -> dict[str, Any]:
    """Add the expression objectives to ``values`` (dependencies first).

    Raises ExpressionError when an expression cannot be evaluated.
    """
    result = dict(values)
    pending = [o for o in objectives if o.expr]
    parsed = {o.name: Expression(o.expr) for o in pending}  # type: ignore[arg-type]
    while pending:
        ready = [o for o in pending if parsed[o.name].names <= result.keys()]
        if not ready:  # cycles are refused by the system check; this is a safety net
            raise ValueError("objective expressions refer to each other in a cycle")
        for o in ready:
            value = parsed[o.name].evaluate(result)
            result[o.name] = float(value) if np.ndim(value) == 0 else np.asarray(value, dtype=float)
            pending.remove(o)
    return result


def flatten_objectives(values: Mapping[str, Any]) -> dict[str, float]:
    """Array objectives become columns ``name[1]`` .. ``name[n]``; scalars stay."""
    flat: dict[str, float] = {}
    for name, value in values.items():
        if np.ndim(value) == 0:
            flat[name] = float(value)
        else:
            for i, v in enumerate(np.asarray(value).ravel(), start=1):
                flat[f"{name}[{i}]"] = float(v)
    return flat
