"""Direct feed-through between units: its dependency order, and algebraic loops solved at each communication point.

An output that depends *directly* on an input (without a step in between) must be evaluated after that input
is set.  Over a system this makes a graph whose nodes are ports, ``(unit, variable)``: a link is an edge
output -> input, a unit's declared feed-through an edge input -> output.  :func:`analyse_coupling` orders it:

- an input that feeds an output directly is a *feed* block: its links are run before anything reads that output;
- a cycle (a strongly connected component, also a unit feeding its own input) is an algebraic :class:`Loop`.
  Its *tearing variables* are the inputs of the links cut to make the rest acyclic (a greedy choice, few cuts);
  given values x there, running the loop's other links in order and reading the cut links' sources gives
  G(x), and the loop holds when the residual G(x) - x is zero.

:class:`LoopSolver` solves it with Newton's method on the residual (its Jacobian from the units' directional
derivatives where every unit on the loop gives them (FMI getDirectionalDerivative, :class:`LoopDerivatives`), else
by finite differences; kept from one communication point to the next while it still contracts, backtracking
steps), falling back to fixed-point
iteration x <- G(x); ``"fixed-point"`` uses only the latter.  The first solve starts from the tearing variables'
start values (the system does not carry the cut links at initialization), as OpenModelica's KINSOL does, each
later one from the last two solutions extrapolated to its time (Newton is local: it follows the solution branch
it starts on, so this is which root a loop with several reaches).  A loop that does not converge within the
iteration limit raises :class:`LoopError` (a UnitError: the run becomes a failed row naming the loop and its
residual), never a hang.  Units are only set and read (FMI 2/3 allow set/get between steps; a Python unit
recomputes its outputs in ``compute_outputs``), never stepped, so solving costs no simulated time.

:class:`CouplingRuntime` binds the blocks to live units: ``propagate(t)`` runs every block in dependency order
(zero-delay feed-through at a communication point), ``solver(loop)`` gives one loop's solver.
This layer knows units and links; the system layer (:mod:`cosim.system.stepping`) says which inputs feed
which outputs (after the spec's own ``feedthrough`` declarations) and calls :func:`analyse_coupling`.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from cosim.errors import LoopError
from cosim.master.transfers import Link, Transfer, TransferFactory, group_transfers
from cosim.units.protocol import ElementRef, Unit

Node = tuple[str, str]  # (unit, variable)
METHODS = ("newton", "fixed-point")  # the spec's experiment.loop_solver.method
JACOBIANS = ("auto", "finite-differences")  # the spec's experiment.loop_solver.jacobian


@dataclass(frozen=True)
class LoopSettings:
    """How loops are solved: ``method`` (``newton``, with a fixed-point fallback, or ``fixed-point``),
    ``tolerance`` (every residual element within ``tolerance * (1 + |x|)``) and ``max_iterations`` (per
    method and communication point), ``jacobian`` (``auto`` or ``finite-differences``)."""

    method: str = "newton"
    tolerance: float = 1e-10
    max_iterations: int = 50
    # Newton's Jacobian: "auto" (the units' directional derivatives where every unit on the loop gives them,
    # finite differences otherwise) or "finite-differences" (always)
    jacobian: str = "auto"


@dataclass(frozen=True)
class Loop:
    """One algebraic loop, as indices into the system's links.

    ``links``: the loop's links that are not cut, in evaluation order; ``torn``: the cut links (their targets
    are the tearing variables); ``entries``: links from outside into the loop's inputs, run before solving.
    ``units`` are the members in the system's unit order, ``ports`` every port on the loop and ``tearing`` the
    tearing variables, as ``unit.variable``.
    """

    units: tuple[str, ...]
    links: tuple[int, ...]
    torn: tuple[int, ...]
    entries: tuple[int, ...]
    ports: tuple[str, ...]
    tearing: tuple[str, ...]

    @property
    def name(self) -> str:
        """``loop through units a, b (tearing a.u)``: how messages name the loop."""
        return f"loop through units {', '.join(self.units)} (tearing {', '.join(self.tearing)})"


@dataclass(frozen=True)
class Coupling:
    """The direct feed-through of a system in dependency order, and how its loops are solved.

    ``blocks`` come in topological order; each is a tuple of link indices feeding one input that feeds an
    output directly, or a :class:`Loop`.  ``direct`` holds every link index in them.
    """

    blocks: tuple[tuple[int, ...] | Loop, ...] = ()
    settings: LoopSettings = field(default_factory=LoopSettings)

    @property
    def loops(self) -> tuple[Loop, ...]:
        return tuple(b for b in self.blocks if isinstance(b, Loop))

    @property
    def direct(self) -> frozenset[int]:
        found: set[int] = set()
        for b in self.blocks:
            found.update((*b.links, *b.torn, *b.entries) if isinstance(b, Loop) else b)
        return frozenset(found)


# The graph --------------------------------------------------------------------------------------------------

def strongly_connected(nodes: list[Any], edges: Mapping[Any, set[Any]]) -> list[list[Any]]:
    """Tarjan's algorithm, iterative; components come in reverse topological order."""
    index: dict[Any, int] = {}
    low: dict[Any, int] = {}
    on_stack: set[Any] = set()
    stack: list[Any] = []
    result: list[list[Any]] = []
    counter = 0
    for root in nodes:
        if root in index:
            continue
        work = [(root, iter(sorted(edges.get(root, ()), key=str)))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            advanced = False
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges.get(child, ()), key=str))))
                    advanced = True
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            if advanced:
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                result.append(component)
    return result


