"""One run of one design point: the co-simulation loop.

:class:`Execution` instantiates (or reuses) the units of a
:class:`~cosim.system.builder.System`, sets parameters, initializes, advances
the system with a master algorithm (:mod:`cosim.master.contract`) and feeds
observers (:mod:`cosim.master.observers`; the run's own are in
:mod:`cosim.execution.observers`).  It does no file or network I/O.
Whatever goes wrong inside a run becomes data: the returned :class:`RunResult`
carries the status and a message naming the unit, the time and the cause.
Units it created are always terminated, also after a failure.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

from cosim.errors import UnitError, UserError
from cosim.execution.native import drive_native, takes_bulk
from cosim.execution.observers import Objectives, Recording, RunContext
from cosim.execution.probe import Probe
from cosim.execution.result import FAILED, INTERNAL_FAILURE, OK, UNIT_FAILURE, USER_FAILURE, RunResult
from cosim.execution.warm_start import WarmSamples, WarmState, refuse_unsaveable, restore_warm, warm_steps
from cosim.master.contract import MasterAlgorithm, StepGrid
from cosim.master.coupled_me import integrate_together
from cosim.master.native.algorithm import NativeFixedStep
from cosim.master.observers import ExactColumns, Observer, StopCondition, StopWhen, flatten_objectives
from cosim.master.registry import make_algorithm
from cosim.master.transfers import group_transfers
from cosim.spec.expressions import evaluate_expressions
from cosim.system.builder import System
from cosim.system.parts import Assignment
from cosim.units.protocol import SimulationEnded, Unit

__all__ = ["Execution", "RunResult", "OK", "FAILED", "UNIT_FAILURE", "USER_FAILURE", "INTERNAL_FAILURE"]


@dataclass
class _Progress:
    """Where a run got to: its time, the steps taken, and why it stopped before its end time (or None)."""

    t: float
    steps: int = 0
    stopped: str | None = None
    by_unit: bool = False  # a unit ended the run (SimulationEnded), not a stop condition
    status: str = OK  # what a stop condition made of the run
    stopper: StopCondition | None = None  # the stop condition that ended it


class Execution:
    """Runs one point of a system.

    ``overrides`` are applied after the spec's own parameters (design-point values).  ``units``: live
    instances to reuse (the caller owns them and must pass them freshly instantiated or reset); when None, the
    execution instantiates its own and terminates them at the end.  ``record`` keeps the full traces of the
    recorded signals.  ``observers`` watch the run beside its own (objectives, traces, ``stop_when``); a
    :class:`~cosim.master.observers.StopCondition` among them may end it early.  ``algorithm``: the master
    algorithm to advance with (default: the spec's ``experiment.algorithm``), bound anew at each run.
    """

    def __init__(self, system: System, overrides: Sequence[Assignment] = (), record: bool = False,
                 units: Mapping[str, Unit] | None = None, observers: Sequence[Observer] = (),
                 warm: WarmState | None = None, save_warm: bool = False, algorithm: MasterAlgorithm | None = None):
        """``warm``: start from this saved warm-up (:mod:`cosim.execution.warm_start`; default: the system's
        ``warm_start``, made by :func:`cosim.execution.warm_up.warmed`) instead of initializing anew: the units
        restored to its states, ``overrides`` set there (inputs and tunable parameters only), its samples
        replayed to the observers, then the steps from its time on.  ``save_warm``: run only to the spec's
        ``experiment.warm_start`` and keep the units' serialized states and the samples in :attr:`saved`."""
        self.system = system
        self.overrides = tuple(overrides)
        self.record = record
        self._given_units = units
        self.extra_observers = list(observers)
        self.warm = None if save_warm else warm if warm is not None else system.warm_start
        self.save_warm = save_warm
        self.saved: WarmState | None = None
        self.algorithm = algorithm

    def run(self) -> RunResult:
        """Run to the stop time (or until a stop condition holds); never raises for a unit's failure."""
        started = time.perf_counter()
        progress = _Progress(self.system.spec.experiment.start)
        units: dict[str, Unit] = dict(self._given_units or {})
        algorithm: MasterAlgorithm | None = None
        observers: list[Observer] = []
        try:
            if self._given_units is None:
                for name, system_unit in self.system.units.items():
                    units[name] = system_unit.unit_type.instantiate(name)
            context, progress.t = self._prepared(units)
            algorithm = self.algorithm or self._default_algorithm()
            algorithm.bind(context.view)
            objectives, recording, keeper = Objectives(self.system), self._recording(), self._keeper()
            observers = [o for o in (recording, objectives, keeper) if o is not None]
            observers += self._stop_conditions() + self.extra_observers
            for observer in observers:
                observer.attached(context)
            self._drive(algorithm, context, observers, progress)
            if keeper is not None:  # the warm-up: keep the states at the warm-start time, and the samples to it
                self.saved = keeper.saved(self.system, units, progress.t, progress.steps, progress.stopped)
                return RunResult(OK, "", elapsed=time.perf_counter() - started, steps=progress.steps,
                                 end_time=progress.t)
            for observer in observers:
                observer.finished(progress.t)
            return self._outcome(objectives, recording, algorithm, progress, time.perf_counter() - started)
        except Exception as exc:
            if isinstance(exc, UserError) and self.save_warm:
                raise  # a warm-up that cannot be made (a unit without saved states): the study's error, not a row
            return _failed(exc, progress, time.perf_counter() - started)
        finally:
            _release(observers, algorithm, units if self._given_units is None else {})

    def _prepared(self, units: Mapping[str, Unit]) -> tuple[RunContext, float]:
        """Initialize ``units`` (or restore the warm start) and return what the observers learn of the run and
        the time it starts from."""
        if self.save_warm:
            refuse_unsaveable(self.system, dict(units))
        groups = self.system.model_exchange  # joined before initialization; the master steps each as one unit
        view = integrate_together(units, groups.order if groups.groups else self.system.order, groups.groups,
                                  self.system.connections, self.system.coupling)
        t = self.system.spec.experiment.start
        if self.warm is not None:
            self._initialize(units, ())  # as the warm-up did; the run's own values are set at its time
            t = restore_warm(self.warm, dict(units), self.overrides, self.system.init_order)
        else:
            self._initialize(units)
        probe = Probe(self.system, units)
        exact = ExactColumns(probe.exact_columns, probe.read_exact) if probe.exact_columns else None
        return RunContext(self.system, units, view, probe, exact), t

    def _default_algorithm(self) -> MasterAlgorithm:
        """The spec's algorithm, stepped by the native kernel where the system's check chose it."""
        exp = self.system.spec.experiment
        if self.system.kernel.kernel == "native":
            return NativeFixedStep(exp, exp.algorithm)
        return make_algorithm(exp.algorithm, exp)

    def _recording(self) -> Recording | None:
        if not self.record:
            return None
        return Recording(self.system, StepGrid.of(self.system.spec.experiment).steps + 1)

    def _keeper(self) -> WarmSamples | None:
        return WarmSamples() if self.save_warm else None

    def _stop_conditions(self) -> list[Observer]:
        stop_when = self.system.spec.experiment.stop_when
        return [StopWhen(stop_when)] if stop_when else []

    def _drive(self, algorithm: MasterAlgorithm, context: RunContext, observers: Sequence[Observer],
               progress: _Progress) -> None:
        """Start ``algorithm`` and advance it to the end time (the warm-start time for a warm-up), feeding the
        observers at every communication point, until a unit ends the run or a stop condition holds."""
        exp = self.system.spec.experiment
        t_end = StepGrid.of(exp).time(warm_steps(exp)) if self.save_warm else exp.stop
        if isinstance(algorithm, NativeFixedStep) and self.warm is None and takes_bulk(observers):
            drive_native(algorithm, context, observers, progress, t_end)
            return
        algorithm.start(progress.t)  # e.g. algebraic loops solved at the start time
        if self.warm is not None:  # the observers see the warm-up's samples, as if this run had taken its steps
            self.warm.replay(observers, context.exact)
        else:
            values = context.probe.read()
            for observer in observers:
                observer.initialized(progress.t, values)
        advance, read = algorithm.advance, context.probe.read
        hooks = [observer.step for observer in observers]
        stops = [observer for observer in observers if isinstance(observer, StopCondition)]
        t = progress.t
        while t < t_end:
            try:
                t = advance(t)
            except SimulationEnded as ended:  # a unit ends the run: record where it got to, then stop
                t, progress.stopped, progress.by_unit = ended.time, str(ended), True
            progress.t, progress.steps = t, progress.steps + 1
            values = read()
            for hook in hooks:
                hook(t, values)
            if progress.stopped is not None:
                return
            for stop in stops:
                if stop.reason is not None:
                    progress.stopped, progress.status, progress.stopper = stop.reason, stop.status, stop
                    return

    def _outcome(self, objectives: Objectives, recording: Recording | None, algorithm: MasterAlgorithm,
                 progress: _Progress, elapsed: float) -> RunResult:
        """The run's result from its observers: failed for a non-finite objective, or when a unit ended it early
        and the spec says ``early_stop: fail``."""
        exp = self.system.spec.experiment
        flat = flatten_objectives(evaluate_expressions(self.system.spec.objectives, objectives.results()))
        traces = recording.frame() if recording is not None else None
        row: dict[str, Any] = dict(objectives=flat, traces=traces, elapsed=elapsed, steps=progress.steps,
                                   end_time=progress.t, step_stats=algorithm.statistics())
        stopper = progress.stopper
        if progress.status != OK and stopper is not None:  # its own verdict (pruned: the bound vector)
            row["objectives"] = stopper.objectives_at_stop(flat)
            return RunResult(progress.status, progress.stopped or "", **row)
        nan = [name for name, v in flat.items() if not math.isfinite(v)]
        if nan:
            return RunResult(FAILED, f"objective(s) not finite: {', '.join(nan)}", failure=UNIT_FAILURE, **row)
        if progress.stopped is not None and progress.by_unit:
            message = f"stopped early: {progress.stopped} (stop time {exp.stop:g})"
            if exp.early_stop == "fail":  # the spec says a run must reach its stop time
                return RunResult(FAILED, message + "; experiment.early_stop is 'fail'", failure=UNIT_FAILURE, **row)
            return RunResult(OK, message, **row)
        if progress.status != OK:  # a stop condition's own verdict on the run
            return RunResult(progress.status, progress.stopped or "", **row)
        return RunResult(OK, "", **row)

    def _initialize(self, units: Mapping[str, Unit], overrides: Sequence[Assignment] | None = None) -> None:
        """Set up, set the spec's values and ``overrides`` (default: the run's), initialize in stepping order."""
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
        into: dict[str, list[Any]] = {}
        for connection in self.system.init_order:
            into.setdefault(connection.target.unit, []).append(connection)
        for name in self.system.order:
            for transfer in group_transfers(units, into.get(name, [])):
                transfer.run()
            units[name].exit_initialization()
        for transfer in group_transfers(units, self.system.init_order):  # outputs may change when it ends
            transfer.run()


def _failed(exc: Exception, progress: _Progress, elapsed: float) -> RunResult:
    """The row of a run that raised: a unit's failure (its own frames kept in the message, where the user
    looks), a user's file found unusable only while running, or an orchestrator bug (still a row, never a lost
    point)."""
    where: dict[str, Any] = dict(elapsed=elapsed, steps=progress.steps, end_time=progress.t)
    if isinstance(exc, UnitError):
        return RunResult(FAILED, exc.with_traceback_text(), failure=UNIT_FAILURE, **where)
    if isinstance(exc, UserError):  # e.g. an FMU archive found unsafe when it is extracted
        return RunResult(FAILED, str(exc).replace("\n", " "), failure=USER_FAILURE, **where)
    return RunResult(FAILED, f"internal error at t={progress.t:g}: {type(exc).__name__}: {exc}",
                     failure=INTERNAL_FAILURE, **where)


def _release(observers: Sequence[Observer], algorithm: MasterAlgorithm | None, owned: Mapping[str, Unit]) -> None:
    """After a run, however it ended: observers detached, the algorithm's saved states freed before the units go,
    the units the run made terminated (each one, whatever another one says)."""
    for observer in observers:
        try:
            observer.detached()
        except Exception:
            pass  # releasing the units matters more
    if algorithm is not None:
        try:
            algorithm.free()
        except Exception:
            pass  # freeing the units matters more
    for unit in owned.values():
        try:
            unit.terminate()
        except Exception:
            pass  # terminating every unit matters more than one unit's complaint
