"""Several design points of one system in lock-step: one stepping loop for K points.

A point of the pick-and-place study costs a few microseconds of physics per
communication step but tens of microseconds of Python calls (units, transfers,
probes, observers).  Run K points side by side and most of that is paid once
per step for all K: a unit with a vectorised twin
(:mod:`cosim.units.python.batch`) advances every point with one call,
any other unit is K ordinary instances called in a tight loop
(:class:`InstanceBatch`: FMUs, Python units without a twin).

The semantics are those of K separate runs (:class:`~cosim.execution.run.Execution`):
every point's units see the same communication points, in the same order of
the master algorithm, with the same initialization; the master algorithm is
the very object a single run uses (:mod:`cosim.master.algorithms`), bound to
the batches instead of units (each batch steps with ``do_step(t, h)`` like a
unit) and given transfers that move all K rows at once; a point that reaches its
``stop_when`` is no longer stepped (its FMU instances) or read (its rows of a
twin); its objectives are reduced from its own samples with the same
reducer.  The results are those of the single runs bit for bit
(``tests/execution/test_lockstep.py``), except where a twin states a tolerance: the
Exudyn arm's twin (``models.panda_exudyn.PandaExudynBatch``) integrates its K
arms in one Exudyn system whose Newton iteration sees all K residuals, so its
rows agree with single runs to the solver's Newton tolerance (bounds and test:
``tests/models/test_panda_exudyn_lockstep.py``), and a row may move within that
tolerance with its group's other points.

Anything unusual makes the points run one by one instead, so a point's row
never depends on its neighbours (beyond such a stated tolerance): a unit error, an exception, a unit ending the
simulation, a twin refusing the rows (:class:`~cosim.units.python.batch.NotBatchable`).
Lock-step is used only where it pays and cannot change a result: no traces
recorded, only numeric probes, Real connections, no algebraic loops, a master
algorithm that can step batches (``batchable``), and at least one unit with
a twin.  Outputs that no objective needs before a point's end (only
``final`` reductions) are read at that point's last sample only, and outputs
no objective needs are not read (:func:`_probe_plan` says when that holds
for a Python unit).
"""

from __future__ import annotations

import math
import time
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np

from cosim.errors import KernelUnavailable
from cosim.execution.lockstep_prune import GroupBound
from cosim.execution.lockstep_reduce import reduce_group
from cosim.execution.observers import reduction_of
from cosim.execution.point_row import PointRow
from cosim.execution.prune import PRUNED, PruneOrder, prune_columns
from cosim.execution.result import FAILED, OK, UNIT_FAILURE, RunResult
from cosim.master.contract import MasterAlgorithm, SystemView
from cosim.master.native.rows import NativeRows
from cosim.master.observers import ObjectiveReducer, flatten_objectives
from cosim.master.registry import ALGORITHMS, make_algorithm
from cosim.master.transfers import Link
from cosim.spec.expressions import evaluate_expressions
from cosim.system.builder import System
from cosim.system.parts import Assignment
from cosim.units.fmu.instance import FmiInstance
from cosim.units.protocol import NUMERIC_TYPES, Selection, Unit
from cosim.units.python.batch import NotBatchable, batch_class_of
from cosim.units.python.unit import PythonUnitType
from cosim.util.limits import limit

GROUP_SIZE = 32  # points per lock-step group at most: enough to share the per-step cost
# A group's rows come together when it ends, so a group is made to last about COSIM_LOCKSTEP_SECONDS
# (cosim.util.limits; 0.25 s by default), from the time of a point run alone.