def is_cycle(component: list[Any], edges: Mapping[Any, set[Any]]) -> bool:
    """Whether a strongly connected component is a cycle: more than one node, or a node feeding itself."""
    return len(component) > 1 or component[0] in edges.get(component[0], ())


def port_graph(links: Sequence[Link], feedthrough: Iterable[tuple[str, str, str]]
               ) -> tuple[list[Node], dict[Node, set[Node]]]:
    """Nodes (in first-seen order) and edges of the port graph: each link output -> input, each
    ``(unit, input, output)`` of ``feedthrough`` input -> output."""
    edges: dict[Node, set[Node]] = {}
    nodes: list[Node] = []

    def add(a: Node, b: Node) -> None:
        for n in (a, b):
            if n not in edges:
                edges[n] = set()
                nodes.append(n)
        edges[a].add(b)

    for link in links:
        add(_source(link), _target(link))
    for unit, inp, out in feedthrough:
        add((unit, inp), (unit, out))
    return nodes, edges


def analyse_coupling(unit_order: Sequence[str], links: Sequence[Link], feedthrough: Iterable[tuple[str, str, str]],
                     settings: LoopSettings = LoopSettings()) -> Coupling:
    """The feed blocks and loops of a system, in dependency order (see the module docstring).

    ``feedthrough`` lists ``(unit, input, output)``: the output depends directly on the (connected) input.
    ``unit_order`` (the spec's) makes every choice deterministic.
    """
    feedthrough = list(feedthrough)
    nodes, edges = port_graph(links, feedthrough)
    feeds_output = {(unit, inp) for unit, inp, _ in feedthrough}
    into: dict[Node, list[int]] = {}
    for i, link in enumerate(links):
        into.setdefault(_target(link), []).append(i)
    rank = {name: i for i, name in enumerate(unit_order)}
    blocks: list[tuple[int, ...] | Loop] = []
    for component in reversed(strongly_connected(nodes, edges)):  # topological order
        if is_cycle(component, edges):
            blocks.append(_loop(set(component), links, feedthrough, rank))
        elif component[0] in feeds_output and component[0] in into:
            blocks.append(tuple(into[component[0]]))
    return Coupling(tuple(blocks), settings)


def _source(link: Link) -> Node:
    return link.source.unit, link.source.refs[0].variable


def _target(link: Link) -> Node:
    return link.target.unit, link.target.refs[0].variable


