"""Observers: what watches a run without changing it.

A run (:class:`cosim.execution.run.Execution`) is given its observers.  Each gets
``attached(context)`` once the run's units are initialized (the context says
what the run probes: its ``columns``, their types and units, the live units),
``initialized(t, values)`` at the start time, ``step(t, values)`` after each
communication step, ``finished(t)`` at a run's regular end and ``detached()``
always, also after a failure.  ``values`` is one numpy vector holding every
probed scalar, in the order of the context's ``columns``.  A
:class:`StopCondition` may end the run at a communication point.

:class:`TraceRecorder` keeps full traces; :class:`ObjectiveReducer` reduces
signals to numbers on the fly, so a sweep never holds a whole trace.
"""

from __future__ import annotations

from typing import Any, Callable, Mapping, Sequence

import numpy as np


def _integral(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    integral: np.ndarray = np.trapezoid(x, t, axis=0) if len(t) > 1 else np.zeros(x.shape[1])
    return integral


def _time_average(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    duration = t[-1] - t[0]
    average: np.ndarray = _integral(t, x) / duration if duration > 0 else x[-1]
    return average


def _rms(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    duration = t[-1] - t[0]
    rms: np.ndarray = np.sqrt(_integral(t, x * x) / duration) if duration > 0 else np.abs(x[-1])
    return rms


# The reductions an objective may name ("reduce"): each maps the sample times t
# and the samples x (one column per signal element) to one value per column.
# This dict is the one list of reduction names (the spec check uses its keys).
REDUCERS: dict[str, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    "final": lambda t, x: x[-1],
    "initial": lambda t, x: x[0],
    "min": lambda t, x: np.min(x, axis=0),
    "max": lambda t, x: np.max(x, axis=0),
    "mean": _time_average,
    "integral": _integral,
    "integral_abs": lambda t, x: _integral(t, np.abs(x)),
    "rms": _rms,
    "time_of_max": lambda t, x: t[np.argmax(x, axis=0)],
    "time_of_min": lambda t, x: t[np.argmin(x, axis=0)],
}


class Observer:
    """Base class with no-op hooks (module docstring)."""

    def attached(self, context: Any) -> None:
        """The run's units are initialized: ``context`` has ``columns`` (the order of ``values``), ``types``,
        ``units`` (of measure), ``system`` and ``live`` (the units by name)."""

    def initialized(self, t: float, values: np.ndarray) -> None:
        pass

    def step(self, t: float, values: np.ndarray) -> None:
        pass

    def load(self, times: np.ndarray, values: np.ndarray) -> bool:
        """Take many samples at once instead of ``initialized`` and ``step`` one by one (a warm start's replay):
        ``times`` (n,), ``values`` (n, columns).  Returns False when this observer takes them one by one."""
        return False

    def finished(self, t: float) -> None:
        pass

    def detached(self) -> None:
        """The run is over, however it ended: release what :meth:`attached` hooked."""


class StopCondition(Observer):
    """An observer that can end a run at a communication point: once :attr:`reason` is set (by its ``step``),
    the run stops there, with ``status`` (``"ok"``: the run ended as asked, e.g. ``stop_when``)."""

    status = "ok"
    reason: str | None = None

    def objectives_at_stop(self, objectives: dict[str, float]) -> dict[str, float]:
        """The objective columns of a run this condition stopped with a status other than ``"ok"``, from the
        values reduced so far (``objectives``): these as they are, unless the condition knows better (a pruned
        design's bound vector)."""
        return objectives


class StopWhen(StopCondition):
    """Ends the run at the first communication point where the probed column ``column`` is non-zero (the
    spec's ``experiment.stop_when``)."""

    def __init__(self, column: str):
        self.column = column
        self.reason = None

    def attached(self, context: Any) -> None:
        self._index = list(context.columns).index(self.column)
        self.reason = None

    def step(self, t: float, values: np.ndarray) -> None:
        if values[self._index]:
            self.reason = f"'{self.column}' became true"


class TraceRecorder(Observer):
    """Records the chosen columns at every communication point (and at events, :meth:`event`).

    ``capacity`` is the expected number of samples; storage grows if needed.
    """

    def __init__(self, all_columns: Sequence[str], recorded: Sequence[str], capacity: int = 1024,
                 exact: "ExactColumns | None" = None, types: Mapping[str, tuple[str, str | None]] | None = None,
                 units: Mapping[str, str] | None = None):
        self.columns = list(recorded)
        # Strings, bytes and 64-bit integers are kept as Python objects (``exact``), the rest in one float array.
        self._exact = exact if exact is not None and any(c in exact.columns for c in recorded) else None
        exact_names = set(self._exact.columns) if self._exact else set()
        self._float_columns = [c for c in recorded if c not in exact_names]
        self._exact_index = [self._exact.columns.index(c) for c in recorded if c in exact_names] if self._exact else []
        self._exact_rows: list[list[Any]] = []
        self._types = dict(types or {})
        self._units = {c: u for c, u in (units or {}).items() if c in self.columns}
        index = [list(all_columns).index(c) for c in self._float_columns]
        # recording every probed column in order is a plain copy, not fancy indexing
        self._index = slice(None) if index == list(range(len(all_columns))) else np.array(index, dtype=int)
        self._data = np.empty((max(capacity, 1), len(self._float_columns) + 1))
        self._n = 0

    def _append(self, t: float, values: np.ndarray) -> None:
        if self._n == len(self._data):
            self._data = np.concatenate([self._data, np.empty_like(self._data)])
        row = self._data[self._n]
        row[0] = t
        row[1:] = values[self._index]
        self._n += 1
        if self._exact is not None:
            current = self._exact.read()
            self._exact_rows.append([current[i] for i in self._exact_index])

    # every sample is one row, at the start and after each step (the hooks are the append itself: no extra call)
    initialized = _append
    step = _append

    def event(self, t: float, values: np.ndarray) -> None:
        """An extra row at an event inside a step (see a model-exchange unit's ``record_events``): rows stay in
        time order, so ``time`` is non-decreasing, with equal times at an event (before it, after it)."""
        self._append(t, values)

    def load(self, times: np.ndarray, values: np.ndarray) -> bool:
        """Replace the samples by a whole run's: ``times`` (n,), ``values`` (n, all columns) as ``step`` receives
        them; False (nothing loaded) when exact columns are recorded, which are read from the units one by one."""
        if self._exact is not None:
            return False
        data = np.empty((len(times), len(self._float_columns) + 1))  # row-major as step() fills it: the
        data[:, 0] = times                                             # reductions then sum in the same order
        data[:, 1:] = values[:, self._index]
        self._data, self._n = data, len(times)
        return True

    def data(self) -> np.ndarray:
        """The samples so far: column 0 is time, then one column per recorded signal."""
        return self._data[: self._n]

    def frame(self) -> Any:
        """The traces as a pandas DataFrame: a 'time' column and one per signal, each of its type.

        Real signals are float64, Integer int64 (UInt64 uint64), Boolean bool, String str and
        Binary the bytes as a hex string (so CSV and Parquet hold the same text).
        """
        import pandas as pd

        frame = pd.DataFrame(self._data[: self._n], columns=["time", *self._float_columns])
        if self._exact is not None:
            exact_names = [c for c in self.columns if c not in self._float_columns]
            for j, name in enumerate(exact_names):
                frame[name] = pd.Series([row[j] for row in self._exact_rows], dtype=object)
        for name in self.columns:
            kind, fmi_type = self._types.get(name, ("Real", None))
            frame[name] = _typed(frame[name], kind, fmi_type)
        frame = frame[["time", *self.columns]]
        if self._units:
            frame.attrs["units"] = dict(self._units)  # kept by Parquet (pandas attrs), read back by players
        return frame


def _typed(column: Any, kind: str, fmi_type: str | None) -> Any:
    if kind == "Integer" and len(column):
        return column.astype("uint64" if fmi_type == "UInt64" else "int64")
    if kind == "Boolean":
        return column.astype(bool)
    if kind == "Binary":
        return column.map(lambda b: bytes(b).hex())
    if kind == "String":
        return column.astype(str)
    return column


class ExactColumns:
    """Columns read as Python objects, not floats: String, Binary and 64-bit integer signals."""

    def __init__(self, columns: Sequence[str], read: Callable[[], Sequence[Any]]):
        self.columns = list(columns)
        self.read = read


class ObjectiveReducer(TraceRecorder):
    """Reduces the signals of the spec's objectives to numbers at the end of a run.

    Only the objective signals are kept (one row per communication point), so
    the per-step cost is one indexed copy and the memory is bounded by the
    run's length, never by a sweep's size.  Integrals use the trapezoidal rule
    over the communication points; ``mean`` and ``rms`` are time averages
    (integral over duration).  ``time_of_max`` and ``time_of_min`` give the
    first time the extreme is reached.  An array signal gives one value per
    element; a NaN sample makes min, max and every integral NaN so it cannot
    hide.
    """

    def __init__(self, all_columns: Sequence[str], objectives: Sequence[tuple[str, str, Sequence[str]]]):
        """``objectives``: (name, reduction, the columns of its signal) for each objective to reduce; the
        reduction is a key of :data:`REDUCERS`."""
        self.objectives = [(name, reduce) for name, reduce, _ in objectives]
        columns = list(all_columns)
        self._slices = []
        flat: list[int] = []
        for _, _, cols in objectives:
            start = len(flat)
            flat.extend(columns.index(c) for c in cols)
            self._slices.append(slice(start, len(flat)))
        super().__init__(columns, [columns[i] for i in flat])
        self.kept = flat  # the columns of ``values`` kept, in the order the reductions see them
        self.slices = list(self._slices)  # objective k reduces kept[slices[k]]
        self._reduced: dict[str, Any] | None = None

    def load_reduced(self, reduced: dict[str, Any]) -> None:
        """Take a whole run's objective values reduced elsewhere (the native kernel's reducers, which equal
        :meth:`results` of the same samples bit for bit) instead of its samples."""
        self._reduced, self._n = reduced, 0

    def results(self) -> dict[str, Any]:
        """Objective name -> value (float, or a numpy array for an array signal)."""
        if self._reduced is not None:
            return {k: v.copy() if isinstance(v, np.ndarray) else v for k, v in self._reduced.items()}
        data = self.data()
        t, x = data[:, 0], data[:, 1:]
        reduced: dict[str, np.ndarray] = {}  # each reduction over every kept column at once, when first needed
        out: dict[str, Any] = {}
        for (name, reduce), part in zip(self.objectives, self._slices):
            if reduce not in reduced:
                with np.errstate(divide="ignore", invalid="ignore"):
                    reduced[reduce] = REDUCERS[reduce](t, x)
            values = reduced[reduce][part]
            out[name] = float(values[0]) if len(values) == 1 else values.copy()
        return out


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
