"""Which Model Exchange units are integrated together, and the stepping order that follows.

Units that give cosim their equations to integrate (Model Exchange FMUs:
:meth:`~cosim.units.protocol.UnitType.offers_equations`) and are connected to
each other, directly or through other such units, form one *group*: one solver
integrates all their states (:mod:`cosim.units.fmu.coupled_me`), and the master
steps the group as one unit.  A unit connected to itself (an output fed back to
its own input) is a group of one.  This is the default; a spec opts out for the
whole system with ``"experiment": {"coupled_model_exchange": false}`` or for one
unit with ``"coupled_model_exchange": false`` on it (that unit is then integrated
alone, inside each communication step, and exchanges values at communication
points only).

An algebraic loop (a cycle of direct feed-through, :mod:`cosim.master.loops`)
whose units are all Model Exchange units of one group is solved *inside* the
group: at every evaluation of the group's equations (the solver's right-hand
side, event iterations), by the loop solver on the members (``CoupledGroup.coupling``).
Units on a loop that also passes through other units are not grouped: the loop
solver sets and reads them between steps; they run one by one, like units that
opted out.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, NamedTuple, Sequence

from cosim.errors import Problem, json_path
from cosim.master.loops import Coupling, strongly_connected
from cosim.spec.loader import Spec
from cosim.system.parts import Connection, SystemUnit
from cosim.system.stepping import feedthrough_coupling, stepping_order

OPT_OUT = "coupled_model_exchange"  # the field, in "experiment" and on a unit


@dataclass(frozen=True)
class CoupledGroup:
    """Model Exchange units integrated together: their names (spec order) and the connections between them,
    in the order their values are carried (an output with direct feed-through after the inputs it reads)."""

    name: str
    members: tuple[str, ...]
    links: tuple[Connection, ...]
    # the members' direct feed-through and the algebraic loops among them, as indices into ``links``, when the
    # links cannot be carried in one order (a loop inside the group); empty otherwise (``links`` in carrying order)
    coupling: Coupling = Coupling()


@dataclass(frozen=True)
class ModelExchangeCoupling:
    """The groups of a system and the master's stepping order, in which each group is one unit named
    ``group.name`` (``order`` is the system's own order when there is no group)."""

    groups: tuple[CoupledGroup, ...] = ()
    order: tuple[str, ...] = ()


def model_exchange_coupling(spec: Spec, units: Mapping[str, SystemUnit], connections: Sequence[Connection],
                            order: Sequence[str], feedthrough: Coupling,
                            problems: list[Problem]) -> ModelExchangeCoupling:
    """The groups of connected Model Exchange units (module docstring) and the stepping order with them.

    ``feedthrough``: the system's direct feed-through and algebraic loops (indices into ``connections``).

    Appends a problem for ``coupled_model_exchange`` on a unit that is not integrated by cosim.
    """
    for name, unit in units.items():
        if OPT_OUT in unit.spec.options and not unit.unit_type.offers_equations():
            problems.append(Problem(spec.path, json_path(["units", name, OPT_OUT]),
                                    f"'{OPT_OUT}' applies to model-exchange units, but unit '{name}' integrates "
                                    "itself (co-simulation) or is not an FMU",
                                    "remove it, or add \"interface\": \"model-exchange\" if the FMU offers it"))
    if not spec.experiment.coupled_model_exchange:
        return ModelExchangeCoupling((), tuple(order))
    candidates = {name for name, unit in units.items()
                  if unit.unit_type.offers_equations() and unit.spec.options.get(OPT_OUT, True)}
    outer_loops = list(feedthrough.loops)
    while True:  # a loop through units that are not all candidates takes its units out (which may free others)
        inner = [loop for loop in outer_loops if set(loop.units) <= candidates]
        outer_loops = [loop for loop in outer_loops if loop not in inner]
        on_loops = {i for loop in outer_loops for i in (*loop.links, *loop.torn, *loop.entries)}
        leaving = {u for i in on_loops for u in (connections[i].source.unit, connections[i].target.unit)}
        if not leaving & candidates:
            break
        candidates -= leaving
        outer_loops = list(feedthrough.loops)
    inside = [c for c in connections if c.source.unit in candidates and c.target.unit in candidates]
    edges: dict[str, set[str]] = {name: set() for name in candidates}
    for c in inside:
        edges[c.source.unit].add(c.target.unit)
        edges[c.target.unit].add(c.source.unit)
    names = [n for n in order if n in candidates]
    groups = []
    taken = set(units)
    for component in strongly_connected(names, edges):  # undirected edges: the connected components
        members = tuple(n for n in names if n in component)
        links = [c for c in inside if c.source.unit in component]
        if not links:
            continue  # a Model Exchange unit connected to no other: it integrates alone, as always
        ordered = _carrying_order(links, units)
        coupling = Coupling()
        if ordered is None:  # an algebraic loop among the members: solved inside the group (module docstring)
            member_units = {m: units[m] for m in members}
            ordered, coupling = links, feedthrough_coupling(list(members), member_units, links, feedthrough.settings)
        name = _free_name("+".join(members), taken)
        taken.add(name)
        groups.append(CoupledGroup(name, members, tuple(ordered), coupling))
    if not groups:
        return ModelExchangeCoupling((), tuple(order))
    group_of = {m: g.name for g in groups for m in g.members}
    contracted = list(dict.fromkeys(group_of.get(n, n) for n in [u.name for u in spec.units if u.name in units]))
    arrows = [_Arrow(_End(group_of.get(c.source.unit, c.source.unit)), _End(group_of.get(c.target.unit, c.target.unit)))
              for c in connections]
    return ModelExchangeCoupling(tuple(groups), tuple(stepping_order(contracted, arrows)))  # type: ignore[arg-type]


class _End(NamedTuple):
    unit: str


class _Arrow(NamedTuple):
    """A connection as stepping_order sees it: from one unit (or group) to another."""

    source: _End
    target: _End


def _carrying_order(links: list[Connection], units: Mapping[str, SystemUnit]) -> list[Connection] | None:
    """``links`` so that a link out of an output comes after the links into the inputs that output reads
    directly (the units' feed-through); None when they form a loop."""
    after: dict[int, set[int]] = {i: set() for i in range(len(links))}  # link -> links that must come first
    for i, out in enumerate(links):
        reads = set(units[out.source.unit].description.depends_on(out.source.variable.name))
        for j, into in enumerate(links):
            if into.target.unit == out.source.unit and into.target.variable.name in reads:
                after[i].add(j)
    ordered: list[int] = []
    done: set[int] = set()
    while len(ordered) < len(links):
        ready = [i for i in range(len(links)) if i not in done and after[i] <= done]
        if not ready:
            return None
        ordered.append(ready[0])  # connection order where free
        done.add(ready[0])
    return [links[i] for i in ordered]


def _free_name(name: str, taken: set[str]) -> str:
    candidate, n = name, 2
    while candidate in taken:
        candidate, n = f"{name}#{n}", n + 1
    return candidate
