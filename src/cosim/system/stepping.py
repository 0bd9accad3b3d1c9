"""Stepping order and algebraic loops: the graph side of a system.

:func:`stepping_order` orders units for Gauss-Seidel (sources first, feedback
cycles kept together); :func:`check_algebraic_loops` finds cycles of direct
feed-through and gives the connections in initialization order; both use
:func:`strongly_connected` (Tarjan).
"""

from __future__ import annotations

import heapq
from typing import Any, Mapping

from cosim.errors import Problem
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


def check_algebraic_loops(units: Mapping[str, SystemUnit], connections: list[Connection],
                           problems: list[Problem], file: str) -> list[Connection]:
    """Find cycles of direct feed-through; return the connections in initialization order.

    Nodes are (unit, variable); a connection is an edge output -> input and a
    unit's declared feed-through is an edge input -> output.
    """
    edges: dict[tuple[str, str], set[tuple[str, str]]] = {}
    nodes: list[tuple[str, str]] = []

    def add(a: tuple[str, str], b: tuple[str, str]) -> None:
        for n in (a, b):
            if n not in edges:
                edges[n] = set()
                nodes.append(n)
        edges[a].add(b)

    for c in connections:
        add((c.source.unit, c.source.variable.name), (c.target.unit, c.target.variable.name))
    connected_inputs = {(c.target.unit, c.target.variable.name) for c in connections}
    for name, unit in units.items():
        for out in unit.description.outputs():
            for inp in unit.description.depends_on(out.name):
                if (name, inp) in connected_inputs or _element_input_connected(name, inp, connected_inputs):
                    add((name, inp), (name, out.name))
        # array elements: an element input depends on the whole array's dependencies
    for comp in strongly_connected(nodes, edges):
        if len(comp) > 1 or comp[0] in edges.get(comp[0], set()):
            involved = sorted({u for u, _ in comp})
            ports = ", ".join(sorted(f"{u}.{v}" for u, v in comp))
            # outputs whose dependencies nobody declared are assumed to depend on every input (FMI's rule)
            assumed = sorted({u for u, v in comp if u in units and v in {o.name for o in units[u].description.outputs()}
                              and v not in units[u].description.feedthrough})
            why = (f"; unit(s) {', '.join(assumed)} declare no dependencies for their outputs, so every output "
                   "is assumed to depend directly on every input" if assumed else "")
            fix = ("break the loop: connect through a unit without direct feed-through, or change one connection"
                   + (f"; if an output does not depend on an input directly, declare it in the spec, e.g. "
                      f"\"units\": {{\"{assumed[0]}\": {{\"feedthrough\": {{\"<output>\": []}}}}}}" if assumed else ""))
            problems.append(Problem(file, "$.connections",
                                    f"algebraic loop through units {', '.join(involved)} (ports {ports}){why}", fix))
    rank: dict[tuple[str, str], int] = {}
    for i, comp in enumerate(reversed(strongly_connected(nodes, edges))):
        for n in comp:
            rank[n] = i
    return sorted(connections, key=lambda c: rank.get((c.source.unit, c.source.variable.name), 0))


def _element_input_connected(unit: str, variable: str, connected: set[tuple[str, str]]) -> bool:
    return any(u == unit and parse_port(v)[0] == variable for u, v in connected)