class InstanceBatch:
    """K live instances of one unit, driven like a vectorised twin (``get`` gives a (K, n) array).

    Only the rows in ``active`` are set, stepped and read during the run, so
    a point that has ended sees no further step.  Errors are not wrapped per
    instance: any exception makes the caller run the points one by one, where
    each gets its own message.  FMI 2.0/3.0 co-simulation instances are set
    (plain Real inputs) and stepped by C loops over the rows
    (:class:`~cosim.master.native.rows.NativeRows`, the same FMI calls in the
    same order) unless ``native`` is False or the kernel's library cannot be
    built here; then, and for any other unit, each instance is called from Python.
    """

    def __init__(self, units: Sequence[Unit], native: bool = True):
        self.units = list(units)
        self.name = self.units[0].name
        self.description = self.units[0].description
        self.rows = len(self.units)
        self.native = _native_rows(self.units) if native else None
        self.active = np.arange(self.rows)
        self._steps = [unit.do_step for unit in self.units]

    @property
    def active(self) -> np.ndarray:
        """The rows still running (their indices)."""
        return self._active

    @active.setter
    def active(self, rows: np.ndarray) -> None:
        self._active, self._active_list = rows, rows.tolist()  # the list is what the loops below walk
        self._active_c = np.ascontiguousarray(rows, dtype=np.int64)  # and this what the C loops walk
        self._active_at = self._active_c.ctypes.data

    def _sync(self) -> None:
        if self.native is not None:
            self.native.sync()

    def select(self, refs: Sequence[Any]) -> tuple[list[Selection], list[Any], list[Any], Any]:
        selections = [unit.select(refs) for unit in self.units]
        # bound once: the unit's fastest reader (an FMU's is a view of its buffer) and its set
        readers = [unit.reader(s) for unit, s in zip(self.units, selections)]
        setters = [unit.writer(s) for unit, s in zip(self.units, selections)]
        plan = self.native.inputs(selections) if self.native is not None else None  # None: set from Python
        return selections, readers, setters, plan

    def get(self, selection: tuple[list[Selection], list[Any], list[Any], Any]) -> np.ndarray:
        plan = selection[3]
        out = np.zeros((self.rows, len(selection[0][0])))
        if plan is not None and self.native is not None and plan.n_values == out.shape[1]:
            self.native.get(plan, len(self._active_c), self._active_at, out)  # the same FMI gets, a C loop
            return out
        self._sync()
        readers = selection[1]
        for k in self._active_list:
            out[k] = readers[k]()
        return out

    def get_rows(self, selection: tuple[list[Selection], list[Any], list[Any], Any], rows: list[int]) -> np.ndarray:
        self._sync()
        readers = selection[1]
        return np.array([readers[k]() for k in rows], dtype=float).reshape(len(rows), len(selection[0][0]))

    def set(self, selection: tuple[list[Selection], list[Any], list[Any], Any], values: np.ndarray) -> None:
        plan = selection[3]
        if plan is not None and self.native is not None:
            self.native.set(plan, len(self._active_c), self._active_at, np.ascontiguousarray(values, dtype=np.float64))
            return
        self._sync()
        setters = selection[2]
        for k in self._active_list:
            setters[k](values[k])

    def set_row(self, selection: tuple[list[Selection], list[Any], list[Any], Any], row: int,
                values: Sequence[Any]) -> None:
        self._sync()
        self.units[row].set(selection[0][row], list(values))

    def setup(self, start_time: float, stop_time: float | None) -> None:
        self._sync()
        for unit in self.units:
            unit.setup(start_time, stop_time)

    def enter_initialization(self) -> None:
        self._sync()
        for unit in self.units:
            unit.enter_initialization()

    def exit_initialization(self) -> None:
        self._sync()
        for unit in self.units:
            unit.exit_initialization()

    def do_step(self, t: float, h: float) -> None:
        """Step the active instances from ``t`` to ``t + h`` (what a master algorithm calls, as on a unit)."""
        if self.native is not None:
            self.native.do_step(len(self._active_c), self._active_at, t, h)
            return
        steps = self._steps
        for k in self._active_list:
            steps[k](t, h)

    def reset(self) -> None:
        self._sync()
        for unit in self.units:
            unit.reset()
        self.active = np.arange(self.rows)

    def terminate(self) -> None:
        self._sync()
        for unit in self.units:
            try:
                unit.terminate()
            except Exception:
                pass  # terminating every instance matters more than one instance's complaint


def _native_rows(units: Sequence[Unit]) -> Any:
    """C loops over these FMU instances (:class:`~cosim.master.native.rows.NativeRows`), or None where they
    do not apply (not FMI co-simulation instances) or the kernel's library cannot be built or loaded here."""
    try:
        return NativeRows(units)
    except (ValueError, KernelUnavailable, OSError):
        return None