def _loop(members: set[Node], links: Sequence[Link], feedthrough: Sequence[tuple[str, str, str]],
          rank: Mapping[str, int]) -> Loop:
    """The loop on ``members``: greedy tearing, then the evaluation order of the links left."""
    inner = [i for i, link in enumerate(links) if _source(link) in members and _target(link) in members]
    entries = tuple(i for i, link in enumerate(links) if _target(link) in members and _source(link) not in members)
    ft: dict[Node, set[Node]] = {n: set() for n in members}  # input -> the outputs it feeds directly
    for unit, inp, out in feedthrough:
        if (unit, inp) in members and (unit, out) in members:
            ft[(unit, inp)].add((unit, out))
    link_nodes = {i: (_source(links[i]), _target(links[i])) for i in inner}

    def key(n: Node) -> tuple[int, str, str]:  # spec order, then names
        return rank.get(n[0], len(rank)), n[0], n[1]

    order = sorted(members, key=key)
    cut: set[int] = set()

    def remaining(cuts: set[int]) -> dict[Node, set[Node]]:
        graph = {n: set(ft[n]) for n in members}
        for i, (a, b) in link_nodes.items():
            if i not in cuts:
                graph[a].add(b)
        return graph

    def still_cyclic(cuts: set[int]) -> int:
        """How many ports are still on a cycle once ``cuts`` are cut."""
        graph = remaining(cuts)
        return sum(len(c) for c in strongly_connected(order, graph) if is_cycle(c, graph))

    while True:  # greedy: cut the links into the one input that leaves the fewest ports on a cycle, and again
        graph = remaining(cut)
        cycles = [c for c in strongly_connected(order, graph) if is_cycle(c, graph)]
        if not cycles:
            break
        inside = set(cycles[0])
        candidates: dict[Node, set[int]] = {}  # an input on this cycle -> its links from the cycle
        for i, (a, b) in link_nodes.items():
            if i not in cut and a in inside and b in inside:
                candidates.setdefault(b, set()).add(i)
        # fewest ports left on a cycle, then fewest tearing values, then most paths closed, then spec order
        scores = {n: (still_cyclic(cut | into_n), sum(len(links[i].target.refs) for i in into_n),
                      -len(into_n) * len(ft[n] & inside), key(n)) for n, into_n in candidates.items()}
        cut |= candidates[min(scores, key=scores.__getitem__)]
    graph = remaining(cut)
    position = {c[0]: p for p, c in enumerate(reversed(strongly_connected(order, graph)))}
    ordered = tuple(sorted((i for i in inner if i not in cut), key=lambda i: (position[link_nodes[i][1]], i)))
    torn = tuple(sorted(cut))
    units = tuple(sorted({n[0] for n in members}, key=lambda u: (rank.get(u, len(rank)), u)))
    ports = tuple(f"{u}.{v}" for u, v in sorted(members, key=key))
    tearing = tuple(dict.fromkeys(f"{u}.{v}" for u, v in (link_nodes[i][1] for i in torn)))
    return Loop(units, ordered, torn, entries, ports, tearing)


# Solving ----------------------------------------------------------------------------------------------------

def _in_order(units: Mapping[str, Unit], links: Sequence[Link]) -> list[Transfer]:
    """Transfers for ``links`` in their order, consecutive links between the same two units as one."""
    transfers: list[Transfer] = []
    group: list[Link] = []
    for link in links:
        if group and (group[-1].source.unit, group[-1].target.unit) != (link.source.unit, link.target.unit):
            transfers.append(Transfer(units[group[0].source.unit], units[group[0].target.unit], group))
            group = []
        group.append(link)
    if group:
        transfers.append(Transfer(units[group[0].source.unit], units[group[0].target.unit], group))
    return transfers


