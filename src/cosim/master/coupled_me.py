"""What a master algorithm steps when Model Exchange units are integrated together.

A group of connected Model Exchange units (:class:`~cosim.units.fmu.coupled_me.CoupledModelExchange`)
is one unit to the master: :func:`integrate_together` makes each group's unit
from the live members, and re-points the links that enter or leave a group at
the group's ports (``member.variable``); links between members of one group are
the group's own business and leave the master's list, and so do the direct
feed-through blocks (:class:`~cosim.master.loops.Coupling`) that contain them
(the group carries those values itself, continuously).  Without groups the units,
links and feed-through come back as they are, so a system without them costs
nothing more.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import partial
from typing import Any, Callable, Mapping, Protocol, Sequence

import numpy as np

from cosim.master.contract import SystemView
from cosim.master.loops import Coupling, Loop, LoopSolver
from cosim.master.transfers import Link, Port
from cosim.units.fmu.coupled_me import CoupledModelExchange, Propagation
from cosim.units.protocol import ElementRef, Unit


class Group(Protocol):
    """Units to integrate together: the group's name, its members' names, the links between them in the order
    their values are carried (the system's :class:`~cosim.system.coupled_me.CoupledGroup`; its ``coupling``, when
    not empty, orders them instead: feed-through blocks and loops solved inside the group)."""

    @property
    def name(self) -> str: ...
    @property
    def members(self) -> tuple[str, ...]: ...
    @property
    def links(self) -> Sequence[Link]: ...


@dataclass(frozen=True)
class _Port:
    unit: str
    refs: tuple[ElementRef, ...]


@dataclass(frozen=True)
class _Link:
    source: Port
    target: Port
    factor: float
    offset: float


def integrate_together(units: Mapping[str, Unit], order: Sequence[str], groups: Sequence[Group],
                       links: Sequence[Link], coupling: Coupling = Coupling()) -> SystemView:
    """What the master steps: each group's members joined to one :class:`CoupledModelExchange` (call before they
    are initialized: joined members start no solver of their own), the links and feed-through as the master sees
    them (module docstring) and, as the view's ``settle``, the loops inside groups solved at the start time.
    ``order``: the stepping order with each group as one unit; ``coupling``: the system's, as indices into
    ``links``; the system groups no unit on an algebraic loop (:mod:`cosim.system.coupled_me`), so only
    feed-through blocks can contain internal links."""
    if not groups:
        return SystemView(dict(units), order, list(links), coupling)
    stepped = dict(units)
    group_of: dict[str, CoupledModelExchange] = {}
    for group in groups:
        coupling_inside = getattr(group, "coupling", None)
        unit = CoupledModelExchange(group.name, {m: units[m] for m in group.members}, group.links,
                                    _carry_plan(group.links, coupling_inside) if coupling_inside and
                                    coupling_inside.loops else None)
        for member in group.members:
            del stepped[member]
            group_of[member] = unit
        stepped[group.name] = unit
    outer: list[Link] = []
    renumbered: dict[int, int] = {}  # index in links -> index in outer
    for i, link in enumerate(links):
        source, target = group_of.get(link.source.unit), group_of.get(link.target.unit)
        if source is not None and source is target:
            continue
        renumbered[i] = len(outer)
        outer.append(_Link(_seen_from(link.source, source), _seen_from(link.target, target), link.factor, link.offset))
    return SystemView(stepped, order, outer, _renumbered(coupling, renumbered),
                      settle=partial(_settle_groups, list(dict.fromkeys(group_of.values()))))


def _settle_groups(groups: Sequence[CoupledModelExchange], t: float) -> None:
    """Solve the loops inside groups at ``t`` (after initialization, before the first step): the values read at
    the start time then satisfy them, as the master's loops are solved at the start time."""
    for group in groups:
        group.settle(t)