def has_twin(system: System) -> bool:
    """Whether some unit of ``system`` is a Python unit with a vectorised twin."""
    for system_unit in system.units.values():
        unit_type = system_unit.unit_type
        if isinstance(unit_type, PythonUnitType) and batch_class_of(unit_type.load_class()) is not None:
            return True
    return False


def can_run_in_lockstep(system: System) -> bool:
    """Whether points of ``system`` may run in lock-step (module docstring): a twin, a batchable master
    algorithm, no loops, no warm start, Real connections, numeric probes."""
    # algebraic loops are solved point by point; a group of model-exchange units steps as one
    if not has_twin(system) or system.coupling.loops or system.model_exchange.groups:
        return False
    if system.spec.experiment.warm_start is not None:
        return False  # each point starts from the saved warm-up (cosim.execution.warm_start), one by one

    if not getattr(ALGORITHMS.get(system.spec.experiment.algorithm), "batchable", False):
        return False  # e.g. adaptive: its steps differ from point to point, no common grid to step together
    # connections carry Real values only (batches hand values on as float arrays; an Integer or Boolean
    # input keeps its exact type on the one-by-one path)
    if any(c.target.variable.type != "Real" or c.source.variable.type != "Real" for c in system.connections):
        return False
    return all(s.variable.type in NUMERIC_TYPES and s.variable.fmi_type not in ("Int64", "UInt64")
               for s in system.probes)


class Batches(dict[str, Any]):
    """Unit name -> live batch (a twin or an :class:`InstanceBatch`), with the wiring between them built
    once (transfers, probe, selections): the batches are reused group after group."""

    wiring: "_Wiring | None" = None


def instantiate(system: System, rows: int) -> Batches:
    """One batch per unit of ``system`` for ``rows`` points: its twin, or ``rows`` instances (FMU instances
    called by C loops unless the spec's ``experiment.kernel`` is ``python``)."""
    native = system.spec.experiment.kernel != "python"
    batches = Batches()
    try:
        for name, system_unit in system.units.items():
            unit_type = system_unit.unit_type
            twin = batch_class_of(unit_type.load_class()) if isinstance(unit_type, PythonUnitType) else None
            if twin is not None and isinstance(unit_type, PythonUnitType):  # twin implies a Python unit
                batches[name] = twin(unit_type.load_class(), name, rows)
            else:
                batches[name] = InstanceBatch([unit_type.instantiate(name) for _ in range(rows)], native)
    except BaseException:
        terminate(batches)
        raise
    return batches


def terminate(batches: Mapping[str, Any]) -> None:
    for batch in batches.values():
        try:
            batch.terminate()
        except Exception:
            pass


class _Transfer:
    """Output elements of one batch to input elements of another, all rows at once (factor and offset applied);
    a master algorithm runs it as it runs a :class:`~cosim.master.transfers.Transfer` between units."""

    def __init__(self, source: Any, target: Any, connections: Sequence[Link]):
        self.source, self.target = source, target
        self.source_selection = source.select([r for c in connections for r in c.source.refs])
        self.target_selection = target.select([r for c in connections for r in c.target.refs])
        self.factor = self.offset = None
        if any((c.factor, c.offset) != (1.0, 0.0) for c in connections):
            self.factor = np.array([c.factor for c in connections for _ in c.source.refs])
            self.offset = np.array([c.offset for c in connections for _ in c.source.refs])

    def read(self) -> np.ndarray:
        values = self.source.get(self.source_selection)
        converted: np.ndarray = values if self.factor is None else values * self.factor + self.offset
        return converted

    def write(self, values: np.ndarray) -> None:
        self.target.set(self.target_selection, values)

    def run(self) -> None:
        self.write(self.read())


def _transfers(batches: Mapping[str, Any], connections: Sequence[Link]) -> list[_Transfer]:
    """One _Transfer per (source, target) batch pair, in the order first seen: the lock-step
    :data:`~cosim.master.transfers.TransferFactory`, as :func:`~cosim.master.transfers.group_transfers` for units."""
    groups: dict[tuple[str, str], list[Link]] = {}
    for c in connections:
        groups.setdefault((c.source.unit, c.target.unit), []).append(c)
    return [_Transfer(batches[s], batches[t], cs) for (s, t), cs in groups.items()]