class LoopSolver:
    """Solves one :class:`Loop` of live units; ``solve(t)`` leaves every input of the loop at the solution.

    ``evaluations`` counts the evaluations of G (each: set the tearing variables, run the loop's links, read)
    and ``iterations`` the iterations of the last solve, for tests and benchmarks.
    """

    def __init__(self, loop: Loop, units: Mapping[str, Unit], links: Sequence[Link], settings: LoopSettings,
                 transfers: TransferFactory | None = None):
        """``transfers``: how the loop's values are carried (``transfers(units, [link])``: objects with
        ``read()``, ``write(values)``, ``run()``), e.g. inside a group integrated by one solver; default: the
        units' own get and set (:class:`~cosim.master.transfers.Transfer`)."""
        self.loop = loop
        self.settings = settings
        if transfers is None:
            self._entries = group_transfers(units, [links[i] for i in loop.entries])
            self._torn = [Transfer(units[links[i].source.unit], units[links[i].target.unit], [links[i]])
                          for i in loop.torn]
            self._inner = _in_order(units, [links[i] for i in loop.links])
        else:
            self._entries = [t for i in loop.entries for t in transfers(units, [links[i]])]
            self._torn = [transfers(units, [links[i]])[0] for i in loop.torn]
            self._inner = [t for i in loop.links for t in transfers(units, [links[i]])]
        bounds = np.cumsum([0] + [len(links[i].target.refs) for i in loop.torn])
        self._slices = [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]
        self._jacobian: np.ndarray | None = None  # of the residual, kept while Newton steps still contract
        self._solutions: deque[tuple[float, np.ndarray]] = deque(maxlen=2)  # (t, x) of the last two solves
        # the Jacobian from the units' directional derivatives, when every unit on the loop gives them
        self.derivatives = (LoopDerivatives.of(loop, units, links) if settings.jacobian == "auto" and
                            settings.method == "newton" else None)
        self._at: np.ndarray | None = None  # the x of the last evaluation (where the units' inputs are now)
        self.evaluations = 0
        self.jacobians = 0  # Jacobians made (by derivatives or finite differences)
        self.iterations = 0
        self.newton_stop = ""  # why the last Newton iteration stopped short, for the message

    def _start_values(self) -> np.ndarray:
        """The tearing variables as their units hold them now (the cut links' targets, read back); what the cut
        links carry (their sources, converted) where a transfer does not say its target."""
        values = []
        for transfer in self._torn:
            target, selection = getattr(transfer, "target", None), getattr(transfer, "target_selection", None)
            if target is None or selection is None:
                return self._read()
            values.append(np.array(target.get(selection), dtype=float).reshape(-1))
        return np.concatenate(values)

    def _read(self) -> np.ndarray:
        """The cut links' values now (their sources' outputs, converted)."""
        return np.concatenate([np.array(t.read(), dtype=float).reshape(-1) for t in self._torn])

    def _evaluate(self, x: np.ndarray) -> np.ndarray:
        """G(x): the tearing variables set to ``x``, the loop's links run in order, the cut links read."""
        for transfer, part in zip(self._torn, self._slices):
            transfer.write(x[part].tolist())
        for transfer in self._inner:
            transfer.run()
        self.evaluations += 1
        self._at = x
        return self._read()

    def _converged(self, r: np.ndarray, x: np.ndarray) -> bool:
        """Every |r_i| <= tolerance * (1 + |x_i|) (false for NaN); on lists: loops are small, numpy's per-call
        cost would be most of the solve."""
        tolerance = self.settings.tolerance
        return all(abs(ri) <= tolerance * (1.0 + abs(xi)) for ri, xi in zip(r.tolist(), x.tolist()))

    def solve(self, t: float) -> None:
        """Solve the loop at time ``t``; raises LoopError when it does not converge (UnitError of a unit as is)."""
        for transfer in self._entries:
            transfer.run()
        x = self._guess(t)
        g = self._evaluate(x)
        r = g - x
        self.iterations = 0
        if self._converged(r, x):
            self._solutions.append((t, x))
            return
        newton_iterations = 0
        best = (_size(r), x)
        if self.settings.method == "newton":
            done, x, r, newton_iterations, best = self._newton(x, g, r, best)
            if done:
                self._solutions.append((t, x))
                return
        done, x, fixed_iterations, best = self._fixed_point(best[1], best)
        if done:
            self._solutions.append((t, x))
            return
        tried = (f"{newton_iterations} Newton iteration(s) ({self.newton_stop}), then "
                 if self.settings.method == "newton" else "")
        raise LoopError(self.loop.name, f"did not converge: largest residual {best[0]:.3g} (tolerance "
                                        f"{self.settings.tolerance:g}) after {tried}{fixed_iterations} fixed-point "
                                        "iteration(s)", t)

    @property
    def solution(self) -> np.ndarray | None:
        """The tearing values of the last solve (None before the first)."""
        return self._solutions[-1][1] if self._solutions else None

    def _guess(self, t: float) -> np.ndarray:
        """Where to start at ``t``: at the first solve the tearing variables' values now (their start values:
        the system does not carry the cut links at initialization), as OpenModelica's KINSOL starts from the
        start values; then the last two solutions extrapolated linearly (the last one alone after the first
        solve), so a smooth solution is followed closely.  Newton is local: this choice is which root a loop
        with several solutions reaches."""
        if not self._solutions:
            return self._start_values()
        t1, x1 = self._solutions[-1]
        if len(self._solutions) == 1 or t == t1:
            return x1.copy()
        t0, x0 = self._solutions[0]
        return x1 + (x1 - x0) * ((t - t1) / (t1 - t0)) if t1 != t0 else x1.copy()

    def _newton(self, x: np.ndarray, g: np.ndarray, r: np.ndarray, best: tuple[float, np.ndarray]
                ) -> tuple[bool, np.ndarray, np.ndarray, int, tuple[float, np.ndarray]]:
        """Newton on r(x) = G(x) - x from ``x``; (converged, x, r, iterations, best (residual, x) seen)."""
        jacobian, fresh = self._jacobian, False
        iterations, self.newton_stop = 0, "iteration limit"
        while iterations < self.settings.max_iterations:
            if jacobian is None:
                jacobian, fresh = self.jacobian_at(x, g), True
            dx = _newton_step(jacobian, r)
            if dx is None or not all(map(math.isfinite, dx.tolist())):
                if fresh:  # singular at this x: leave it to the fixed-point iteration
                    self.newton_stop = "singular Jacobian"
                    break
                jacobian = None
                continue
            iterations += 1
            size, scale = _size(r), 1.0
            while True:  # backtracking: halve the step until the residual shrinks (at most 4 times)
                x_new = x + scale * dx
                g_new = self._evaluate(x_new)
                r_new = g_new - x_new
                size_new = _size(r_new)
                if size_new < size or scale <= 1.0 / 16:
                    break
                scale /= 2
            if size_new < best[0]:
                best = (size_new, x_new)
            if not size_new < size:
                if fresh:
                    self.newton_stop = "no step reduced the residual"
                    break
                jacobian = None  # an old Jacobian that no longer leads down: make a new one here
                continue
            x, g, r = x_new, g_new, r_new
            if self._converged(r, x):
                self._jacobian, self.iterations = jacobian, iterations
                return True, x, r, iterations, best
            if size_new > 0.25 * size:  # contracting slowly: the Jacobian is out of date
                jacobian = None
            fresh = False
        self._jacobian = None
        return False, x, r, iterations, best

    def jacobian_at(self, x: np.ndarray, g: np.ndarray) -> np.ndarray:
        """The residual's Jacobian dG/dx - I at ``x`` (``g`` = G(x)): from the units' directional derivatives when
        they give them (the units are put at ``x`` first if the last evaluation was elsewhere), else by finite
        differences."""
        self.jacobians += 1
        if self.derivatives is None:
            return self._finite_differences(x, g)
        if self._at is None or (self._at is not x and not np.array_equal(self._at, x)):
            self._evaluate(x)
        return self.derivatives.jacobian(len(x)) - np.eye(len(x))

    def _finite_differences(self, x: np.ndarray, g: np.ndarray) -> np.ndarray:
        """The residual's Jacobian dG/dx - I by forward differences (one evaluation of G per tearing value)."""
        n = len(x)
        jacobian = np.empty((n, n))
        for j in range(n):
            delta = math.sqrt(np.finfo(float).eps) * max(1.0, abs(x[j]))
            shifted = x.copy()
            shifted[j] += delta
            jacobian[:, j] = (self._evaluate(shifted) - g) / delta
        jacobian -= np.eye(n)
        return jacobian

    def _fixed_point(self, x: np.ndarray, best: tuple[float, np.ndarray]
                     ) -> tuple[bool, np.ndarray, int, tuple[float, np.ndarray]]:
        """x <- G(x) from ``x``; (converged, the last x, iterations, best (residual, x) seen)."""
        g = self._evaluate(x)
        for iterations in range(1, self.settings.max_iterations + 1):
            x = g
            g = self._evaluate(x)
            r = g - x
            if _size(r) < best[0]:
                best = (_size(r), x)
            if self._converged(r, x):
                self.iterations = iterations
                return True, x, iterations, best
        return False, x, self.settings.max_iterations, best


