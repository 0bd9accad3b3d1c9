""":class:`NativeFixedStep`: Gauss-Seidel, Jacobi or jacobi-delayed stepped by the C kernel (kernel.c).

It implements the master contract (``advance`` takes one step in C), and :meth:`NativeFixedStep.run` takes
every step of a run in one call, recording the probed columns into a preallocated array that the run hands to
its observers in bulk (``Observer.load``).  It steps FMI 2.0 / 3.0 co-simulation instances, players (their
tables, played by kernel.c as PlayerUnit plays them) and system connectors (values kernel.c holds, written back
to the unit after a run), whose links and probes are Real, Integer or Boolean, scalars or FMI 3.0 arrays
(:func:`cosim.system.kernel_choice.kernel_choice` decides which systems qualify); the values are the Python
master's bit for bit.
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


_VERSIONS: dict[type, int] = {}  # unit class -> its KUnit.version, found once per class


def _version(unit: Any) -> int:
    """kernel.c's KUnit.version of ``unit``: 2 or 3 (FMI co-simulation), PLAYER or STORE; raises ValueError."""
    version = _VERSIONS.get(type(unit))
    if version is not None:
        return version
    from cosim.units.connectors import SystemConnectors
    from cosim.units.fmu.fmi2 import Fmi2Unit
    from cosim.units.fmu.fmi3 import Fmi3Unit
    from cosim.units.player import PlayerUnit

    exact = {Fmi2Unit: 2, Fmi3Unit: 3, PlayerUnit: lib.PLAYER}  # exact classes: a subclass may step otherwise
    if type(unit) in exact:
        version = exact[type(unit)]
    elif isinstance(unit, SystemConnectors):
        version = lib.STORE
    else:
        raise ValueError(f"unit '{getattr(unit, 'name', unit)}' is not an FMI 2.0/3.0 co-simulation instance, a "
                         "player or system connectors")
    _VERSIONS[type(unit)] = version
    return version


def _address(function: Any) -> int:
    return ctypes.cast(function, ctypes.c_void_p).value or 0


