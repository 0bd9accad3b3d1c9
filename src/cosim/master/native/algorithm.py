""":class:`NativeFixedStep`: Gauss-Seidel, Jacobi or jacobi-delayed stepped by the C kernel (kernel.c).

It implements the master contract (``advance`` takes one step in C), and :meth:`NativeFixedStep.run` takes
every step of a run in one call, recording the probed columns into a preallocated array that the run hands to
its observers in bulk (``Observer.load``).  It steps only FMI 2.0 / 3.0 co-simulation instances whose links
and probes are Real, Integer or Boolean scalars (:func:`cosim.system.kernel_choice.kernel_choice` decides
which systems qualify); the values are the Python master's bit for bit.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from cosim.master.algorithms import FixedStep
from cosim.master.contract import SystemView
from cosim.master.native import library as lib
from cosim.units.protocol import ElementRef, SimulationEnded, UnitError

TYPE_CODES = {"Real": 0, "Float64": 0, "Integer": 1, "Enumeration": 1, "Int32": 1, "Boolean": 2}
_CALL_TYPES = {2: ("Real", "Integer", "Boolean"), 3: ("Float64", "Int32", "Boolean")}
_ALGORITHMS = ("gauss-seidel", "jacobi", "jacobi-delayed")


@dataclass
class KernelRun:
    """What :meth:`NativeFixedStep.run` did: ``times`` (n,) and ``values`` (n, columns) of the probe at the
    start and after each step, the ``steps`` taken, the time ``t`` reached, and why it stopped early:
    ``stopped`` (the stop column became non-zero), ``ended`` (a unit ended the simulation) or ``error``."""

    times: np.ndarray
    values: np.ndarray
    steps: int
    t: float
    stopped: bool = False
    ended: SimulationEnded | None = None
    error: UnitError | None = None


def _version(unit: Any) -> int:
    from cosim.units.fmu.fmi2 import Fmi2Unit
    from cosim.units.fmu.fmi3 import Fmi3Unit

    if type(unit) is Fmi2Unit:
        return 2
    if type(unit) is Fmi3Unit:
        return 3
    raise ValueError(f"unit '{getattr(unit, 'name', unit)}' is not an FMI 2.0/3.0 co-simulation instance")


def _address(function: Any) -> int:
    return ctypes.cast(function, ctypes.c_void_p).value or 0


class NativeFixedStep(FixedStep):
    """A fixed-step algorithm (``base``: gauss-seidel, jacobi or jacobi-delayed) whose steps run in C.

    ``bind`` raises ValueError for a view it cannot step (a unit that is no FMI co-simulation instance, a link
    of another type, loops or direct feed-through under Jacobi); the system check refuses those before.
    """

    name = "native"
    batchable = False

    def __init__(self, experiment: Any = None, base: str = "gauss-seidel"):
        super().__init__(experiment)
        if base not in _ALGORITHMS:
            raise ValueError(f"the native kernel steps {', '.join(_ALGORITHMS)}, not '{base}'")
        self.base = base
        self._run = lib.run_function()

    # binding ----------------------------------------------------------------------------------------

    def bind(self, view: SystemView) -> None:
        self.view = view
        self._units = [view.units[n] for n in view.order]
        self._index = {n: i for i, n in enumerate(view.order)}
        self._keep: list[Any] = []  # every ctypes array the kernel points into
        units = (lib.KUnit * len(self._units))()
        for i, unit in enumerate(self._units):
            self._describe_unit(units[i], unit)
        jacobi = self.base != "gauss-seidel"
        if self.base == "gauss-seidel" and view.coupling.loops:
            raise ValueError("the native kernel does not solve algebraic loops")
        if self.base == "jacobi" and view.coupling.direct:
            raise ValueError("the native kernel does not propagate direct feed-through under jacobi")
        transfers: list[lib.KTransfer] = []
        plan_start, plan = [0], list[int]()
        if jacobi:
            transfers = self._transfers(view.links)
        else:
            for name in view.order:
                mine = self._transfers([c for c in view.links if c.target.unit == name])
                plan.extend(range(len(transfers), len(transfers) + len(mine)))
                transfers.extend(mine)
                plan_start.append(len(plan))
        kernel = lib.Kernel()
        kernel.n_units, kernel.units, kernel.jacobi = len(self._units), units, int(jacobi)
        kernel.n_transfers = len(transfers)
        kernel.transfers = (lib.KTransfer * max(len(transfers), 1))(*transfers)
        kernel.plan_start = (ctypes.c_int * len(plan_start))(*plan_start) if not jacobi else None
        kernel.plan = (ctypes.c_int * max(len(plan), 1))(*plan)
        kernel.stop_column = -1
        grid = self.grid
        if grid is not None:
            kernel.start, kernel.stop, kernel.step, kernel.grid_steps = grid.start, grid.stop, grid.step, grid.steps
        self._keep += [units, kernel.transfers, kernel.plan_start, kernel.plan]
        self._kernel = kernel

    def _describe_unit(self, into: Any, unit: Any) -> None:
        from cosim.units.fmu.fmpy_internals import library

        version = _version(unit)
        dll = library(unit._slave)
        into.version = version
        component = unit._component
        into.component = getattr(component, "value", component)
        prefix = f"fmi{version}"
        into.do_step = _address(getattr(dll, f"{prefix}DoStep"))
        for i, kind in enumerate(_CALL_TYPES[version]):
            into.get[i] = _address(getattr(dll, f"{prefix}Get{kind}"))
            into.set[i] = _address(getattr(dll, f"{prefix}Set{kind}"))
        if version == 3:
            into.event, into.terminate = ctypes.addressof(unit._event), ctypes.addressof(unit._terminate)
            into.early, into.last_time = ctypes.addressof(unit._early), ctypes.addressof(unit._last_time)

    def _port(self, unit_name: str, refs: Sequence[ElementRef]) -> tuple[lib.KPort, list[str]]:
        unit = self.view.units[unit_name]
        elements = [unit.elements[r.variable][r.offset] for r in refs]
        for e in elements:
            if e.size != 1 or e.fmi_type not in TYPE_CODES:
                raise ValueError(f"'{unit_name}.{e.name if hasattr(e, 'name') else ''}' is a {e.fmi_type} "
                                 f"of {e.size} values: the native kernel carries Real, Integer and Boolean scalars")
        vrs = (ctypes.c_uint * len(elements))(*[e.value_reference for e in elements])
        self._keep.append(vrs)
        port = lib.KPort(self._index[unit_name], TYPE_CODES[elements[0].fmi_type], len(elements), vrs)
        return port, [e.fmi_type for e in elements]

    def _transfers(self, links: Sequence[Any]) -> list[lib.KTransfer]:
        """One transfer per (source unit, target unit, type), in the order Python's group_transfers meets them;
        a group converts (factor * x + offset) all of its elements when any of its links has a conversion."""
        groups: dict[tuple[str, str], list[Any]] = {}
        for c in links:
            groups.setdefault((c.source.unit, c.target.unit), []).append(c)
        out = []
        for (source, target), group in groups.items():
            convert = any((c.factor, c.offset) != (1.0, 0.0) for c in group)
            by_type: dict[int, list[tuple[ElementRef, ElementRef, float, float]]] = {}
            for c in group:
                for s, t in zip(c.source.refs, c.target.refs):
                    e = self.view.units[source].elements[s.variable][s.offset]
                    by_type.setdefault(TYPE_CODES.get(e.fmi_type, -1), []).append((s, t, c.factor, c.offset))
            for code, items in by_type.items():
                if convert and code != 0:
                    raise ValueError("a factor or offset on a link that is not Real")
                sport, _ = self._port(source, [s for s, _, _, _ in items])
                tport, _ = self._port(target, [t for _, t, _, _ in items])
                if sport.type != tport.type:
                    raise ValueError(f"a link from {source} to {target} changes the value's type")
                factor = (ctypes.c_double * len(items))(*[f for _, _, f, _ in items])
                offset = (ctypes.c_double * len(items))(*[o for _, _, _, o in items])
                self._keep += [factor, offset]
                out.append(lib.KTransfer(sport, tport, int(convert), factor, offset))
        return out

    # stepping ---------------------------------------------------------------------------------------

    def advance(self, t: float) -> float:
        if self.grid is None:
            raise ValueError("the native algorithm was made without an experiment: it has no steps to advance")
        steps, t_out, fail = ctypes.c_long(), ctypes.c_double(), lib.KFail()
        outcome = self._run(ctypes.byref(self._kernel), t, self.grid.stop, 1, None, None, ctypes.byref(steps),
                            ctypes.byref(t_out), ctypes.byref(fail))
        self._after(outcome, fail, t if outcome in (lib.RUN_FAILED, lib.RUN_ENDED) else t_out.value)
        return t_out.value

    def run(self, t: float, t_end: float, probes: Sequence[tuple[str, Sequence[ElementRef], Sequence[int]]],
            n_columns: int, stop_column: int = -1) -> KernelRun:
        """Every step from ``t`` while ``t < t_end``, the probe recorded at ``t`` and after each step:
        ``probes`` is (unit, element refs, their columns) per unit; the run stops after the first step whose
        ``stop_column`` (-1: none) is non-zero.  A unit's failure is returned (``error``/``ended``), not raised."""
        kernel = self._kernel
        table, keep = [], []
        for name, refs, columns in probes:
            by_type: dict[int, tuple[list[ElementRef], list[int]]] = {}
            for ref, column in zip(refs, columns):
                e = self.view.units[name].elements[ref.variable][ref.offset]
                by_type.setdefault(TYPE_CODES.get(e.fmi_type, -1), ([], []))
                by_type[TYPE_CODES.get(e.fmi_type, -1)][0].append(ref)
                by_type[TYPE_CODES.get(e.fmi_type, -1)][1].append(column)
            for code, (rs, cs) in by_type.items():
                port, _ = self._port(name, rs)
                where = (ctypes.c_int * len(cs))(*cs)
                keep.append(where)
                table.append(lib.KProbe(port, where))
        kernel.n_probes, kernel.probes = len(table), (lib.KProbe * max(len(table), 1))(*table)
        kernel.n_columns, kernel.stop_column = n_columns, stop_column
        if self.grid is None:
            raise ValueError("the native algorithm was made without an experiment: it has no steps to run")
        capacity = self.grid.steps - self.grid.index(t) + 1
        values = np.empty((capacity, n_columns))
        times = np.empty(capacity)
        steps, t_out, fail = ctypes.c_long(), ctypes.c_double(), lib.KFail()
        outcome = self._run(ctypes.byref(kernel), t, t_end, capacity - 1, values.ctypes.data, times.ctypes.data,
                            ctypes.byref(steps), ctypes.byref(t_out), ctypes.byref(fail))
        kernel.n_probes, kernel.stop_column = 0, -1
        n = steps.value + 1
        result = KernelRun(times[:n], values[:n], steps.value, t_out.value, stopped=outcome == lib.RUN_STOPPED)
        try:
            self._after(outcome, fail, t_out.value)
        except SimulationEnded as ended:
            result.ended = ended
        except UnitError as error:
            result.error = error
        return result

    def _after(self, outcome: int, fail: Any, t: float) -> None:
        """Every unit's values may have changed (no cached read may be handed out again), and the failure of a
        step raised as the Python master raises it."""
        for unit in self._units:
            unit.generation += 1
            unit.time = fail.t if outcome in (lib.RUN_FAILED, lib.RUN_ENDED) else t - fail.h
        if outcome == -1:
            raise MemoryError("the native kernel could not allocate its buffers")
        if outcome == lib.RUN_ENDED:
            self._units[fail.unit]._ended_or_returned_early(fail.t, fail.h)
        if outcome != lib.RUN_FAILED:
            return
        unit = self._units[fail.unit]
        version = _version(unit)
        if fail.call == 0:
            if version == 2:
                unit.step_outcome(fail.status)
            raise unit.fail_status(f"fmi{version}DoStep", fail.status)
        verb = "Get" if fail.call == 1 else "Set"
        raise unit.fail_status(f"fmi{version}{verb}{_CALL_TYPES[version][fail.type]}", fail.status)

