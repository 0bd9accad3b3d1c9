"""Master algorithms: Gauss-Seidel, Jacobi (zero-delay feed-through) and Jacobi with delay, with fixed
steps; ``adaptive`` (steps chosen by an error estimate) is in :mod:`cosim.master.adaptive`.

An algorithm is bound to live units once (:meth:`MasterAlgorithm.bind`),
which resolves every connection into a :class:`Transfer` with pre-built
selections; after that, :meth:`step` does no name lookup and no I/O.
Time is counted in whole steps by the caller (``t_k = start + k*h``), so
long runs do not drift.
"""

from __future__ import annotations

from typing import Any, Callable, Mapping, Sequence

from cosim.master.loops import Coupling, CouplingRuntime
from cosim.master.transfers import Link, Port, Transfer, TransferFactory, group_transfers  # noqa: F401  (re-exported: their old place)
from cosim.units.protocol import SimulationEnded, Unit, UnitError


def step_unit(unit: Unit, t: float, h: float) -> None:
    """``unit.do_step(t, h)``; any exception becomes a UnitError naming the unit and time."""
    try:
        unit.do_step(t, h)
    except (UnitError, SimulationEnded):
        raise
    except Exception as exc:  # a Python unit's own bug, reported like an FMU's error status
        raise UnitError.raised(unit.name, "do_step", exc, t) from exc


class MasterAlgorithm:
    """Base: ``bind`` to live units, ``start(t)`` once at the start time, then ``step(t, h)`` advances all of them.

    ``coupling`` (:class:`cosim.master.loops.Coupling`): the system's direct feed-through and algebraic loops,
    given to ``bind`` only when the algorithm says ``solves_loops`` (it then solves the loops at every
    communication point); the system check refuses a system with loops for any other algorithm, whose ``bind``
    may keep the three arguments.

    An algorithm with ``variable_step = True`` chooses its own steps: the run gives it the experiment (start,
    stop, step, options) with ``configure(experiment)`` and asks its ``advance(t)`` for each step (see
    :mod:`cosim.master.adaptive`).

    ``batchable``: the algorithm uses its units only through their ``name`` and ``do_step(t, h)`` and moves
    values only through the transfers that ``bind``'s ``transfers`` factory makes (called like
    :func:`group_transfers`, ``transfers(units, links)``), so it can be bound to other stepping objects
    than units: the lock-step runner (:mod:`cosim.execution.lockstep`) binds it to batches of K points with
    transfers that move all K rows at once. Others (the default) run point by point.
    """

    name = "abstract"
    solves_loops = False
    variable_step = False
    batchable = False

    def bind(self, units: Mapping[str, Unit], order: Sequence[str], connections: Sequence[Link],
             coupling: Coupling | None = None, transfers: TransferFactory = group_transfers) -> None:
        raise NotImplementedError

    def start(self, t: float) -> None:
        """Called once after initialization, before the first step: outputs consistent at ``t`` (default: as they are)."""

    def step(self, t: float, h: float) -> None:
        raise NotImplementedError


class GaussSeidel(MasterAlgorithm):
    """Units step one after another in ``order``; each first takes its inputs
    from the *latest* outputs, so a unit later in the order sees the values its
    sources computed in this same step.  An algebraic loop is solved as soon as
    its last unit has stepped, so the units after it see the solution."""

    name = "gauss-seidel"
    solves_loops = True
    batchable = True

    def bind(self, units: Mapping[str, Unit], order: Sequence[str], connections: Sequence[Link],
             coupling: Coupling | None = None, transfers: TransferFactory = group_transfers) -> None:
        self._plan = []
        for name in order:
            incoming = [c for c in connections if c.target.unit == name]
            self._plan.append((units[name], transfers(units, incoming)))
        self._loops = (CouplingRuntime(coupling, units, connections, transfers)
                       if coupling and coupling.loops else None)
        if self._loops is not None:  # only then the step that solves loops (a system without any pays nothing)
            last = {loop: max(order.index(u) for u in loop.units) for loop in coupling.loops}
            self._solve_after = [[self._loops.solver(loop).solve for loop in coupling.loops if last[loop] == i]
                                 for i in range(len(order))]
            self.step = self._step_solving_loops  # type: ignore[method-assign]

    def start(self, t: float) -> None:
        if self._loops is not None:
            self._loops.propagate(t)

    def step(self, t: float, h: float) -> None:
        for unit, transfers in self._plan:
            for transfer in transfers:
                transfer.run()
            step_unit(unit, t, h)

    def _step_solving_loops(self, t: float, h: float) -> None:
        for (unit, transfers), solves in zip(self._plan, self._solve_after):
            for transfer in transfers:
                transfer.run()
            step_unit(unit, t, h)
            for solve in solves:
                solve(t + h)


