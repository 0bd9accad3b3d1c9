"""The fixed-step master algorithms: Gauss-Seidel, Jacobi (zero-delay feed-through) and Jacobi with delay.

Each advances the system one communication step of the experiment's grid (:class:`~cosim.master.contract.StepGrid`)
per :meth:`~cosim.master.contract.MasterAlgorithm.advance`; ``step(t, h)`` is that step of any length, which the
adaptive algorithm (:mod:`cosim.master.adaptive`) uses to take the steps it chooses.  ``bind`` resolves every link
into a transfer with pre-built selections, so a step does no name lookup and no I/O.
"""

from __future__ import annotations

from typing import Any, Sequence

from cosim.master.contract import MasterAlgorithm, StepGrid, SystemView, step_unit
from cosim.master.loops import CouplingRuntime
from cosim.units.protocol import SimulationEnded, UnitError


class FixedStep(MasterAlgorithm):
    """A master algorithm on the experiment's grid of communication points: ``advance(t)`` takes the grid's step
    from ``t`` with :meth:`step`, which subclasses implement.  ``experiment`` (anything with ``start``, ``stop``
    and ``step``) gives the grid; an algorithm made without one can only :meth:`step` (the adaptive algorithm's
    base, a test)."""

    def __init__(self, experiment: Any = None):
        self.grid = StepGrid.of(experiment) if experiment is not None else None

    def advance(self, t: float) -> float:
        grid = self.grid
        if grid is None:
            raise ValueError(f"the {self.name} algorithm was made without an experiment: it has no steps to advance")
        k = round((t - grid.start) / grid.step) + 1  # grid.time(grid.index(t) + 1), without two calls per step
        t_next = grid.stop if k >= grid.steps else grid.start + k * grid.step
        self.step(t, t_next - t)
        return t_next

    def step(self, t: float, h: float) -> None:
        """Advance every unit from ``t`` by ``h`` (raises as :meth:`advance` does)."""
        raise NotImplementedError


class GaussSeidel(FixedStep):
    """Units step one after another in ``order``; each first takes its inputs
    from the *latest* outputs, so a unit later in the order sees the values its
    sources computed in this same step.  An algebraic loop is solved as soon as
    its last unit has stepped, so the units after it see the solution."""

    name = "gauss-seidel"
    solves_loops = True
    batchable = True

    def bind(self, view: SystemView) -> None:
        self.view = view
        units, order, coupling = view.units, view.order, view.coupling
        self._plan = []
        for name in order:
            incoming = [c for c in view.links if c.target.unit == name]
            self._plan.append((units[name], view.transfers(units, incoming)))
        self._loops = (CouplingRuntime(coupling, units, view.links, view.transfers)
                       if self.solves_loops and coupling.loops else None)
        self._solve_after: list[list[Any]] | None = None  # per unit in order: the loops solved once it has stepped
        self._after_solve: Sequence[Any] = ()  # the links into inputs that feed no output directly (start)
        if self._loops is not None:  # a system without loops pays nothing for them
            last = {loop: max(order.index(u) for u in loop.units) for loop in coupling.loops}
            self._solve_after = [[self._loops.solver(loop).solve for loop in coupling.loops if last[loop] == i]
                                 for i in range(len(order))]
            direct = coupling.direct
            self._after_solve = view.transfers(units, [c for i, c in enumerate(view.links) if i not in direct])

    def start(self, t: float) -> None:
        if self._loops is not None:
            self._loops.propagate(t)
            # initialization carried the values from before the solve: the rest of the inputs get the solution,
            # so the first row of the traces shows it (they feed no output directly: no output changes)
            for transfer in self._after_solve:
                transfer.run()
        super().start(t)

    def step(self, t: float, h: float) -> None:
        if self._solve_after is not None:
            self._step_solving_loops(t, h)
            return
        for unit, transfers in self._plan:
            for transfer in transfers:
                transfer.run()
            step_unit(unit, t, h)

    def _step_solving_loops(self, t: float, h: float) -> None:
        for (unit, transfers), solves in zip(self._plan, self._solve_after or ()):
            for transfer in transfers:
                transfer.run()
            step_unit(unit, t, h)
            for solve in solves:
                solve(t + h)


class Jacobi(FixedStep):
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
    zero_delay = True  # links into direct feed-through inputs are carried in dependency order

    def bind(self, view: SystemView) -> None:
        self.view = view
        units, links = view.units, view.links
        # without zero-delay feed-through (jacobi-delayed) every link is set at once, after all reads
        direct = view.coupling.direct if self.zero_delay else frozenset()
        # links into direct inputs are set in dependency order (propagate), then the others all at once
        self._transfers = view.transfers(units, [c for i, c in enumerate(links) if i not in direct])
        self._units = [units[n] for n in view.order]
        self._coupling = CouplingRuntime(view.coupling, units, links, view.transfers) if direct else None
        self._loops = self._coupling is not None and bool(view.coupling.loops)

    def start(self, t: float) -> None:
        if self._loops and self._coupling is not None:  # initialization set every input in dependency order:
            self._coupling.propagate(t)                  # only loops remain
            # the other inputs still hold what initialization carried before the loops were solved: the first
            # step starts from the solution, as every later one does (they feed no output directly)
            for transfer in self._transfers:
                transfer.run()
        super().start(t)

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
    zero_delay = False
