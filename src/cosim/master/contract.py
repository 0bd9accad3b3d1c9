"""The one contract every master algorithm implements, and the time grid of fixed communication steps.

An algorithm is made for an experiment (its start, stop, step and options), bound once to what it steps
(:class:`SystemView`: live units, their stepping order, the links between their ports, the direct feed-through
and algebraic loops among them), started once at the start time, and then asked to **advance** the system from
a time ``t`` to a later time it chooses, which it returns: libcosim's ``do_step`` shape.  A fixed-step
algorithm advances one step of the grid ``t_k = start + k * step`` (the last one ends exactly at ``stop``); an
adaptive one chooses the length by an error estimate.  Whoever drives the run (:mod:`cosim.execution.run`, the
lock-step runner, a test) only calls :meth:`MasterAlgorithm.advance` and never asks which kind it holds.

A new algorithm is a subclass of :class:`MasterAlgorithm` (or of :class:`cosim.master.algorithms.FixedStep`
when it steps the grid) registered in :data:`cosim.master.registry.ALGORITHMS`.
"""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar, Mapping, Sequence

from cosim.master.loops import Coupling
from cosim.master.transfers import Link, TransferFactory, group_transfers
from cosim.units.protocol import SimulationEnded, Unit, UnitError


def step_count(start: float, stop: float, h: float) -> int:
    """Number of communication steps from start to stop; the last may be shorter.

    A ratio within 1e-9 of a whole number counts as that number, so 1.0/0.1 gives 10 steps, not 11.
    """
    ratio = (stop - start) / h
    nearest = round(ratio)
    if abs(ratio - nearest) <= 1e-9 * max(1.0, abs(ratio)):
        return int(nearest)
    return int(math.ceil(ratio))


@dataclass(frozen=True)
class StepGrid:
    """The communication points ``t_k = start + k * step`` for k = 0 .. n, the last one exactly ``stop``.

    Times are computed from whole step counts, never summed, so long runs do not drift.
    """

    start: float
    stop: float
    step: float
    steps: int = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "steps", step_count(self.start, self.stop, self.step))

    @classmethod
    def of(cls, experiment: Any) -> "StepGrid":
        """The grid of an experiment (anything with ``start``, ``stop`` and ``step``)."""
        return cls(experiment.start, experiment.stop, experiment.step)

    def time(self, k: int) -> float:
        """The time of communication point ``k`` (``stop`` from the last one on)."""
        return self.stop if k >= self.steps else self.start + k * self.step

    def index(self, t: float) -> int:
        """The communication point at time ``t`` (a time of this grid: the nearest whole step)."""
        return round((t - self.start) / self.step)


def _settle_nothing(t: float) -> None:
    pass


@dataclass(frozen=True)
class SystemView:
    """What an algorithm steps: ``units`` by name (a group of model-exchange units integrated together is one of
    them, :mod:`cosim.master.coupled_me`), their stepping ``order``, the ``links`` between their ports, the direct
    feed-through and loops among them (``coupling``, as indices into ``links``), how values move (``transfers``,
    called like :func:`cosim.master.transfers.group_transfers`) and what to solve inside the units at the start
    time (``settle``: loops within model-exchange groups).

    The lock-step runner binds the same algorithms to batches of points through its own ``transfers``.
    """

    units: Mapping[str, Any]
    order: Sequence[str]
    links: Sequence[Link]
    coupling: Coupling = Coupling()
    transfers: TransferFactory = group_transfers
    settle: Callable[[float], None] = _settle_nothing


def step_unit(unit: Unit, t: float, h: float) -> None:
    """``unit.do_step(t, h)``; any exception becomes a UnitError naming the unit and time."""
    try:
        unit.do_step(t, h)
    except (UnitError, SimulationEnded):
        raise
    except Exception as exc:  # a Python unit's own bug, reported like an FMU's error status
        raise UnitError.raised(unit.name, "do_step", exc, t) from exc


class MasterAlgorithm(abc.ABC):
    """The master-algorithm contract (module docstring): ``bind`` once, ``start`` once, ``advance`` until done.

    Class attributes say what the system check and the lock-step runner may rely on: ``solves_loops`` (the
    algorithm solves the algebraic loops of the view's coupling at every communication point; the system check
    refuses a system with loops for any other) and ``batchable`` (it touches its units only through their
    ``name`` and ``do_step(t, h)`` and moves values only through the view's transfers, so it can step batches of
    points together).
    """

    name: ClassVar[str] = "abstract"
    solves_loops: ClassVar[bool] = False
    batchable: ClassVar[bool] = False
    view: SystemView  # what bind() was given

    def __init__(self, experiment: Any = None) -> None:
        """Made for ``experiment``: its ``start``, ``stop``, ``step`` and the options the algorithm reads."""

    @abc.abstractmethod
    def bind(self, view: SystemView) -> None:
        """Keep ``view`` (as :attr:`view`) and resolve everything the steps need (transfers, loop solvers);
        after this no step looks up a name."""

    def start(self, t: float) -> None:
        """Called once after initialization, before the first step: make the outputs consistent at ``t``
        (the view's model-exchange groups settled; an algorithm that solves loops solves them first)."""
        self.view.settle(t)

    @abc.abstractmethod
    def advance(self, t: float) -> float:
        """Advance every unit from ``t`` to a time of the algorithm's choosing and return it (never past the
        experiment's stop time, exactly it for the last step).  Raises UnitError for a unit's failure and
        SimulationEnded when a unit ends the run (its ``time`` says where)."""

    def statistics(self) -> dict[str, Any] | None:
        """What the algorithm did beyond plain steps (the adaptive one's accepted and rejected steps), or None."""
        return None

    def free(self) -> None:
        """Release what the algorithm holds in the units (saved states); called before the units terminate."""