class Jacobi(MasterAlgorithm):
    """All units step from the outputs at ``t``: step every unit (in any order;
    they are independent), then read every output and set every input.

    The transfers come at the end of the step, not at its start: the inputs a
    unit steps from are the same (initialization already set them for the
    first step), but whoever reads the units after ``step`` (the trace, the
    objectives) sees inputs consistent with the outputs at ``t + h``, also at
    the stop time.  A unit that ends the simulation skips the transfers.

    The inputs that feed outputs directly are set first, in dependency order,
    and algebraic loops are solved (zero-delay feed-through); then the others,
    from outputs now current: a chain of direct feed-through units sees the
    current values at each communication point, as under Gauss-Seidel.  ``jacobi-delayed``
    (:class:`JacobiDelayed`) reads every output before setting any input, so
    each link into a direct feed-through unit adds one step of delay.
    """

    name = "jacobi"
    solves_loops = True
    batchable = True

    def bind(self, units: Mapping[str, Unit], order: Sequence[str], connections: Sequence[Link],
             coupling: Coupling | None = None, transfers: TransferFactory = group_transfers) -> None:
        direct = coupling.direct if coupling is not None else frozenset()
        # links into direct inputs are set in dependency order (propagate), then the others all at once
        self._transfers = transfers(units, [c for i, c in enumerate(connections) if i not in direct])
        self._units = [units[n] for n in order]
        self._coupling = CouplingRuntime(coupling, units, connections, transfers) if direct else None
        self._loops = bool(coupling and coupling.loops)

    def start(self, t: float) -> None:
        if self._loops:  # initialization already set every input in dependency order: only loops remain
            self._coupling.propagate(t)

    def step(self, t: float, h: float) -> None:
        try:  # step_unit's rule, with the try around the loop: one Python call less per unit and step
            for unit in self._units:
                unit.do_step(t, h)
        except (UnitError, SimulationEnded):
            raise
        except Exception as exc:
            raise UnitError.raised(unit.name, "do_step", exc, t) from exc
        if self._coupling is not None:  # the direct feed-through inputs first, in dependency order; loops solved
            self._coupling.propagate(t + h)
        # each transfer reads into its source's buffer, so all reads stay valid until the writes
        values = [transfer.read() for transfer in self._transfers]
        for transfer, v in zip(self._transfers, values):
            transfer.write(v)


class JacobiDelayed(Jacobi):
    """Jacobi as it was before zero-delay feed-through: every output is read before any input is set, so each
    link into a direct feed-through unit adds one step of delay; refuses algebraic loops."""

    name = "jacobi-delayed"
    solves_loops = False

    def bind(self, units: Mapping[str, Unit], order: Sequence[str], connections: Sequence[Link],
             coupling: Coupling | None = None, transfers: TransferFactory = group_transfers) -> None:
        super().bind(units, order, connections, None, transfers)


class AdaptiveEntry:
    """The adaptive algorithm's entry in ALGORITHMS: its class attributes, and calling it makes a
    :class:`cosim.master.adaptive.Adaptive` (imported then: that module builds on the classes above)."""

    name = "adaptive"
    solves_loops = True
    variable_step = True

    def __new__(cls, experiment: Any = None) -> Any:  # type: ignore[misc]
        from cosim.master.adaptive import Adaptive

        return Adaptive(experiment)


# the one list of master algorithm names (each maps to a class; a variable-step one takes the experiment)
ALGORITHMS: dict[str, Callable[..., MasterAlgorithm]] = {
    GaussSeidel.name: GaussSeidel, Jacobi.name: Jacobi, JacobiDelayed.name: JacobiDelayed,
    AdaptiveEntry.name: AdaptiveEntry}
DEFAULT_ALGORITHM = GaussSeidel.name


def make_algorithm(name: str, experiment: Any = None) -> MasterAlgorithm:
    """The algorithm called ``name``, for ``experiment`` (start, stop, step, options; needed by the adaptive
    algorithm); raises ValueError for an unknown name or options that cannot work."""
    try:
        factory = ALGORITHMS[name]
    except KeyError:
        raise ValueError(f"unknown master algorithm '{name}'; use one of {', '.join(ALGORITHMS)}") from None
    return factory(experiment) if getattr(factory, "variable_step", False) else factory()
