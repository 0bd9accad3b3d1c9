"""K instances of one FMU set and stepped by C loops: the lock-step runner's FMU rows (kernel.c's ``cosim_rows_*``).

A lock-step group (:mod:`cosim.execution.lockstep`) holds K instances of each FMU, one per design point, and
calls the same function on each of them at every communication step: set the inputs, ``doStep``.  From Python
that is one ctypes call per instance and call (about 1.5-2 us each); here it is one ctypes call per step for
all rows, and the loop over them is C calling the FMI functions FMPy resolved.  The FMU sees the same calls
with the same arguments in the same order, so its results are the same bit for bit.

After C has called an instance, the instance's Python object does not know it: :meth:`NativeRows.sync` must
run before anything else reads or calls the instances (it marks their cached reads stale and sets their
time), which :class:`~cosim.execution.lockstep.InstanceBatch` does.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Callable, Sequence

import numpy as np

from cosim.master.native import library as lib
from cosim.master.native.algorithm import _CALL_TYPES, _version, describe_fmu
from cosim.units.protocol import Selection

_REAL_TYPES = ("Real", "Float64")  # FMI 2.0 / FMI 3.0 names of a double


@lru_cache(maxsize=1)
def _functions() -> tuple[Callable[..., int], Callable[..., int], Callable[..., int]]:
    """``cosim_rows_set_reals``, ``cosim_rows_do_step`` and ``cosim_rows_get_reals`` with their ctypes
    signatures (raises KernelUnavailable when the library cannot be built, OSError when it cannot be loaded)."""
    dll = ctypes.CDLL(str(lib.library_path()))
    set_reals, do_step, get_reals = dll.cosim_rows_set_reals, dll.cosim_rows_do_step, dll.cosim_rows_get_reals
    set_reals.argtypes = get_reals.argtypes = [
        ctypes.c_void_p, ctypes.c_long, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_size_t,
        ctypes.c_void_p, ctypes.c_long, ctypes.POINTER(lib.KFail)]
    do_step.argtypes = [ctypes.c_void_p, ctypes.c_long, ctypes.c_void_p, ctypes.c_double, ctypes.c_double,
                        ctypes.POINTER(lib.KFail)]
    set_reals.restype = do_step.restype = get_reals.restype = ctypes.c_int
    return set_reals, do_step, get_reals


@dataclass(frozen=True)
class RealInputs:
    """What :meth:`NativeRows.set` sets: the value references of a plain Real/Float64 selection (one group, in
    the selection's order) and the number of values they take (an FMI 3.0 array takes several)."""

    vrs: Any  # the ctypes array the instances' own selection holds (kept alive by it)
    n_vrs: int
    n_values: int


class NativeRows:
    """The instances ``units`` (K FMI 2.0/3.0 co-simulation instances of one FMU) called by C loops.

    Raises ValueError when they do not qualify (another kind of unit, FMI versions mixed, a unit whose set or
    step does more than the FMI call), KernelUnavailable or OSError when the C library is not there.
    """

    def __init__(self, units: Sequence[Any]):
        versions = {_version(u) for u in units}  # ValueError for most units but FMI 2.0/3.0 CS instances
        if versions - {2, 3} or len(versions) != 1 or not all(getattr(u, "_plain_calls", False) for u in units):
            raise ValueError("the instances' FMI calls are not plain or their FMI versions differ")
        self.units = list(units)
        self._set_reals, self._do_step, self._get_reals = _functions()
        self._table = (lib.KUnit * len(self.units))()
        for i, unit in enumerate(self.units):
            describe_fmu(self._table[i], unit)
        self._address = ctypes.addressof(self._table)
        self._fail = lib.KFail()
        self._fail_ref = ctypes.byref(self._fail)
        self.version = versions.pop()
        self.dirty = False  # True after a C call the units' Python objects have not seen (sync)
        self._t = 0.0
        self._values: np.ndarray | None = None  # the last values set, and their address
        self._values_at = 0

    def inputs(self, selections: Sequence[Selection]) -> RealInputs | None:
        """The set plan of one selection per unit (the same elements), or None when it is not a plain set of
        Real/Float64 values (then the units' own writers must set it)."""
        plans = set()
        for sel in selections:
            groups = getattr(sel, "groups", None)
            if (not getattr(sel, "plain", False) or getattr(sel, "structural", False) or not groups
                    or groups[0].fmi_type not in _REAL_TYPES):
                return None
            plans.add((tuple(groups[0].vrs), groups[0].n_values))
        if len(plans) != 1:
            return None
        group = selections[0].groups[0]  # type: ignore[attr-defined]
        return RealInputs(group.vrs, group.n_vrs, group.n_values)

    def set(self, plan: RealInputs, count: int, rows: int, values: np.ndarray) -> None:
        """Set ``plan``'s variables of the ``count`` rows listed (int64) at address ``rows`` to their rows of
        ``values`` (K x n float64, C-ordered); raises the unit's UnitError for a status above Warning."""
        self.dirty = True
        if values is not self._values:  # a transfer hands the same buffer at every step: its address once
            self._values, self._values_at = values, values.ctypes.data
        if self._set_reals(self._address, count, rows, plan.vrs, plan.n_vrs, plan.n_values, self._values_at,
                           values.shape[1], self._fail_ref) != lib.RUN_DONE:
            self._raise()

    def get(self, plan: RealInputs, count: int, rows: int, out: np.ndarray) -> None:
        """Read ``plan``'s variables of the ``count`` rows listed (int64) at address ``rows`` into their rows of
        ``out`` (K x n float64, C-ordered): the FMI get each unit's reader makes, in a C loop; raises the unit's
        UnitError for a status above Warning."""
        if self._get_reals(self._address, count, rows, plan.vrs, plan.n_vrs, plan.n_values, out.ctypes.data,
                           out.shape[1], self._fail_ref) != lib.RUN_DONE:
            self._raise()

    def do_step(self, count: int, rows: int, t: float, h: float) -> None:
        """``doStep(t, h)`` of the ``count`` rows listed (int64) at address ``rows``, in order; raises as the
        unit's do_step raises (UnitError, SimulationEnded) for the first row that fails or ends the simulation."""
        self.dirty = True
        self._t = t
        outcome = self._do_step(self._address, count, rows, t, h, self._fail_ref)
        if outcome != lib.RUN_DONE:
            self._raise(outcome)

    def sync(self) -> None:
        """Tell the units' Python objects that C called them: no cached read is handed out again, their time
        is that of the last step started."""
        if self.dirty:
            self.dirty = False
            for unit in self.units:
                unit.generation += 1
                unit.time = self._t

    def _raise(self, outcome: int = lib.RUN_FAILED) -> None:
        self.sync()
        fail = self._fail
        unit = self.units[fail.unit]
        if outcome == lib.RUN_ENDED:
            unit._ended_or_returned_early(fail.t, fail.h)
        if fail.call == lib.CALL_DOSTEP:
            unit.time = fail.t
            if self.version == 2:
                unit.step_outcome(fail.status)
            raise unit.fail_status(f"fmi{self.version}DoStep", fail.status)
        verb = "Get" if fail.call == lib.CALL_GET else "Set"
        raise unit.fail_status(f"fmi{self.version}{verb}{_CALL_TYPES[self.version][0]}", fail.status)