class _BatchProbe:
    """Probed scalars of every row: ``read()`` gives a (K, columns) array in :class:`Probe`'s column order.

    ``columns`` are all probe columns; only those in ``keep`` are read (the others stay 0).
    """

    def __init__(self, system: System, batches: Mapping[str, Any], columns: Sequence[str], keep: set[str]):
        index = {c: i for i, c in enumerate(columns)}
        per_unit: dict[str, tuple[list[Any], list[int]]] = {}
        for signal in system.probes:
            for ref, column in zip(signal.refs, signal.columns):
                refs, where = per_unit.setdefault(signal.unit, ([], []))
                if column in index and column in keep and index[column] not in where:
                    refs.append(ref)
                    where.append(index[column])
        self._reads = [(batches[name], batches[name].select(refs), np.array(where))
                       for name, (refs, where) in per_unit.items() if refs]
        self.width = len(columns)

    def read(self, rows: int) -> np.ndarray:
        values = np.zeros((rows, self.width))
        for batch, selection, where in self._reads:
            values[:, where] = batch.get(selection)
        return values

    def fill(self, values: np.ndarray, rows: np.ndarray) -> None:
        """Read this probe's columns of ``rows`` only, into ``values`` (a sample already taken)."""
        for batch, selection, where in self._reads:
            values[np.ix_(rows, where)] = batch.get_rows(selection, rows.tolist())


def _probe_plan(system: System, batches: Mapping[str, Any], columns: Sequence[str],
                every_too: frozenset[str] = frozenset()) -> tuple[set[str], set[str]]:
    """The columns read at every communication point and those read at each point's end only.

    Every sample is kept for a column that ``stop_when`` or an objective other than ``final`` (or
    ``initial``: the first sample is read whole) reduces; a column only reduced by ``final`` needs no sample
    but a point's last, and a column nothing reduces needs none.  An FMU's get has no side effect, so its
    other columns are read at a point's end only (unused ones never).  A Python unit's get may compute its
    outputs, so a Python unit with no column needed every step keeps all its columns every step; one with
    such a column is still read at every step (the same computations at the same times), and its other
    columns are read at a point's end (``final``) or never (unused).
    """
    every = {system.spec.experiment.stop_when} if system.spec.experiment.stop_when else set()
    every |= every_too  # e.g. what a pruned group's bounds reduce while it runs (cosim.execution.lockstep_prune)
    final: set[str] = set()
    for o in system.spec.objectives:
        if o.signal:
            (final if o.reduce in ("final", "initial") else every).update(_columns_of(system, o.signal))
    keep_every: set[str] = set()
    end_only: set[str] = set()
    for name in batches:
        mine = [c for s in system.probes if s.unit == name for c in s.columns if c in columns]
        if not any(c in every for c in mine) and not _is_fmu(batches[name]):
            keep_every.update(mine)  # nothing of it is needed every step: read it all, every step, as before
            continue
        keep_every.update(c for c in mine if c in every)
        end_only.update(c for c in mine if c in final and c not in every)
    return keep_every, end_only


def _is_fmu(batch: Any) -> bool:
    return isinstance(batch, InstanceBatch) and isinstance(batch.units[0], FmiInstance)