def describe_fmu(into: Any, unit: Any) -> None:
    """Fill the kernel's ``KUnit`` ``into`` with an FMI 2.0/3.0 co-simulation instance's handle and the FMI
    functions FMPy resolved from its library (raises ValueError for any other unit)."""
    from cosim.units.fmu.fmpy_internals import library

    version = _version(unit)
    if version not in (2, 3):
        raise ValueError(f"unit '{unit.name}' is not an FMI 2.0/3.0 co-simulation instance")
    into.version = version
    dll = library(unit._slave)
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
        self._fmus = [u for u in self._units if _version(u) >= 2]
        self._index = {n: i for i, n in enumerate(view.order)}
        self._keep: list[Any] = []  # every ctypes array the kernel points into
        self._clocks: dict[str, Any] = {}  # player name -> the time the kernel keeps for it
        self._stores: dict[str, tuple[list[str], np.ndarray]] = {}  # connectors: their slots' names and values
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
        version = _version(unit)
        into.version = version
        if version == lib.PLAYER:
            return self._describe_player(into, unit)
        if version == lib.STORE:
            return self._describe_store(into, unit)
        describe_fmu(into, unit)

    def _describe_player(self, into: Any, unit: Any) -> None:
        """The player's table as kernel.c plays it; its ``current`` becomes the array the kernel writes."""
        times = np.ascontiguousarray(unit.time_points, dtype=float)
        values = np.ascontiguousarray(unit.values, dtype=float)
        discrete = np.ascontiguousarray(unit.discrete, dtype=np.uint8)
        unit.current = np.array(unit.current, dtype=float)  # the player's values at its time, kept by the kernel
        clock = ctypes.c_double(unit.t)
        into.n_samples, into.n_columns = len(times), values.shape[1]
        into.mode = lib.MODES[unit.unit_type.interpolation]
        into.times, into.values, into.discrete = times.ctypes.data, values.ctypes.data, discrete.ctypes.data
        into.current, into.time = unit.current.ctypes.data, ctypes.addressof(clock)
        self._keep += [times, values, discrete, unit.current, clock]
        self._clocks[unit.name] = clock

    def _describe_store(self, into: Any, unit: Any) -> None:
        """System connectors: one slot per numeric scalar, the kernel's ``current``; written back after a run."""
        names = [v.name for v in unit.description.variables if v.type in ("Real", "Integer", "Boolean")
                 and not v.is_array]
        held = np.array([float(getattr(unit, n)) for n in names], dtype=float)
        into.current = held.ctypes.data
        self._keep.append(held)
        self._stores[unit.name] = (names, held)

    def _element(self, unit_name: str, ref: ElementRef) -> tuple[int, int, int, int]:
        """(type code, value reference or slot, values of its call, index in them) of one element; raises
        ValueError for a type the kernel does not carry."""
        unit = self.view.units[unit_name]
        version = _version(unit)
        if version == lib.PLAYER:
            column = unit.unit_type.column_index(ref)
            return TYPE_CODES[unit.unit_type.kinds()[column]], column, 1, 0
        if version == lib.STORE:
            names, _ = self._stores[unit_name]
            if ref.variable not in names:
                raise ValueError(f"'{unit_name}.{ref.variable}' is not a number the native kernel holds")
            kind = unit.description.variable(ref.variable).type
            return TYPE_CODES[kind], names.index(ref.variable), 1, 0
        e = unit.elements[ref.variable][ref.offset]
        if e.fmi_type not in TYPE_CODES or (version == 3 and e.fmi_type == "Enumeration"):
            raise ValueError(f"'{unit_name}.{ref.variable}' is a {e.fmi_type}: the native kernel carries Real, "
                             "Integer and Boolean values (FMI 3.0: Float64, Int32, Boolean)")
        return TYPE_CODES[e.fmi_type], e.value_reference, e.size, e.index

    def _port(self, unit_name: str, refs: Sequence[ElementRef]) -> lib.KPort:
        """One call's port over ``refs`` (all of one type), laid out as FmiInstance.select lays it out: value
        references in first-seen order, an array's values all read, an array partly set read first."""
        elements = [self._element(unit_name, r) for r in refs]
        sizes: dict[int, int] = {}
        for _, vr, size, _ in elements:
            sizes.setdefault(vr, size)
        offsets, start = {}, 0
        for vr, size in sizes.items():
            offsets[vr] = start
            start += size
        positions = [offsets[vr] + index for _, vr, _, index in elements]
        covered: dict[int, set[int]] = {}
        for _, vr, _, index in elements:
            covered.setdefault(vr, set()).add(index)
        partial = any(len(covered[vr]) < size for vr, size in sizes.items())
        plain = positions == list(range(start)) and len(positions) == start
        vrs = (ctypes.c_uint * len(sizes))(*sizes)
        pos = (ctypes.c_int * len(positions))(*positions)
        self._keep += [vrs, pos]
        return lib.KPort(self._index[unit_name], elements[0][0], len(elements), vrs, len(sizes), start,
                         None if plain else pos, int(partial))

    def _type_of(self, unit_name: str, ref: ElementRef) -> int:
        return self._element(unit_name, ref)[0]

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
                    by_type.setdefault(self._type_of(source, s), []).append((s, t, c.factor, c.offset))
            for code, items in by_type.items():
                if convert and code != 0:
                    raise ValueError("a factor or offset on a link that is not Real")
                sport = self._port(source, [s for s, _, _, _ in items])
                tport = self._port(target, [t for _, t, _, _ in items])
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
                chosen = by_type.setdefault(self._type_of(name, ref), ([], []))
                chosen[0].append(ref)
                chosen[1].append(column)
            for code, (rs, cs) in by_type.items():
                port = self._port(name, rs)
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
        for unit in self._fmus:
            unit.generation += 1
            unit.time = fail.t if outcome in (lib.RUN_FAILED, lib.RUN_ENDED) else t - fail.h
        for name, clock in self._clocks.items():
            self.view.units[name].t = clock.value
        for name, (names, held) in self._stores.items():  # what the connections gave the inputs, as set() keeps it
            unit = self.view.units[name]
            for slot, variable in enumerate(names):
                if unit.description.variable(variable).causality == "input":
                    setattr(unit, variable, float(held[slot]))
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

