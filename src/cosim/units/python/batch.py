"""Vectorised twins of Python units: one object advances a unit for K design points at once.

A lock-step run (:mod:`cosim.execution.lockstep`) steps K points of one system
through one loop.  A :class:`~cosim.units.python.unit.PythonUnit` whose
Python cost per step is worth sharing offers a twin, a subclass of
:class:`PythonBatchUnit` named by the unit class's own ``batch_class``
attribute (set on the class itself: a subclass that changes behaviour does not
inherit its parent's twin)::

    class Gain(PythonUnit):
        variables = (Variable("k", "parameter", start=2.0), Variable("u", "input"), Variable("y", "output"))
        def do_step(self, t, h):
            self.y = self.k * self.u

    class GainBatch(PythonBatchUnit):
        def do_step(self, t, h):
            self.y[:] = self.k * self.u      # every attribute has a leading axis of K rows

    Gain.batch_class = GainBatch

The twin has the same variables as its unit; each attribute holds all K
points: a scalar variable as an array of shape (K,), an array variable of n
elements as (K, n); row k is point k.  Its hooks (``initialize``,
``do_step(t, h)``, ``compute_outputs``, ``close``) work on all rows at once
and must give row k exactly what the single unit gives point k (the lock-step
tests compare them).  ``active`` holds the rows still running: a row whose
point has ended (``stop_when``) is never read again, so a twin may keep
computing it or skip it (the robot skips its pinocchio calls).  A twin that
cannot handle some combination of rows raises :class:`NotBatchable` from
``initialize``; the points then run one by one.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from cosim.units.protocol import ElementRef, SimulationEnded, UnitDescription, UnitError
from cosim.units.python.unit import PythonUnit, _AttributeSelection

_DTYPES = {"Real": float, "Integer": np.int64, "Boolean": bool}


class NotBatchable(Exception):
    """These points cannot run in lock-step through this twin (e.g. rows disagree on a mode); run them one by one."""


class PythonBatchUnit:
    """Base of vectorised twins (see the module docstring): K rows of one Python unit.

    ``get`` returns a float array (K, n) of the selected elements, ``set``
    takes one (``set_row`` sets one row, for parameters); ``do_step(t, h)``
    advances every row: the master algorithm calls it as it calls a unit's (and
    reports what it raises as a UnitError naming the unit, as for a unit).  The
    other hooks raise UnitError naming the unit when they raise.
    """

    def __init__(self, single_class: type[PythonUnit], name: str, rows: int):
        self.single_class: type[PythonUnit] = single_class  # the unit whose K rows this twin runs
        self.name = name
        self.rows = rows
        self.description: UnitDescription = single_class.describe_class()
        self._arrays = {v.name for v in self.description.variables if v.is_array}
        self._has_feedthrough = any(self.description.feedthrough.get(o.name) for o in self.description.outputs())
        self._outputs_stale = False
        self.active = np.arange(rows)
        self.start_time = 0.0
        self.stop_time: float | None = None
        self._apply_start_values()

    def _apply_start_values(self) -> None:
        for v in self.description.variables:
            dtype = _DTYPES.get(v.type, object)
            if v.is_array:
                start = v.start if v.start is not None else 0
                row = np.array(start, dtype=dtype).reshape(-1) if np.ndim(start) else np.full(v.size, start, dtype=dtype)
                setattr(self, v.name, np.tile(row, (self.rows, 1)))
            else:
                default = {"Real": 0.0, "Integer": 0, "Boolean": False, "String": ""}[v.type]
                value = np.empty(self.rows, dtype=dtype)
                value[:] = v.start if v.start is not None else default
                setattr(self, v.name, value)

    # the batch protocol (cosim.execution.lockstep) ------------------------------------

    def select(self, refs: Sequence[ElementRef]) -> _AttributeSelection:
        return _AttributeSelection(refs, self._arrays)

    def get(self, selection: _AttributeSelection) -> np.ndarray:
        """The selected elements of every row, (K, n) floats; the array is the selection's own buffer,
        valid until the next ``get`` with the same selection."""
        if self._outputs_stale:
            self._outputs_stale = False
            self._call("compute_outputs", None)
        out = selection.buffer
        if out is None or out.shape[0] != self.rows:
            out = selection.buffer = np.empty((self.rows, len(selection.refs)))
        i = 0
        for name, part, n in selection.runs:
            if part is None:
                out[:, i] = getattr(self, name)
                i += 1
            else:
                out[:, i:i + n] = getattr(self, name)[:, part]
                i += n
        return out

    def get_rows(self, selection: _AttributeSelection, rows: list[int]) -> np.ndarray:
        """The selected elements of ``rows`` only, (len(rows), n) floats."""
        return self.get(selection)[rows]

    def set(self, selection: _AttributeSelection, values: np.ndarray) -> None:
        i = 0
        for name, part, n in selection.runs:
            if part is None:
                getattr(self, name)[:] = values[:, i]
                i += 1
            else:
                getattr(self, name)[:, part] = values[:, i:i + n]
                i += n
        if self._has_feedthrough:
            self._outputs_stale = True

    def set_row(self, selection: _AttributeSelection, row: int, values: Sequence[Any]) -> None:
        """Set the selected elements of one row (a point's parameters and start values)."""
        i = 0
        for name, part, n in selection.runs:
            if part is None:
                getattr(self, name)[row] = values[i]
                i += 1
            else:
                getattr(self, name)[row, part] = values[i:i + n]
                i += n
        if self._has_feedthrough:
            self._outputs_stale = True

    def setup(self, start_time: float, stop_time: float | None) -> None:
        self.start_time = start_time
        self.stop_time = stop_time

    def enter_initialization(self) -> None:
        pass

    def exit_initialization(self) -> None:
        self._call("initialize", self.start_time)
        self._outputs_stale = self._has_feedthrough

    def reset(self) -> None:
        self._call("close", None)
        self._apply_start_values()
        self.active = np.arange(self.rows)
        self._outputs_stale = False

    def terminate(self) -> None:
        self._call("close", None)

    # hooks for twins -----------------------------------------------------------------

    def initialize(self) -> None:
        """Called once every row's parameters and start values are set, before stepping."""

    def do_step(self, t: float, h: float) -> None:
        """Advance every row from ``t`` to ``t + h``."""

    def compute_outputs(self) -> None:
        """Recompute the outputs of every row from its inputs (twins of units with direct feed-through)."""

    def close(self) -> None:
        """Free resources."""

    def _call(self, hook: str, t: float | None, *args: Any) -> None:
        try:
            getattr(self, hook)(*args)
        except (UnitError, SimulationEnded, NotBatchable):
            raise
        except Exception as exc:
            raise UnitError.raised(self.name, f"{hook}()", exc, t) from exc


def batch_class_of(cls: type) -> type[PythonBatchUnit] | None:
    """The vectorised twin a Python unit class declares itself (``batch_class`` in its own body), or None."""
    twin = cls.__dict__.get("batch_class")
    return twin if isinstance(twin, type) and issubclass(twin, PythonBatchUnit) else None