def run_lockstep(system: System, points: Sequence[Sequence[Assignment]], batches: Mapping[str, Any],
                 prune: PruneOrder | None = None) -> list[RunResult]:
    """Run ``points`` (each its override assignments) in lock-step on ``batches`` (from :func:`instantiate`,
    fresh or reset, with at least as many rows as points); one RunResult per point, in order.

    ``prune`` (a :class:`~cosim.execution.prune.PruneOrder`): rows proven off its front leave the group
    (:mod:`cosim.execution.lockstep_prune`) with status ``pruned``, their bound vector as objectives and
    the single run's message; the other rows are what they are without it, bit for bit.

    Raises NotBatchable, UnitError, SimulationEnded or any other exception of
    a unit: the caller then runs the points one by one (:class:`LockstepRunner`),
    after resetting or re-instantiating the batches.
    """
    started = time.perf_counter()
    rows = next(iter(batches.values())).rows
    n = len(points)
    if not 0 < n <= rows:
        raise ValueError(f"{n} points for batches of {rows} rows")
    wiring = batches.wiring if isinstance(batches, Batches) else None
    every_too = frozenset(prune_columns(system, prune.settings)) if prune is not None else frozenset()
    if wiring is None or wiring.system is not system or wiring.every_too != every_too:
        wiring = _Wiring(system, batches, every_too)
        if isinstance(batches, Batches):
            batches.wiring = wiring
    padded = list(points) + [points[0]] * (rows - n)  # spare rows copy the first point; never read
    wiring.initialize(padded)
    bound = GroupBound(system, prune, wiring.columns, n) if prune is not None else None
    times, samples, ends = _advance_together(system, wiring, batches, n, bound)
    data = np.stack(samples)  # (samples, rows, columns)
    t_all = np.array(times)
    elapsed = (time.perf_counter() - started) / n
    results = []
    reducer = wiring.reducer  # one reducer: the whole group's reductions at once, or each point's in turn
    reduced = reduce_group(reducer, t_all, data, ends)
    for i in range(n):
        if reduced is None:
            reducer.load(t_all[:ends[i] + 1], data[:ends[i] + 1, i, :])
        values = reducer.results() if reduced is None else reduced[i]
        flat = flatten_objectives(evaluate_expressions(system.spec.objectives, values))
        nan = [name for name, v in flat.items() if not math.isfinite(v)]
        end_time = float(t_all[ends[i]])
        verdict = bound.verdicts.get(i) if bound is not None else None
        if verdict is not None:  # as a single run's stop condition gives it (cosim.execution.run)
            results.append(RunResult(PRUNED, verdict.reason or "", verdict.objectives_at_stop(flat), None, elapsed,
                                     int(ends[i]), end_time))
        elif nan:
            results.append(RunResult(FAILED, f"objective(s) not finite: {', '.join(nan)}", flat, None, elapsed,
                                     int(ends[i]), end_time, failure=UNIT_FAILURE))
        else:
            results.append(RunResult(OK, "", flat, None, elapsed, int(ends[i]), end_time))
    return results


def _advance_together(system: System, wiring: "_Wiring", batches: Mapping[str, Any], n: int,
                      bound: GroupBound | None = None) -> tuple[list[float], list[np.ndarray], np.ndarray]:
    """Advance the batches' first ``n`` rows to the stop time with the bound algorithm, each row until its
    ``stop_when`` holds (or ``bound`` prunes it); returns the sample times, the samples (rows, columns) at
    each, and per row the index of its last sample."""
    exp = system.spec.experiment
    rows = next(iter(batches.values())).rows
    columns, probe, end_probe = wiring.columns, wiring.probe, wiring.end_probe
    stop_column = columns.index(exp.stop_when) if exp.stop_when else None
    wiring.algorithm.start(exp.start)  # as Execution does (no loops here: nothing to solve)
    advance = wiring.algorithm.advance
    samples = [probe.read(rows)]
    end_probe.fill(samples[0], np.arange(rows))
    if bound is not None:
        bound.start(exp.start, samples[0])
    times = [exp.start]
    active = np.arange(n)
    ends = np.full(n, -1)  # per point: the index of its last sample
    _set_active(batches, active)
    t = exp.start
    while t < exp.stop:
        t = advance(t)
        values = probe.read(rows)
        samples.append(values)
        times.append(t)
        done = values[active, stop_column] != 0 if stop_column is not None else np.zeros(len(active), bool)
        if bound is not None:  # rows proven off the front end here too (a stop_when at this sample wins)
            pruned = bound.step(t, values, active[~done])
            if len(pruned):
                done |= np.isin(active, pruned)
        if done.any():
            ends[active[done]] = len(samples) - 1
            end_probe.fill(values, active[done])  # their last sample: now the end-only columns too
            active = active[~done]
            if not len(active):
                break
            _set_active(batches, active)
    if len(active) and ends[active[0]] < 0:  # still running at the stop time: the last sample is theirs
        end_probe.fill(samples[-1], active)
    ends[ends < 0] = len(samples) - 1
    return times, samples, ends


def probe_columns(system: System) -> list[str]:
    """The numeric columns :class:`~cosim.execution.run.Probe` reads, in its order."""
    columns: list[str] = []
    for signal in system.probes:
        if signal.variable.type in NUMERIC_TYPES:
            columns.extend(c for c in signal.columns if c not in columns)
    return columns


