"""One run of one design point: the co-simulation loop.

:class:`Execution` instantiates (or reuses) the units of a
:class:`~cosim.system.builder.System`, sets parameters, initializes, steps with
the master algorithm and feeds observers.  It does no file or network I/O.
Whatever goes wrong inside a run becomes data: the returned :class:`RunResult`
carries the status and a message naming the unit, the time and the cause.
Units it created are always terminated, also after a failure.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from cosim.errors import UnitError, UserError
from cosim.execution.warm_start import WarmSamples, WarmState, refuse_unsaveable, restore_warm, warm_steps
from cosim.master.algorithms import group_transfers, make_algorithm
from cosim.master.coupled_me import integrate_together, settle_groups
from cosim.master.observers import ExactColumns, ObjectiveReducer, Observer, TraceRecorder, flatten_objectives
from cosim.spec.expressions import evaluate_expressions
from cosim.system.builder import Assignment, System
from cosim.units.protocol import NUMERIC_TYPES, SimulationEnded, Unit

OK, FAILED = "ok", "failed"
# Why a run failed, for RunResult.failure: a unit (or a non-finite objective),
# a user's file found unusable only while running, or a bug in cosim.
UNIT_FAILURE, USER_FAILURE, INTERNAL_FAILURE = "unit", "user", "internal"


@dataclass
class RunResult:
    """What one run produced.

    ``objectives`` is flat (array objectives as ``name[i]``); ``traces`` is a
    pandas DataFrame when recording was asked for, else None.  ``failure``
    says why a failed run failed: ``"unit"`` (a unit, or a non-finite
    objective), ``"user"`` (a user's file found unusable only while running,
    e.g. an FMU archive that escapes its folder) or ``"internal"`` (a bug).
    ``steps`` counts the communication steps taken (the accepted ones under
    the adaptive algorithm, whose ``step_stats`` say what else it did; under
    ``experiment.warm_start`` those after the warm start).
    """

    status: str
    message: str = ""
    objectives: dict[str, float] = field(default_factory=dict)
    traces: Any = None
    elapsed: float = 0.0
    steps: int = 0
    end_time: float = math.nan
    failure: str = ""
    # the adaptive algorithm's statistics (accepted, rejected, exceeded, smallest, largest, ...); None for a fixed step
    step_stats: dict[str, Any] | None = None

    @property
    def ok(self) -> bool:
        """Whether the run reached its stop time without a failure (status "ok")."""
        return self.status == OK


def step_count(start: float, stop: float, h: float) -> int:
    """Number of communication steps from start to stop; the last may be shorter.

    A ratio within 1e-9 of a whole number counts as that number, so 1.0/0.1
    gives 10 steps, not 11.
    """
    ratio = (stop - start) / h
    nearest = round(ratio)
    if abs(ratio - nearest) <= 1e-9 * max(1.0, abs(ratio)):
        return int(nearest)
    return int(math.ceil(ratio))


class Probe:
    """Reads every probed signal of the system into one float vector.

    Signals whose values are not floats (String, Binary) or do not fit one
    exactly (64-bit integers) are also read as Python objects by
    :meth:`read_exact`, for the trace recorder; only numbers enter the vector.
    """

    def __init__(self, system: System, units: Mapping[str, Unit]):
        self.columns: list[str] = []
        self.types: dict[str, tuple[str, str | None]] = {}
        self.units: dict[str, str] = {}  # column -> unit of measure, for the recorded table's metadata
        per_unit: dict[str, list] = {}
        positions: dict[str, list[int]] = {}
        exact: dict[str, list] = {}
        self.exact_columns: list[str] = []
        for signal in system.probes:
            for ref, column in zip(signal.refs, signal.columns):
                if column in self.types:
                    continue
                variable = signal.variable
                self.types[column] = (variable.type, variable.fmi_type)
                if variable.unit:
                    self.units[column] = variable.unit
                if variable.type not in NUMERIC_TYPES or variable.fmi_type in ("Int64", "UInt64"):
                    exact.setdefault(signal.unit, []).append(ref)
                    self.exact_columns.append(column)
                if variable.type not in NUMERIC_TYPES:
                    continue
                positions.setdefault(signal.unit, []).append(len(self.columns))
                per_unit.setdefault(signal.unit, []).append(ref)
                self.columns.append(column)
        self._exact_reads = [(units[name].select(refs), units[name]) for name, refs in exact.items()]
        self.values = np.zeros(len(self.columns))
        self._reads = []
        self._reads_of: dict[str, tuple] = {}  # unit name -> its read, for read_units
        for name, refs in per_unit.items():
            where = np.array(positions[name], dtype=int)
            contiguous = bool(np.all(np.diff(where) == 1))
            # a contiguous run is written through a slice, cheaper than fancy indexing
            target = slice(int(where[0]), int(where[-1]) + 1) if contiguous else where
            self._reads.append((units[name].reader(units[name].select(refs)), target))
            self._reads_of[name] = self._reads[-1]

    def read(self) -> np.ndarray:
        values = self.values
        for read, where in self._reads:
            values[where] = read()
        return values

    def read_units(self, names: Sequence[str]) -> np.ndarray:
        """The vector with only the columns of the units ``names`` read anew; the others keep the values of the
        last read (an event row: one unit is inside its step, the others are not to be read there)."""
        values = self.values
        for name in names:
            if name in self._reads_of:
                read, where = self._reads_of[name]
                values[where] = read()
        return values

    def read_exact(self) -> list[Any]:
        """The values of ``exact_columns``, as the units give them (str, bytes, int)."""
        out: list[Any] = []
        for selection, unit in self._exact_reads:
            out.extend(unit.get(selection))
        return out


def _record_events(system: System, stepped: Mapping[str, Any], probe: Probe, recorder: TraceRecorder) -> list[Any]:
    """Hook the model-exchange units whose spec says ``record_events`` (or the group integrating them) so that
    every event they handle inside a step adds two rows to the traces: their recorded columns just before the
    event and just after it, the other columns as at the last row.  Returns what was hooked."""
    wanted = [name for name, unit in system.units.items() if unit.spec.options.get("record_events")]
    by_stepping: dict[int, tuple[Any, list[str]]] = {}
    for name in wanted:
        stepping = stepped.get(name) or next((g for g in stepped.values() if name in getattr(g, "members", {})),
                                             None)
        if stepping is not None and hasattr(stepping, "on_event"):  # checked by the system: model exchange
            by_stepping.setdefault(id(stepping), (stepping, []))[1].append(name)
    for stepping, names in by_stepping.values():
        def on_event(t: float, phase: str, names: tuple[str, ...] = tuple(names)) -> None:
            recorder.event(t, probe.read_units(names))
        stepping.on_event = on_event
    return [stepping for stepping, _ in by_stepping.values()]


class Execution:
    """Runs one point of a system.

    ``overrides`` are applied after the spec's own parameters (design-point
    values). ``units``: live instances to reuse (the caller owns them and must
    pass them freshly instantiated or reset); when None, the execution
    instantiates its own and terminates them at the end. ``record`` keeps the
    full traces of the recorded signals.
    """

    def __init__(self, system: System, overrides: Sequence[Assignment] = (), record: bool = False,
                 units: Mapping[str, Unit] | None = None, observers: Sequence[Observer] = (),
                 warm: WarmState | None = None, save_warm: bool = False):
        """``warm``: start from this saved warm-up (:mod:`cosim.execution.warm_start`; default: the system's
        ``warm_start``, made by :func:`cosim.execution.warm_start.warmed`) instead of initializing anew: the units restored to its states, ``overrides`` set there (inputs and tunable parameters only), its
        samples replayed to the observers, then the steps from its time on.  ``save_warm``: run only to the
        spec's ``experiment.warm_start`` and keep the units' serialized states and the samples in :attr:`saved`."""
        self.system = system
        self.overrides = tuple(overrides)
        self.record = record
        self._given_units = units
        self.extra_observers = list(observers)
        self.warm = None if save_warm else warm if warm is not None else system.warm_start
        self.save_warm = save_warm
        self.saved: WarmState | None = None

    def run(self) -> RunResult:
        """Run to the stop time (or until ``stop_when`` is true); never raises for a unit's failure."""
        started = time.perf_counter()
        exp = self.system.spec.experiment
        units: dict[str, Unit] = dict(self._given_units or {})
        owned = self._given_units is None
        t = exp.start
        steps = 0
        algorithm = None
        hooked: list[Any] = []
        try:
            if owned:
                for name, system_unit in self.system.units.items():
                    units[name] = system_unit.unit_type.instantiate(name)
            n_steps = step_count(exp.start, exp.stop, exp.step)
            first, end = 0, n_steps  # the steps this run takes: k = first .. end - 1
            if self.save_warm:
                end = warm_steps(exp)
                refuse_unsaveable(self.system, units)
            # groups of model-exchange units: joined before initialization; the master steps each as one unit
            groups = self.system.model_exchange
            stepped = integrate_together(units, groups.groups, self.system.connections, self.system.coupling)
            order = groups.order if groups.groups else self.system.order
            if self.warm is not None:
                self._initialize(units, ())  # as the warm-up did; the run's own values are set at its time
                t, first = restore_warm(self.warm, units, self.overrides, self.system.init_order), self.warm.steps
            else:
                self._initialize(units)
            probe = Probe(self.system, units)
            exact = ExactColumns(probe.exact_columns, probe.read_exact) if probe.exact_columns else None
            recorder = TraceRecorder(probe.columns, self.system.recorded, n_steps + 1, exact,
                                     probe.types, probe.units) if self.record else None
            reducer = ObjectiveReducer(probe.columns, [(o.name, o.reduce, self._columns_of(o.signal)) for o in
                                                       self.system.spec.objectives if o.signal])
            observers = [o for o in (recorder, reducer) if o is not None] + self.extra_observers
            if recorder is not None:
                hooked = _record_events(self.system, stepped.units, probe, recorder)
            keeper = WarmSamples(probe, exact) if self.save_warm else None
            if keeper is not None:
                observers.append(keeper)
            stop_column = probe.columns.index(exp.stop_when) if exp.stop_when else None

            algorithm = make_algorithm(exp.algorithm)
            variable = algorithm.variable_step  # the adaptive algorithm: steps of its choosing, after the loop
            if variable:
                algorithm.configure(exp)  # type: ignore[attr-defined]  # its options, the run's span
            if algorithm.solves_loops:  # given the feed-through and loops to solve (others never see a loop)
                algorithm.bind(stepped.units, order, stepped.links, stepped.coupling)
            else:
                algorithm.bind(stepped.units, order, stepped.links)
            algorithm.start(t)  # e.g. algebraic loops solved at the start time
            if groups.groups:
                settle_groups(stepped, t)  # loops among a group's members, solved at the start time too
            if self.warm is not None:  # the observers see the warm-up's samples, as if this run had taken its steps
                self.warm.replay(observers, exact)
            else:
                values = probe.read()
                for observer in observers:
                    observer.initialized(t, values)
            start, h, last = exp.start, exp.step, n_steps - 1
            step, read = algorithm.step, probe.read
            hooks = [observer.step for observer in observers]
            ended: SimulationEnded | None = None
            for k in range(first, first if variable else end):
                t = start + k * h  # whole steps counted, never summed: no drift
                t_next = exp.stop if k == last else start + (k + 1) * h
                try:
                    step(t, t_next - t)
                except SimulationEnded as stop:  # a unit ends the run: record where it got to, then stop
                    ended, t_next = stop, stop.time
                t = t_next
                steps += 1
                values = read()
                for hook in hooks:
                    hook(t, values)
                if ended is not None or stop_column is not None and values[stop_column]:
                    break
            while variable and ended is None and t < exp.stop:
                try:
                    t = algorithm.advance(t)  # type: ignore[attr-defined]
                except SimulationEnded as stop:
                    ended, t = stop, stop.time
                steps += 1
                values = read()
                for hook in hooks:
                    hook(t, values)
                if stop_column is not None and values[stop_column]:
                    break
            if keeper is not None:  # the warm-up: keep the states at the warm-start time, and the samples to it
                self.saved = keeper.saved(self.system, units, t, end, ended, steps)
                return RunResult(OK, "", elapsed=time.perf_counter() - started, steps=steps, end_time=t)
            stats = algorithm.stats.as_dict() if variable else None  # type: ignore[attr-defined]
            for observer in observers:
                observer.finished(t)
            objectives = evaluate_expressions(self.system.spec.objectives, reducer.results())
            flat = flatten_objectives(objectives)
            nan = [name for name, v in flat.items() if not math.isfinite(v)]
            if nan:
                return RunResult(FAILED, f"objective(s) not finite: {', '.join(nan)}", flat,
                                 recorder.frame() if recorder else None, time.perf_counter() - started, steps, t,
                                 failure=UNIT_FAILURE, step_stats=stats)
            if ended is not None:
                message = f"stopped early: {ended} (stop time {exp.stop:g})"
                if exp.early_stop == "fail":  # the spec says a run must reach its stop time
                    return RunResult(FAILED, message + "; experiment.early_stop is 'fail'", flat,
                                     recorder.frame() if recorder else None, time.perf_counter() - started,
                                     steps, t, failure=UNIT_FAILURE, step_stats=stats)
                return RunResult(OK, message, flat, recorder.frame() if recorder else None,
                                 time.perf_counter() - started, steps, t, step_stats=stats)
            return RunResult(OK, "", flat, recorder.frame() if recorder else None,
                             time.perf_counter() - started, steps, t, step_stats=stats)
        except UnitError as exc:  # a Python unit's own frames kept in the message: where the user looks
            return RunResult(FAILED, exc.with_traceback_text(), elapsed=time.perf_counter() - started, steps=steps, end_time=t,
                             failure=UNIT_FAILURE)
        except UserError as exc:  # e.g. an FMU archive found unsafe when it is extracted
            if self.save_warm:
                raise  # a warm-up that cannot be made (a unit without saved states): the study's error, not a row
            return RunResult(FAILED, str(exc).replace("\n", " "), elapsed=time.perf_counter() - started,
                             steps=steps, end_time=t, failure=USER_FAILURE)
        except Exception as exc:  # an orchestrator bug must still become a row, not a lost point
            return RunResult(FAILED, f"internal error at t={t:g}: {type(exc).__name__}: {exc}",
                             elapsed=time.perf_counter() - started, steps=steps, end_time=t,
                             failure=INTERNAL_FAILURE)
        finally:
            for stepping in hooked:
                stepping.on_event = None  # units given by the caller outlive this run
            if algorithm is not None and algorithm.variable_step:
                try:
                    algorithm.free()  # type: ignore[attr-defined]  # its saved states, before the units go
                except Exception:
                    pass  # freeing the units matters more
            if owned:
                for unit in units.values():
                    try:
                        unit.terminate()
                    except Exception:
                        pass  # terminating every unit matters more than one unit's complaint

    def _columns_of(self, signal: str | None) -> list[str]:
        for s in self.system.probes:
            if s.text == signal:
                return list(s.columns)
        raise KeyError(signal)

    def _initialize(self, units: Mapping[str, Unit], overrides: Sequence[Assignment] | None = None) -> None:
        exp = self.system.spec.experiment
        for unit in units.values():
            unit.setup(exp.start, exp.stop)
        for assignment in self.system.assignments + tuple(self.overrides if overrides is None else overrides):
            unit = units[assignment.unit]
            unit.set(unit.select(assignment.refs), list(assignment.values))
        for unit in units.values():
            unit.enter_initialization()
        # Units leave initialization in stepping order, each after receiving the
        # initial outputs of its sources, so a unit's initialize() sees
        # consistent inputs (e.g. a robot starts where its trajectory starts).
        into: dict[str, list] = {}
        for connection in self.system.init_order:
            into.setdefault(connection.target.unit, []).append(connection)
        for name in self.system.order:
            for transfer in group_transfers(units, into.get(name, [])):
                transfer.run()
            units[name].exit_initialization()
        for transfer in group_transfers(units, self.system.init_order):  # outputs may change when it ends
            transfer.run()
