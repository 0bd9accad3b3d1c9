"""Model Exchange FMUs (FMI 2.0 and 3.0) as co-simulation units.

A Model Exchange FMU only evaluates its equations (derivatives, event
indicators, event updates); the importer integrates them.  Here each
communication step ``do_step(t, h)`` integrates the FMU from ``t`` to ``t + h``
with CVode (SUNDIALS, as shipped with fmpy: :class:`fmpy.sundials.CVodeSolver`,
BDF with a dense Newton solver, absolute tolerance = relative tolerance x the
states' nominal values), with the inputs held as the master set them:

* **time events**: the step is split at the FMU's next event time, where the
  event is handled exactly;
* **state events**: CVode locates the zero crossings of the event indicators
  (root finding) and returns there; the event is handled, then integration
  goes on to the end of the step;
* **step events**: after every return of the solver (the end of the step, a
  time or a state event) ``completedIntegratorStep`` is called, as fmpy's
  ``simulate_fmu`` does, and an event is handled when the FMU asks for one;
* an **input change** between steps restarts the solver (the right-hand side
  jumps), and is handled as an event when it flips an event indicator's sign.

Handling an event = Event Mode, the event iteration (``newDiscreteStates`` /
``updateDiscreteStates`` until no discrete state needs an update; at most
:data:`MAX_EVENT_ITERATIONS` rounds), Continuous-Time Mode, solver restart.
An FMU that asks to terminate (``terminateSimulation``) ends the run there, cleanly
(:class:`~cosim.units.protocol.SimulationEnded`, as a co-simulation FMU does).

Solver settings come from the spec (:class:`SolverSettings`: ``tolerance``,
``max_step``, by default the communication step); the tolerance is also handed
to the FMU (``setupExperiment`` / ``enterInitializationMode``).
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np
from fmpy.fmi2 import FMU2Model
from fmpy.fmi3 import FMU3Model

from cosim.units.fmu.fmi2 import Fmi2Unit
from cosim.units.fmu.fmi3 import Fmi3Unit
from cosim.units.fmu.fmpy_internals import with_cached_signatures
from cosim.units.fmu.instance import FmiInstance
from cosim.units.protocol import Selection, SimulationEnded, UnitError

MAX_EVENT_ITERATIONS = 100
# CVode's relative tolerance when the spec gives none.  1e-6 was not enough for results another tool accepts:
# the Reference FMU BouncingBall's bounce times drift by ~100 x rtol over its 11 bounces (v 8e-4 off after the
# last ones), and a two-mass oscillator whose internal step is capped at a 1 ms communication step stays at BDF
# order 2 (its local error estimate passes at 1e-6), 4e-5 of its amplitude off after 10 periods; OMSimulator's
# testsuite compares such results with rel 1e-4 + abs 1e-4.  At 1e-8 both are 30-300x inside that, for about 10 %
# more right-hand-side evaluations (tests/units/test_vendor_numerics.py; docs/fmi-support.md, "Model exchange defaults").
DEFAULT_TOLERANCE = 1e-8
# CVode's limit of internal steps per communication step (fmpy's default of 500
# is too small for long communication steps with a small max_step).
MAX_INTERNAL_STEPS = 100_000


@dataclass(frozen=True)
class SolverSettings:
    """How a Model Exchange unit is integrated.

    ``tolerance``: CVode's relative tolerance (the absolute one is
    ``tolerance`` x each state's nominal value).  ``max_step``: the largest
    internal step in seconds (``None``: the communication step; see
    :func:`internal_step_cap`).  Raises ValueError for values that are not positive.
    """

    tolerance: float = DEFAULT_TOLERANCE
    max_step: float | None = None

    def __post_init__(self) -> None:
        if not (isinstance(self.tolerance, (int, float)) and 0 < self.tolerance < 1):
            raise ValueError(f"tolerance must be a number in (0, 1), not {self.tolerance!r}")
        if self.max_step is not None and not (isinstance(self.max_step, (int, float)) and self.max_step > 0
                                              and math.isfinite(self.max_step)):
            raise ValueError(f"max_step must be a positive number of seconds, not {self.max_step!r}")


def internal_step_cap(settings: SolverSettings, h: float) -> float:
    """The largest internal CVode step for a communication step ``h``: ``settings.max_step``, else ``h``.

    Why a cap by default: CVode (in fmpy's CV_NORMAL mode) steps past the
    communication point and interpolates back, and its step size grows from one
    communication step to the next, so without a cap a loose tolerance gives
    errors far above it (a Dahlquist equation at tolerance 1e-4 was 1.2e-3 off;
    ``tests/units/test_model_exchange_units.py``).
    """
    return settings.max_step if settings.max_step is not None else h


def solver_problem() -> str | None:
    """Why CVode cannot run here (fmpy ships SUNDIALS for some platforms only), or None when it can."""
    try:
        import fmpy.sundials  # noqa: F401  (loads the SUNDIALS libraries)
    except Exception as exc:  # ImportError, OSError from ctypes, fmpy's version check
        return f"model exchange needs CVode from fmpy (fmpy.sundials), which does not load here: {exc}"
    return None


class _NoInputs:
    """fmpy's CVodeSolver applies input signals in its root function; ours are set by the master."""

    @staticmethod
    def apply(*args: Any, **kwargs: Any) -> None:
        return None


class EventLoop:
    """CVode over continuous states with events: what one Model Exchange unit and a group of them share.

    ``do_step(t, h)`` integrates from ``t`` to ``t + h`` as the module docstring says (time events split
    the step, state events stop the solver, step events after every return, an input change restarts it).
    A subclass is the model: it supplies

    * ``_solver_model()``: keyword arguments of fmpy's ``CVodeSolver`` (nx, nz, get_x, set_x, get_dx, get_z,
      get_nominals, set_time), each call wrapped with :meth:`_caught`;
    * ``_set_time(t)``: the model's time after the solver returned (also ``self._now = t``);
    * ``_completed_integrator_step()``: True when the model asks for a step event;
    * ``_enter_event_mode()``, ``_event_iteration()``, ``_enter_continuous_time_mode()``;
    * ``_next_event_time()``: the next time event, or None;
    * ``_read_indicators_into(buffer)``: the event indicators now;
    * ``_callback_failure(exc)``: the UnitError for an exception raised inside a solver callback.

    Call :meth:`_init_loop` from ``__init__``.
    """

    name: str
    time: float | None
    # called at every time, state and step event handled inside do_step, with (t, "before") just before the
    # event is handled (the left limit) and (t, "after") right after it (the right limit): the run records
    # event rows so (a unit's "record_events"); not for an input change at a communication point
    on_event: Callable[[float, str], None] | None = None

    def _init_loop(self, settings: SolverSettings, nz: int) -> None:
        self._settings = settings
        self._nz = nz
        self._solver: Any = None
        self._step_cap: float | None = None  # CVode's max step as last set (internal_step_cap)
        self._now = 0.0  # the time the model and the solver are at
        self._inputs_changed = False
        self._z = np.zeros(nz)
        self._z_buffer = (ctypes.c_double * max(nz, 1))()
        self._callback_error: BaseException | None = None
        self.events = {"time": 0, "state": 0, "step": 0, "input": 0}  # handled so far (for tests and reports)

    # -- stepping --------------------------------------------------------------

    def do_step(self, t: float, h: float) -> None:
        self.time = t
        end = t + h
        if self._solver is None:
            raise UnitError(self.name, "do_step before initialization", t)
        self._cap_internal_step(h)
        if self._inputs_changed:
            self._after_input_change()
        events_in_place = 0  # events handled without time advancing: a bound against endless loops
        while not _reached(self._now, end):
            event_time = self._next_event_time()
            # A time event inside the step, or on its end up to rounding, ends this stretch of integration.
            due = event_time if event_time is not None and (event_time < end or _close(event_time, end)) else None
            target = max(min(due, end), self._now) if due is not None else end
            if _reached(self._now, target):
                events_in_place += 1
                if events_in_place > MAX_EVENT_ITERATIONS:
                    raise UnitError(self.name, f"time stands still: the FMU keeps announcing its next event at "
                                    f"t={event_time!r}, not after the current time", self._now)
            state_event = self._integrate(target) if not _reached(self._now, target) else False
            time_event = due is not None and not state_event
            if due is not None and not state_event:
                self._set_time(due)  # exactly the announced time, whatever rounding did to 'target'
            step_event = self._completed_integrator_step()
            if time_event or state_event or step_event:
                self.events["time"] += time_event
                self.events["state"] += state_event
                self.events["step"] += step_event
                if self.on_event is not None:
                    self.on_event(self._now, "before")
                self._handle_event()
                if self.on_event is not None:
                    self.on_event(self._now, "after")
        self._now = max(self._now, end)

    def _cap_internal_step(self, h: float) -> None:
        cap = internal_step_cap(self._settings, h)
        if self._step_cap is None or not _close(cap, self._step_cap):  # CVodeReInit keeps it: set on a change
            from fmpy.sundials.cvode import CVodeSetMaxStep

            CVodeSetMaxStep(self._solver.cvode_mem, cap)
            self._step_cap = cap

    def _integrate(self, target: float) -> bool:
        """Run CVode from ``self._now`` towards ``target``; True when it stopped earlier at a state event."""
        self._callback_error = None
        try:
            state_event, _roots, reached = self._solver.step(self._now, target)
        except Exception as exc:  # fmpy raises RuntimeError with CVode's message
            raise UnitError(self.name, f"the solver (CVode) failed between t={self._now:g} and t={target:g}: {exc}; "
                            "try a smaller 'max_step' or a looser 'tolerance'", self._now) from None
        if self._callback_error is not None:
            raise self._fail_callback()
        self._set_time(reached if state_event else target)  # fmpy's solver has set the states already
        return bool(state_event)

    def _after_input_change(self) -> None:
        """Inputs jumped at a communication point: an event if an indicator changed sign, and a solver restart."""
        self._inputs_changed = False
        before = self._z.copy()
        self._read_indicators()
        if np.any(np.signbit(before) != np.signbit(self._z)):
            self.events["input"] += 1
            self._handle_event()  # restarts the solver too
        else:
            self._restart_solver()

    def _handle_event(self) -> None:
        self._enter_event_mode()
        self._event_iteration()
        self._enter_continuous_time_mode()
        self._restart_solver()

    def _start_solver(self) -> None:
        from fmpy.sundials import CVodeSolver
        from fmpy.sundials.cvode import CVodeSetMaxNumSteps

        max_step = self._settings.max_step if self._settings.max_step is not None else float("inf")
        self._step_cap = None  # the communication step's cap is set at the first do_step
        self._solver = CVodeSolver(**self._solver_model(), input=_NoInputs(), startTime=self._now,
                                   maxStep=max_step, relativeTolerance=self._settings.tolerance)
        CVodeSetMaxNumSteps(self._solver.cvode_mem, MAX_INTERNAL_STEPS)
        if self._callback_error is not None:
            raise self._fail_callback()
        self._read_indicators()

    def _restart_solver(self) -> None:
        """States, discrete states or inputs jumped: CVode starts afresh from the current point."""
        self._set_time(self._now)
        self._solver.reset(self._now)
        if self._callback_error is not None:
            raise self._fail_callback()
        self._read_indicators()

    def _read_indicators(self) -> None:
        if self._nz:
            self._read_indicators_into(self._z_buffer)
            self._z = np.array(self._z_buffer[:self._nz])

    # -- errors ------------------------------------------------------------------

    def _caught(self, call: Callable[..., Any]) -> Callable[..., Any]:
        """``call`` for CVode's callbacks: an exception cannot cross the C solver, so keep the first one."""
        def guarded(*args: Any) -> Any:
            try:
                return call(*args)
            except Exception as exc:
                if self._callback_error is None:
                    self._callback_error = exc
                return None
        return guarded

    def _fail_callback(self) -> UnitError:
        """The UnitError for the exception a solver callback kept (called only when one did)."""
        exc, self._callback_error = self._callback_error, None
        assert exc is not None, "_fail_callback without a failed callback"
        return self._callback_failure(exc)

    # -- the model (see the class docstring) -------------------------------------

    def _solver_model(self) -> dict[str, Any]:
        raise NotImplementedError

    def _set_time(self, time: float) -> None:
        raise NotImplementedError

    def _completed_integrator_step(self) -> bool:
        raise NotImplementedError

    def _enter_event_mode(self) -> None:
        raise NotImplementedError

    def _event_iteration(self) -> None:
        raise NotImplementedError

    def _enter_continuous_time_mode(self) -> None:
        raise NotImplementedError

    def _next_event_time(self) -> float | None:
        raise NotImplementedError

    def _read_indicators_into(self, buffer: Any) -> None:
        raise NotImplementedError

    def _callback_failure(self, exc: BaseException) -> UnitError:
        raise NotImplementedError


class _ModelExchangeStepping(EventLoop, FmiInstance):
    """One Model Exchange FMU as a unit, FMI 2.0 and 3.0 alike (a mixin before Fmi2Unit/Fmi3Unit).

    It derives from :class:`FmiInstance` (the instance it is a model of: ``_guard``, ``fail``, ``_slave``) so
    that the type checker knows those; the classes' order is unchanged (``Fmi2ModelExchangeUnit``: this
    mixin, EventLoop, Fmi2Unit, FmiInstance), so ``super()`` here still reaches Fmi2Unit/Fmi3Unit.

    Subclasses provide ``_update_discrete_states()`` (fmpy's 6-tuple) and
    ``_get_derivatives`` (fmpy's name differs between versions).

    A unit that a group integrates together with others (:mod:`cosim.units.fmu.coupled_me`,
    :meth:`join`) has no solver of its own: the group evaluates its equations and handles its events.
    """

    _plain_calls = False  # its set() and do_step() do more than the FMI calls (see FmiInstance._plain_calls)

    def __init__(self, name: str, unit_type: Any):
        super().__init__(name, unit_type)  # Fmi2Unit/Fmi3Unit: the instance, as a model
        md = unit_type.model_description()
        self._init_loop(unit_type.solver_settings, md.numberOfEventIndicators)
        self._nx = md.numberOfContinuousStates
        self._needs_step_call = bool(getattr(md.modelExchange, "needsCompletedIntegratorStep", True))
        self._next_event: float | None = None
        self._last_set: dict[int, tuple[Selection, tuple[Any, ...]]] = {}
        self.group: Any = None  # the group integrating this unit together with others (join), or None

    # -- lifecycle -----------------------------------------------------------

    def setup(self, start_time: float, stop_time: float | None) -> None:
        # safe-super: Unit.setup is abstract, but super() is Fmi2Unit/Fmi3Unit here (both define it)
        super().setup(start_time, stop_time)  # type: ignore[safe-super]
        self._now = start_time

    def join(self, group: Any) -> None:
        """From now on ``group`` integrates this unit (with others): no solver of its own, no do_step."""
        self.group = group

    # -- inputs ------------------------------------------------------------------

    def set(self, selection: Selection, values: Sequence[Any]) -> None:
        # Only a *changed* input restarts the solver: masters set every input every step.
        # The selection is kept with its values so that a new selection reusing its id() is not mistaken for it.
        new = tuple(values)
        if self._last_set.get(id(selection)) != (selection, new):
            self._last_set[id(selection)] = (selection, new)
            self._inputs_changed = True
        super().set(selection, values)

    def set_within_group(self, selection: Selection, values: Sequence[Any]) -> None:
        """Set inputs as the group integrating this unit does while it evaluates the equations: no restart."""
        super().set(selection, values)

    def exit_initialization(self) -> None:
        super().exit_initialization()  # type: ignore[safe-super]  # as in setup: Fmi2Unit/Fmi3Unit define it
        self._event_iteration()  # FMI: the instance is in Event Mode after initialization
        self._enter_continuous_time_mode()
        if self.group is None:
            self._start_solver()
        self._inputs_changed = False

    def reset(self) -> None:
        self._solver = None
        self._next_event = None
        self._last_set.clear()
        super().reset()

    def terminate(self) -> None:
        self._solver = None  # CVodeFree runs when fmpy's solver object is collected
        super().terminate()

    def do_step(self, t: float, h: float, no_set_prior: int = 1) -> None:
        # no_set_prior: FmiInstance's signature; unused, as a Model Exchange unit's state is never restored
        if self.group is not None:
            raise UnitError(self.name, f"do_step on a unit that '{self.group.name}' integrates together with "
                            "others (step the group instead)", t)
        super().do_step(t, h)

    # -- the model for the solver loop -----------------------------------------------

    def _solver_model(self) -> dict[str, Any]:
        return dict(nx=self._nx, nz=self._nz, get_x=self._caught(self._slave.getContinuousStates),
                    set_x=self._caught(self._slave.setContinuousStates), get_dx=self._caught(self._get_derivatives()),
                    get_z=self._caught(self._slave.getEventIndicators),
                    get_nominals=self._caught(self._slave.getNominalsOfContinuousStates),
                    set_time=self._caught(self._slave.setTime))

    def _set_time(self, time: float) -> None:
        self._now = time
        self._guard("setTime", lambda: self._slave.setTime(time))

    def _completed_integrator_step(self) -> bool:
        if not self._needs_step_call:
            return False
        step_event, terminate = self._guard("completedIntegratorStep", self._slave.completedIntegratorStep)
        if terminate:
            raise self._ended("completedIntegratorStep")
        return bool(step_event)

    def _enter_event_mode(self) -> None:
        self._guard("enterEventMode", self._slave.enterEventMode)

    def _enter_continuous_time_mode(self) -> None:
        self._guard("enterContinuousTimeMode", self._slave.enterContinuousTimeMode)

    def _event_iteration(self) -> None:
        """Update discrete states until the FMU needs no more; note the next time event."""
        for _ in range(MAX_EVENT_ITERATIONS):
            needed, terminate, _nominals, _values, next_defined, next_time = self._guard(
                self._update_call, self._update_discrete_states)
            if terminate:
                raise self._ended(self._update_call)
            if not needed:
                self._next_event = float(next_time) if next_defined else None
                return
        raise UnitError(self.name, f"the event iteration did not converge in {MAX_EVENT_ITERATIONS} rounds "
                        "(the FMU keeps asking for new discrete states)", self._now)

    def _next_event_time(self) -> float | None:
        return self._next_event

    def _read_indicators_into(self, buffer: Any) -> None:
        self._guard("getEventIndicators", lambda: self._slave.getEventIndicators(buffer, self._nz))

    def _callback_failure(self, exc: BaseException) -> UnitError:
        return self.fail("a call during integration", exc)

    def _ended(self, call: str) -> SimulationEnded:
        """The FMU asked to end the simulation: the run ends here, cleanly (as for a co-simulation FMU)."""
        return SimulationEnded(self.name, self._now, f"ended the simulation ({call}: terminateSimulation)")

    # provided per FMI version
    _update_call = "updateDiscreteStates"

    def _update_discrete_states(self) -> tuple[Any, ...]:
        raise NotImplementedError

    def _get_derivatives(self) -> Callable[..., Any]:
        raise NotImplementedError


def _reached(now: float, target: float) -> bool:
    """``now`` is at or past ``target``, up to the rounding of adding step sizes."""
    return target - now <= 1e-12 * max(1.0, abs(target))


def _close(a: float, b: float) -> bool:
    """``a`` and ``b`` are the same time up to the rounding of adding step sizes."""
    return abs(a - b) <= 1e-12 * max(1.0, abs(a), abs(b))


class Fmi2ModelExchangeUnit(_ModelExchangeStepping, Fmi2Unit):
    """A live FMI 2.0 Model Exchange instance, integrated by CVode inside each communication step."""

    _slave_class = with_cached_signatures(FMU2Model)
    _interface = "modelExchange"
    _update_call = "fmi2NewDiscreteStates"

    def setup(self, start_time: float, stop_time: float | None) -> None:
        self.time = self._now = start_time
        self._guard("fmi2SetupExperiment", lambda: self._slave.setupExperiment(
            tolerance=self._settings.tolerance, startTime=start_time, stopTime=stop_time))

    def _update_discrete_states(self) -> tuple[Any, ...]:
        return tuple(self._slave.newDiscreteStates())  # fmpy's tuple itself (tuple() of a tuple is no copy)

    def _get_derivatives(self) -> Callable[..., Any]:
        derivatives: Callable[..., Any] = self._slave.getDerivatives
        return derivatives


class Fmi3ModelExchangeUnit(_ModelExchangeStepping, Fmi3Unit):
    """A live FMI 3.0 Model Exchange instance, integrated by CVode inside each communication step."""

    _slave_class = with_cached_signatures(FMU3Model)
    _interface = "modelExchange"
    _update_call = "fmi3UpdateDiscreteStates"

    def enter_initialization(self) -> None:
        self._guard("fmi3EnterInitializationMode", lambda: self._slave.enterInitializationMode(
            tolerance=self._settings.tolerance, startTime=self._start_time, stopTime=self._stop_time))

    def _update_discrete_states(self) -> tuple[Any, ...]:
        return tuple(self._slave.updateDiscreteStates())  # as for FMI 2.0: fmpy's tuple itself

    def _get_derivatives(self) -> Callable[..., Any]:
        derivatives: Callable[..., Any] = self._slave.getContinuousStateDerivatives
        return derivatives