def _newton_step(jacobian: np.ndarray, r: np.ndarray) -> np.ndarray | None:
    """dx solving ``jacobian @ dx = -r``; None when the Jacobian is singular (a scalar loop without numpy's solver)."""
    if len(r) == 1:
        return -r / jacobian[0, 0] if jacobian[0, 0] != 0.0 else None
    try:
        return np.linalg.solve(jacobian, -r)
    except np.linalg.LinAlgError:
        return None


def _size(r: np.ndarray) -> float:
    """The largest residual element; infinite when any is not finite (never 'smaller' than a finite one)."""
    values = [abs(v) for v in r.tolist()]
    largest = max(values, default=0.0)
    return largest if math.isfinite(largest) and all(v == v for v in values) else math.inf


class LoopDerivatives:
    """dG/dx of a loop from its units' directional derivatives (the chain rule along the loop's links).

    Each unit on the loop gives the derivatives of its loop outputs with respect to its loop inputs
    (:meth:`~cosim.units.protocol.Unit.differentiator`: FMI ``getDirectionalDerivative``), one call per loop input
    (a column of its local Jacobian).  Seeding the tearing variables with the identity, the loop's links are
    followed in their evaluation order: an input gets ``factor`` times its source output's row, an output the
    unit's local Jacobian times its inputs' rows; the cut links' sources give dG/dx.  ``calls`` counts the
    units' derivative calls (a finite-difference Jacobian costs one evaluation of G, a set and a get per link,
    per tearing value instead).
    """

    def __init__(self, loop: Loop, links: Sequence[Link], functions: dict[str, Any],
                 inputs: dict[str, list[ElementRef]], outputs: dict[str, list[ElementRef]]):
        self._links = links
        self._loop = loop
        self._functions = functions
        self._inputs = inputs
        self._outputs = {u: {r: i for i, r in enumerate(refs)} for u, refs in outputs.items()}
        self.calls = 0

    @classmethod
    def of(cls, loop: Loop, units: Mapping[str, Unit], links: Sequence[Link]) -> "LoopDerivatives | None":
        """The derivatives of ``loop``, or None when a unit on it gives none for its loop ports."""
        inputs: dict[str, list[ElementRef]] = {}
        outputs: dict[str, list[ElementRef]] = {}
        for i in (*loop.links, *loop.torn):
            link = links[i]
            for ref in link.source.refs:
                if ref not in outputs.setdefault(link.source.unit, []):
                    outputs[link.source.unit].append(ref)
            for ref in link.target.refs:
                if ref not in inputs.setdefault(link.target.unit, []):
                    inputs[link.target.unit].append(ref)
        functions = {}
        for unit in outputs:
            function = units[unit].differentiator(outputs[unit], inputs.get(unit, []))
            if function is None:
                return None
            functions[unit] = function
        return cls(loop, links, functions, inputs, outputs)

    def _local(self, unit: str) -> np.ndarray:
        """The unit's d(loop outputs)/d(loop inputs) now: one derivative call per input."""
        n = len(self._inputs.get(unit, []))
        columns = []
        for j in range(n):
            seed = [0.0] * n
            seed[j] = 1.0
            columns.append(self._functions[unit](seed))
            self.calls += 1
        return np.column_stack(columns) if columns else np.zeros((len(self._outputs[unit]), 0))

    def jacobian(self, n: int) -> np.ndarray:
        """dG/dx (n by n) at the units' current inputs (the point of the last evaluation of G)."""
        rows: dict[tuple[str, ElementRef], np.ndarray] = {}
        k = 0
        for i in self._loop.torn:  # the tearing variables, in the order of x
            for ref in self._links[i].target.refs:
                rows[(self._links[i].target.unit, ref)] = np.eye(n)[k]
                k += 1
        local: dict[str, np.ndarray] = {}
        zero = np.zeros(n)

        def output_row(unit: str, ref: ElementRef) -> np.ndarray:
            if unit not in local:
                local[unit] = self._local(unit)
            inputs = self._inputs.get(unit, [])
            below = np.array([rows.get((unit, r), zero) for r in inputs]).reshape(len(inputs), n)
            row: np.ndarray = local[unit][self._outputs[unit][ref]] @ below
            return row

        for i in self._loop.links:  # evaluation order: an input's row is set before its unit's outputs are used
            link = self._links[i]
            for source, target in zip(link.source.refs, link.target.refs):
                rows[(link.target.unit, target)] = link.factor * output_row(link.source.unit, source)
        return np.array([self._links[i].factor * output_row(self._links[i].source.unit, ref)
                         for i in self._loop.torn for ref in self._links[i].source.refs]).reshape(n, n)