def _columns_of(system: System, signal: str | None) -> list[str]:
    for s in system.probes:
        if s.text == signal:
            return list(s.columns)
    raise KeyError(signal)


def _set_active(batches: Mapping[str, Any], active: np.ndarray) -> None:
    for batch in batches.values():
        batch.active = active


class _Wiring:
    """What connects the batches of one system, built once: transfers, the probe, selections, the master
    algorithm bound to the batches."""

    def __init__(self, system: System, batches: Mapping[str, Any], every_too: frozenset[str] = frozenset()):
        """``every_too``: probe columns read at every communication point whatever the objectives need."""
        self.system, self.batches, self.every_too = system, batches, every_too
        into: dict[str, list[Any]] = {}
        for connection in system.init_order:
            into.setdefault(connection.target.unit, []).append(connection)
        self.into = [(batches[name], _transfers(batches, into.get(name, []))) for name in system.order]
        self.after_init = _transfers(batches, system.init_order)
        self.columns = probe_columns(system)
        every, end_only = _probe_plan(system, batches, self.columns, every_too)
        self.probe = _BatchProbe(system, batches, self.columns, every)
        self.end_probe = _BatchProbe(system, batches, self.columns, end_only)
        self.algorithm = _bind_algorithm(system, batches)
        self.reducer = ObjectiveReducer(self.columns, [(o.name, reduction_of(o), _columns_of(system, o.signal))
                                                       for o in system.spec.objectives if o.signal])
        self._selections: dict[tuple[str, tuple[Any, ...]], Any] = {}
        self._spec_values: list[tuple[Any, Any, list[Any]]] | None = None

    def _resolved(self, assignment: Assignment) -> tuple[Any, Any, list[Any]]:
        """The batch, the selection (made once per unit and elements) and the values of ``assignment``."""
        batch = self.batches[assignment.unit]
        key = (assignment.unit, assignment.refs)
        if key not in self._selections:
            self._selections[key] = batch.select(assignment.refs)
        return batch, self._selections[key], list(assignment.values)

    def initialize(self, points: Sequence[Sequence[Assignment]]) -> None:
        """As :meth:`Execution._initialize`, for every row: the spec's assignments, then each point's overrides."""
        system, batches = self.system, self.batches
        exp = system.spec.experiment
        for batch in batches.values():
            batch.setup(exp.start, exp.stop)
        if self._spec_values is None:  # the spec's own assignments are the same for every row and group
            self._spec_values = [self._resolved(a) for a in system.assignments]
        for row, overrides in enumerate(points):
            for batch, selection, values in self._spec_values:
                batch.set_row(selection, row, values)
            for assignment in overrides:
                batch, selection, values = self._resolved(assignment)
                batch.set_row(selection, row, values)
        for batch in batches.values():
            batch.enter_initialization()
        # units leave initialization in stepping order, each after receiving its sources' initial outputs
        for batch, transfers in self.into:
            for transfer in transfers:
                transfer.run()
            batch.exit_initialization()
        for transfer in self.after_init:
            transfer.run()


def _bind_algorithm(system: System, batches: Mapping[str, Any]) -> MasterAlgorithm:
    """The spec's master algorithm (the class a single run uses) bound to ``batches``: it steps each batch
    with ``do_step`` and moves values with transfers of all rows (:func:`_transfers`).

    Raises NotBatchable for an algorithm that is not ``batchable`` (its points then run one by one).
    """
    algorithm = make_algorithm(system.spec.experiment.algorithm, system.spec.experiment)
    if not algorithm.batchable:
        raise NotBatchable(f"no lock-step version of the master algorithm '{algorithm.name}'")
    # no loops here (can_run_in_lockstep): the coupling only orders the direct feed-through under Jacobi
    algorithm.bind(SystemView(batches, system.order, system.connections, system.coupling, transfers=_transfers))
    return algorithm