class _MemberTransfer:
    """One link between members of a group, for the loop solver: read the source's output (scaled), set the
    target's input as the group does while it evaluates its equations (``set_within_group``: no solver restart).
    ``target`` and ``target_selection`` let the solver read a tearing variable's start value back, as for any
    transfer."""

    __slots__ = ("_read", "target", "target_selection", "_set", "_factor", "_offset")

    def __init__(self, members: Mapping[str, Any], link: Link):
        source, self.target = members[link.source.unit], members[link.target.unit]
        self._read = source.reader(source.select(list(link.source.refs)))
        self.target_selection = self.target.select(list(link.target.refs))
        self._set = self.target.set_within_group
        self._factor, self._offset = link.factor, link.offset

    def read(self) -> list[float]:
        return [self._factor * float(v) + self._offset for v in self._read()]

    def write(self, values: Sequence[float]) -> None:
        self._set(self.target_selection, list(values))

    def run(self) -> None:
        self.write(self.read())


class _SolveInGroup:
    """A loop among a group's members, solved whenever the group carries its values (every evaluation of its
    equations); ``run()`` says whether the solution moved (the group's event iteration repeats until it does not)."""

    __slots__ = ("_solver", "_now", "_last")

    def __init__(self, solver: LoopSolver, now: Callable[[], float]):
        self._solver, self._now = solver, now
        self._last: np.ndarray | None = None

    def run(self) -> bool:
        self._solver.solve(self._now())
        x = self._solver.solution
        changed = self._last is None or x is None or not np.array_equal(x, self._last)
        self._last = x
        return changed


# A loop inside a group is solved at every evaluation of the group's equations, which CVode differentiates with
# increments of about 1e-8 of the states: solved only to the default 1e-10, the loop's solution looks like noise
# on that scale (a guess within the tolerance is kept while the states moved), and the integration drifted 1.8e-3
# off the exact solution where 1e-12 keeps it at the solver's accuracy (3.6e-7; tests/master/test_coupled_model_exchange)
GROUP_LOOP_TOLERANCE = 1e-12


def _carry_plan(links: Sequence[Link], coupling: Coupling) -> Callable[[Mapping[str, Any], Callable[[], float]], list[Any]]:
    """How a group with loops among its members carries its links: the feed-through blocks and loops of
    ``coupling`` (indices into ``links``) in dependency order, each loop by a :class:`LoopSolver` on the members
    (to :data:`GROUP_LOOP_TOLERANCE`, or the spec's tolerance if tighter), then the links into inputs that feed
    no output."""
    settings = replace(coupling.settings, tolerance=min(coupling.settings.tolerance, GROUP_LOOP_TOLERANCE))

    def make(members: Mapping[str, Any], now: Callable[[], float]) -> list[Any]:
        actions: list[Any] = []
        done: set[int] = set()
        for block in coupling.blocks:
            if isinstance(block, Loop):
                solver = LoopSolver(block, members, links, settings,
                                    transfers=lambda units, some: [_MemberTransfer(units, link) for link in some])
                actions.append(_SolveInGroup(solver, now))
                done.update((*block.links, *block.torn, *block.entries))
            else:
                actions.extend(Propagation(members, links[i]) for i in block if i not in done)
                done.update(block)
        actions.extend(Propagation(members, link) for i, link in enumerate(links) if i not in done)
        return actions

    return make


def _renumbered(coupling: Coupling, renumbered: dict[int, int]) -> Coupling:
    """``coupling`` over the links that remain: blocks with a group's internal link dropped, indices renumbered."""
    blocks: list[tuple[int, ...] | Loop] = []
    for block in coupling.blocks:
        if isinstance(block, Loop) and not all(i in renumbered for i in (*block.links, *block.torn)):
            continue  # a loop inside a group: the group solves it (never a loop partly inside one)
        if isinstance(block, Loop):
            links, torn, entries = (tuple(renumbered[i] for i in part)
                                    for part in (block.links, block.torn, block.entries))
            blocks.append(Loop(block.units, links, torn, entries, block.ports, block.tearing))
        elif all(i in renumbered for i in block):
            blocks.append(tuple(renumbered[i] for i in block))
    return Coupling(tuple(blocks), coupling.settings)


def _seen_from(port: Port, group: CoupledModelExchange | None) -> Port:
    """``port`` as a port of ``group`` (``member.variable``), or unchanged outside any group."""
    if group is None:
        return port
    return _Port(group.name, tuple(ElementRef(group.port_name(port.unit, r.variable), r.offset) for r in port.refs))
