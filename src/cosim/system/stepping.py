"""Stepping order, direct feed-through and algebraic loops: the graph side of a system.

:func:`stepping_order` orders units for Gauss-Seidel (sources first, feedback
cycles kept together); :func:`feedthrough_coupling` finds the direct feed-through
in dependency order and the algebraic loops with their tearing variables (solved
by the master, :mod:`cosim.master.loops`); :func:`check_algebraic_loops` reports
the loops that cannot be solved and gives the connections in initialization
order; all use :func:`strongly_connected` (Tarjan).
"""

from __future__ import annotations

import heapq
from typing import Mapping

from cosim.errors import Problem
from cosim.master.loops import (
    Coupling,
    Loop,
    LoopSettings,
    analyse_coupling,
    port_graph,
    strongly_connected,
)
from cosim.master.registry import ALGORITHMS
from cosim.system.parts import Connection, SystemUnit
from cosim.units.protocol import parse_port


def stepping_order(names: list[str], connections: list[Connection]) -> list[str]:
    """Gauss-Seidel order: sources before the units they feed, spec order where free.

    Units in a feedback cycle form one group, ordered as in the spec; groups are
    sorted topologically, preferring the group whose first unit comes first.
    """
    edges: dict[str, set[str]] = {n: set() for n in names}
    for c in connections:
        if c.source.unit != c.target.unit:
            edges[c.source.unit].add(c.target.unit)
    components = [sorted(comp, key=names.index) for comp in strongly_connected(names, edges)]
    group_of = {n: i for i, comp in enumerate(components) for n in comp}
    successors: dict[int, set[int]] = {i: set() for i in range(len(components))}
    indegree = {i: 0 for i in range(len(components))}
    for a, targets in edges.items():
        for b in targets:
            ga, gb = group_of[a], group_of[b]
            if ga != gb and gb not in successors[ga]:
                successors[ga].add(gb)
                indegree[gb] += 1
    ready = [(names.index(components[i][0]), i) for i in indegree if indegree[i] == 0]
    heapq.heapify(ready)
    ordered: list[str] = []
    while ready:
        _, g = heapq.heappop(ready)
        ordered.extend(components[g])
        for nxt in successors[g]:
            indegree[nxt] -= 1
            if indegree[nxt] == 0:
                heapq.heappush(ready, (names.index(components[nxt][0]), nxt))
    return ordered


def feedthrough_edges(units: Mapping[str, SystemUnit], connections: list[Connection]) -> list[tuple[str, str, str]]:
    """``(unit, input, output)`` for every connected input an output depends on directly (the spec's
    ``feedthrough`` declarations applied; an output that declares nothing depends on every input, FMI's rule)."""
    connected_inputs = {(c.target.unit, c.target.variable.name) for c in connections}
    found = []
    for name, unit in units.items():
        for out in unit.description.outputs():
            for inp in unit.description.depends_on(out.name):
                # array elements: an element input depends on the whole array's dependencies
                if (name, inp) in connected_inputs or _element_input_connected(name, inp, connected_inputs):
                    found.append((name, inp, out.name))
    return found


def feedthrough_coupling(unit_order: list[str], units: Mapping[str, SystemUnit], connections: list[Connection],
                         settings: LoopSettings = LoopSettings()) -> Coupling:
    """The system's direct feed-through in dependency order and its algebraic loops with their tearing
    variables (:func:`cosim.master.loops.analyse_coupling` on the system's ports)."""
    return analyse_coupling(unit_order, connections, feedthrough_edges(units, connections), settings)


def assumed_feedthrough(units: Mapping[str, SystemUnit], loop: Loop) -> list[str]:
    """The units of ``loop`` with outputs on it that declare no dependencies (so every input is assumed to feed
    them directly, FMI's rule: a loop that may not be real)."""
    on_loop = {tuple(p.split(".", 1)) for p in loop.ports}
    return [u for u in loop.units if u in units and any(
        (u, o.name) in on_loop and o.name not in units[u].description.feedthrough
        for o in units[u].description.outputs())]


def check_algebraic_loops(units: Mapping[str, SystemUnit], connections: list[Connection],
                          problems: list[Problem], file: str, coupling: Coupling | None = None,
                          algorithm: str | None = None) -> list[Connection]:
    """Report the algebraic loops that cannot be solved; return the connections in initialization order.

    The loops' cut connections (the links into their tearing variables) are left out of the initialization
    order: a tearing variable keeps its start value (the spec's ``start``, else the unit's own) until the
    master solves the loop at the start time, and Newton starts there, as OpenModelica's KINSOL starts from
    the start values (carrying the cut links through a loop at initialization would start it wherever a few
    rounds of fixed-point iteration had wandered to).
    Loops of Real signals are solved by the master (:mod:`cosim.master.loops`); a loop carrying Integer,
    Boolean or String values, or a master ``algorithm`` that does not solve loops, is reported.
    Nodes are (unit, variable); a connection is an edge output -> input and a
    unit's declared feed-through an edge input -> output.
    """
    if coupling is None:
        coupling = feedthrough_coupling(list(units), units, connections)
    solves = ALGORITHMS[algorithm].solves_loops if algorithm in ALGORITHMS else True
    for loop in coupling.loops:
        ports = ", ".join(loop.ports)
        assumed = assumed_feedthrough(units, loop)
        # outputs whose dependencies nobody declared are assumed to depend on every input (FMI's rule)
        why = (f"; unit(s) {', '.join(assumed)} declare no dependencies for their outputs, so every output "
               "is assumed to depend directly on every input" if assumed else "")
        declare = (f"; if an output does not depend on an input directly, declare it in the spec, e.g. "
                   f"\"units\": {{\"{assumed[0]}\": {{\"feedthrough\": {{\"<output>\": []}}}}}}" if assumed else "")
        on_loop = [connections[i] for i in (*loop.links, *loop.torn)]
        discrete = sorted({f"{c.source.text} -> {c.target.text} ({c.source.variable.type})" for c in on_loop
                           if c.source.variable.type != "Real" or c.target.variable.type != "Real"})
        where = f"algebraic loop through units {', '.join(loop.units)} (ports {ports})"
        if discrete:
            problems.append(Problem(file, "$.connections", f"{where} carries values that are not Real: "
                                    f"{', '.join(discrete)}; only loops of Real signals are solved{why}",
                                    "break the loop: connect through a unit without direct feed-through, or "
                                    "change one connection" + declare))
        elif not solves:
            problems.append(Problem(file, "$.experiment.algorithm", f"{where}: the master algorithm "
                                    f"'{algorithm}' does not solve algebraic loops{why}",
                                    "use \"gauss-seidel\" or \"jacobi\", which solve them, or break the loop"
                                    + declare))
    nodes, edges = port_graph(connections, feedthrough_edges(units, connections))
    rank: dict[tuple[str, str], int] = {}
    for i, comp in enumerate(reversed(strongly_connected(nodes, edges))):
        for n in comp:
            rank[n] = i
    torn = {i for loop in coupling.loops for i in loop.torn}
    carried = [c for i, c in enumerate(connections) if i not in torn]
    return sorted(carried, key=lambda c: rank.get((c.source.unit, c.source.variable.name), 0))


def _element_input_connected(unit: str, variable: str, connected: set[tuple[str, str]]) -> bool:
    return any(u == unit and parse_port(v)[0] == variable for u, v in connected)