class LockstepRunner:
    """A sweep child's points in lock-step groups where that is possible, else one by one.

    Wraps the child's :class:`~cosim.parallel.isolation.point_runner.PointRunner` and gives
    the same rows (:class:`~cosim.execution.point_row.PointRow`).  The
    first two points run alone, which times a point; then groups of up to
    GROUP_SIZE points, as many as take about COSIM_LOCKSTEP_SECONDS, run in lock-step; if the system does not
    qualify (:func:`can_run_in_lockstep`) or anything in the group goes wrong,
    the group's points run one by one through the PointRunner, so every row is
    that of a single run.  A row's ``run_time`` is its group's time divided
    by the group's size.
    """

    def __init__(self, single: Any):
        self.single = single
        self.system = single.system
        self.enabled = can_run_in_lockstep(self.system)
        self.group_size: int | None = None if self.enabled else 1
        self._single_times: list[float] = []
        self._batches: dict[int, dict[str, Any]] = {}  # rows -> live batches, reused between groups
        self._announce: Callable[[int], None] | None = None

    def rows(self, points: Sequence[tuple[str, dict[str, Any]]],
             announce: Callable[[int], None] | None = None, prune: PruneOrder | None = None) -> Iterator[PointRow]:
        """One row per point, in order (a generator: a group's rows come when the group is done).

        ``announce(n)`` is called before a lock-step group of n points starts: the sweep's parent
        then knows that a crash or hang in the next n rows is not the first point's own (it runs
        those points again one by one, cosim.parallel.isolation).  ``prune`` (a
        :class:`~cosim.execution.prune.PruneOrder`): every point compares its bound with that front, a
        point alone as in :meth:`PointRunner.run`, a group's rows inside the group (:func:`run_lockstep`).
        """
        self._announce = announce
        points = list(points)
        while points and self.enabled and self.group_size is None:  # first measure a point run alone
            row = self._alone(*points.pop(0), prune)
            if row.ok or row.status == PRUNED:  # a pruned run is shorter: a larger group, at most GROUP_SIZE
                self._single_times.append(row.run_time)
            if len(self._single_times) == 2:  # the first run also instantiated the units: take the faster
                seconds = limit("lockstep_seconds")
                self.group_size = max(1, min(GROUP_SIZE, int(seconds / max(min(self._single_times), 1e-6))))
            yield row
        size = self.group_size or 1
        if size < 2:
            for point_id, values in points:
                yield self._alone(point_id, values, prune)
            return
        for first in range(0, len(points), size):
            group = points[first:first + size]
            if len(group) < 2:
                yield self._alone(*group[0], prune)
            else:
                yield from self._group(group, prune)

    def _group(self, group: Sequence[tuple[str, dict[str, Any]]], prune: PruneOrder | None) -> Iterator[PointRow]:
        from cosim.execution.point import assignments_for

        results = None
        overrides: list[list[Assignment]] | None
        try:
            overrides = [assignments_for(self.system, values) for _, values in group]
            batches = self._batches.pop(len(group), None) or instantiate(self.system, len(group))
        except Exception:  # a value that does not fit, a unit that cannot be instantiated: the single path reports it
            overrides = batches = None
        if batches is not None and overrides is not None:  # both made, or neither
            try:
                if self._announce is not None:
                    self._announce(len(group))
                results = run_lockstep(self.system, overrides, batches, prune)
                if all(r.ok or r.status == PRUNED for r in results):  # clean stops: the batches are reused
                    for batch in batches.values():
                        batch.reset()
                    self._keep(len(group), batches)
                else:
                    terminate(batches)  # after a failed point trust no state, as PointRunner does
            except Exception:
                terminate(batches)
                results = None
        if results is None:
            for point_id, values in group:
                yield self._alone(point_id, values, prune)
            return
        for (point_id, _), result in zip(group, results):
            yield PointRow.of(point_id, result, result.elapsed)

    def _alone(self, point_id: str, values: dict[str, Any], prune: PruneOrder | None) -> PointRow:
        """The point run alone by the PointRunner (with the front it prunes against, if any)."""
        row: PointRow = self.single.run(point_id, values) if prune is None else \
            self.single.run(point_id, values, prune=prune)
        return row

    def _keep(self, rows: int, batches: dict[str, Any]) -> None:
        self._batches[rows] = batches
        while len(self._batches) > 2:  # a full group size and the last, smaller group of a batch
            terminate(self._batches.pop(next(iter(self._batches))))

    def close(self) -> None:
        for batches in self._batches.values():
            terminate(batches)
        self._batches.clear()