class CouplingRuntime:
    """A :class:`Coupling` bound to live units: its feed blocks as transfers (made by ``transfers``, as a master
    algorithm's), its loops as solvers (which set and read units themselves)."""

    def __init__(self, coupling: Coupling, units: Mapping[str, Unit], links: Sequence[Link],
                 transfers: TransferFactory = group_transfers):
        self.coupling = coupling
        self.solvers = {loop: LoopSolver(loop, units, links, coupling.settings) for loop in coupling.loops}
        self._actions: list[Any] = []
        for block in coupling.blocks:
            if isinstance(block, Loop):
                self._actions.append(self.solvers[block].solve)
            else:
                self._actions.extend(_RunAt(t) for t in transfers(units, [links[i] for i in block]))

    def propagate(self, t: float) -> None:
        """Run every feed block and solve every loop, in dependency order, at time ``t``."""
        for action in self._actions:
            action(t)

    def solver(self, loop: Loop) -> LoopSolver:
        return self.solvers[loop]


class _RunAt:
    """A transfer called like a loop's solve (with the time, which it does not need)."""

    __slots__ = ("run",)

    def __init__(self, transfer: Transfer):
        self.run = transfer.run  # any object with run(): a Transfer, or the lock-step runner's

    def __call__(self, t: float) -> None:
        self.run()
