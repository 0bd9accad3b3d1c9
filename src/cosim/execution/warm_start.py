"""A study's warm start: run once to ``experiment.warm_start``, save every unit's state, start each point there.

A system that must settle before the part a study varies (a plant warmed up, a controller wound up) spends most
of every point's run repeating the same warm-up.  With ``"experiment": {"warm_start": T}`` the warm-up runs once,
with the spec's own values (:func:`warm_up`): its units' states at ``T`` are saved and serialized
(:meth:`~cosim.units.protocol.Unit.serialize_state`: FMI ``fmi2SerializeFMUstate`` / ``fmi3SerializeFMUState``, a
Python unit's pickled ``get_state``), and the probed samples from the start time to ``T`` are kept.  The bytes
travel with a study's payload to every worker (:func:`cosim.parallel.isolation.payload.make_payload`).  Each point then

1. initializes its units as the warm-up did (the spec's own values), restores their states at ``T``
   (:func:`restore_warm`), and sets its own values there: inputs and *tunable* parameters only, since a fixed
   parameter is part of the saved state and cannot change after initialization (the system check refuses design
   parameters that are not tunable, :mod:`cosim.system.warm_start_checks`);
2. replays the warm-up's samples to its observers (:meth:`WarmState.replay`), so its traces and objectives cover the
   whole span from the start time, as a run that changed its values at ``T`` would;
3. takes the steps from ``T`` to the stop time on the same grid ``t_k = start + k*h`` as a run from the start.

So a point with the spec's own values gives the results of a run from the start time, and every point takes only
the steps after ``T`` (``RunResult.steps`` counts them).  Needs a fixed-step algorithm (the loader refuses
``adaptive``) and units that can save and serialize their state (a unit that cannot is named by
:func:`refuse_unsaveable`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from cosim.errors import Problem, UserError
from cosim.execution.probe import Probe
from cosim.master.observers import ExactColumns, Observer
from cosim.master.transfers import group_transfers
from cosim.system.builder import System
from cosim.system.parts import Assignment
from cosim.units.protocol import Unit

WARM_PATH = "$.experiment.warm_start"


@dataclass(frozen=True)
class WarmState:
    """The saved warm-up: the time reached, the steps to it, each unit's serialized state and the samples so far.

    ``times`` (n,) and ``samples`` (n, probed columns) are what the observers received from the start time to
    ``time``; ``exact`` the values of the probe's exact columns (text, bytes, 64-bit integers) at each sample.
    Plain data: it pickles into a study's payload.
    """

    time: float
    steps: int
    states: tuple[tuple[str, bytes], ...]
    times: np.ndarray
    samples: np.ndarray
    exact: tuple[tuple[Any, ...], ...]
    columns: tuple[str, ...]

    def replay(self, observers: Sequence[Observer], exact: ExactColumns | None) -> None:
        """Give ``observers`` the warm-up's samples (``initialized`` the first, ``step`` the others), the exact
        columns read from the saved rows instead of the live units (which are at ``time`` already)."""
        live: Callable[[], Sequence[Any]] | None = exact.read if exact is not None else None
        if exact is not None:
            rows = iter(self.exact)
            exact.read = lambda: next(rows)
        # the recorder and the reducer take all samples at once (the same rows); the others one by one
        one_by_one = [observer for observer in observers if not observer.load(self.times, self.samples)]
        try:
            for observer in one_by_one:
                observer.initialized(float(self.times[0]), self.samples[0])
            hooks = [observer.step for observer in one_by_one]
            for t, values in zip(self.times[1:].tolist(), self.samples[1:]):
                for hook in hooks:
                    hook(t, values)
        finally:
            if exact is not None and live is not None:
                exact.read = live


def warm_steps(experiment: Any) -> int:
    """Communication steps from the start time to ``experiment.warm_start`` (on the step grid: the loader checks)."""
    return int(round((experiment.warm_start - experiment.start) / experiment.step))


class WarmSamples(Observer):
    """Keeps every sample of the warm-up (a copy of the probe's vector, and its exact columns)."""

    def __init__(self) -> None:
        self.columns: tuple[str, ...] = ()
        self._exact: ExactColumns | None = None
        self.times: list[float] = []
        self.samples: list[np.ndarray] = []
        self.exact_rows: list[tuple[Any, ...]] = []

    def attached(self, context: Any) -> None:
        probe: Probe = context.probe
        self.columns, self._exact = tuple(probe.columns), context.exact

    def initialized(self, t: float, values: np.ndarray) -> None:
        self.step(t, values)

    def step(self, t: float, values: np.ndarray) -> None:
        self.times.append(t)
        self.samples.append(values.copy())
        if self._exact is not None:
            self.exact_rows.append(tuple(self._exact.read()))

    def saved(self, system: System, units: dict[str, Unit], t: float, steps: int, stopped: str | None) -> WarmState:
        """The warm state at ``t`` after the ``steps`` to the warm-start time; raises UserError when the run
        ended before it (``stopped``: why — a unit ended the simulation, or ``stop_when`` became true)."""
        exp = system.spec.experiment
        if stopped is not None:
            why = stopped
            raise UserError([Problem(system.spec.path, WARM_PATH, f"the warm-up run ended at t={t:g}, before "
                                     f"warm_start {exp.warm_start:g} ({why})",
                                     "choose a warm_start before the run ends, or remove warm_start")])
        states = []
        for name, unit in units.items():
            state = unit.save_state()
            try:
                states.append((name, unit.serialize_state(state)))
            finally:
                unit.free_state(state)
        return WarmState(time=t, steps=steps, states=tuple(states), times=np.array(self.times),
                         samples=np.vstack(self.samples), exact=tuple(self.exact_rows), columns=self.columns)


def refuse_unsaveable(system: System, units: dict[str, Unit]) -> None:
    """Raise UserError naming every unit that cannot save and serialize its state (a warm start needs both)."""
    problems = []
    for name, unit in units.items():
        if unit.can_serialize_state:
            continue
        kind = system.units[name].description.kind
        why = ("a Python unit without get_state and set_state" if kind == "python" else
               "a Model Exchange unit (its solver's state is not in the FMU state)"
               if not getattr(unit, "_plain_calls", True) else
               "its FMU does not declare canGetAndSetFMUstate and canSerializeFMUstate" if kind == "fmu" else
               f"a {kind} unit, which offers no saved state")
        problems.append(Problem(system.spec.path, WARM_PATH, f"unit '{name}' cannot save and serialize its state "
                                f"({why}), which a warm start needs",
                                "remove warm_start, or use units that can (an FMU with canGetAndSetFMUstate and "
                                "canSerializeFMUstate, a Python unit defining get_state and set_state)"))
    if problems:
        raise UserError(problems)


def restore_warm(warm: WarmState, units: dict[str, Unit], overrides: Sequence[Assignment],
                 init_order: Sequence[Any]) -> float:
    """Put the initialized ``units`` into the warm-up's states, set ``overrides`` there (inputs and tunable
    parameters; raises UserError for another), then every input from its source's output; returns the time."""
    for name, data in warm.states:
        unit = units[name]
        state = unit.deserialize_state(data)
        try:
            unit.restore_state(state)
        finally:
            unit.free_state(state)
    for assignment in overrides:
        unit = units[assignment.unit]
        fixed = sorted({ref.variable for ref in assignment.refs if not unit.can_tune(ref.variable)})
        if fixed:
            raise UserError([Problem("", WARM_PATH, f"'{assignment.unit}.{fixed[0]}' is not tunable: a warm-started "
                                     "run cannot change it (it is part of the saved state)",
                                     "vary inputs and tunable parameters only, or remove warm_start")])
        unit.set(unit.select(assignment.refs), list(assignment.values))
    for transfer in group_transfers(units, init_order):  # the inputs follow outputs the new values may change
        transfer.run()
    return warm.time
