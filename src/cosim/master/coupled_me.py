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

from dataclasses import dataclass
from typing import Mapping, NamedTuple, Protocol, Sequence

from cosim.master.loops import Coupling, Loop
from cosim.master.transfers import Link, Port
from cosim.units.fmu.coupled_me import CoupledModelExchange
from cosim.units.protocol import ElementRef, Unit


class Group(Protocol):
    """Units to integrate together: the group's name, its members' names, the links between them in the order
    their values are carried (the system's :class:`~cosim.system.coupled_me.CoupledGroup`)."""

    name: str
    members: tuple[str, ...]
    links: tuple[Link, ...]


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


class Stepped(NamedTuple):
    """The units a master algorithm binds (each group as one unit, by the group's name), its links and the
    direct feed-through among them (indices into ``links``)."""

    units: dict[str, Unit]
    links: list[Link]
    coupling: Coupling


def integrate_together(units: Mapping[str, Unit], groups: Sequence[Group], links: Sequence[Link],
                       coupling: Coupling = Coupling()) -> Stepped:
    """Each group's members joined to one :class:`CoupledModelExchange` (call before they are initialized:
    joined members start no solver of their own), and the links and feed-through as the master sees them
    (module docstring). ``coupling``: the system's, as indices into ``links``; the system groups no unit on an
    algebraic loop (:mod:`cosim.system.coupled_me`), so only feed-through blocks can contain internal links."""
    if not groups:
        return Stepped(dict(units), list(links), coupling)
    stepped = dict(units)
    group_of: dict[str, CoupledModelExchange] = {}
    for group in groups:
        unit = CoupledModelExchange(group.name, {m: units[m] for m in group.members}, group.links)
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
    return Stepped(stepped, outer, _renumbered(coupling, renumbered))


def _renumbered(coupling: Coupling, renumbered: dict[int, int]) -> Coupling:
    """``coupling`` over the links that remain: blocks with a group's internal link dropped, indices renumbered."""
    blocks: list[tuple[int, ...] | Loop] = []
    for block in coupling.blocks:
        if isinstance(block, Loop):  # never through a group (see integrate_together)
            blocks.append(Loop(block.units, *(tuple(renumbered[i] for i in part)
                                              for part in (block.links, block.torn, block.entries)),
                               block.ports, block.tearing))
        elif all(i in renumbered for i in block):
            blocks.append(tuple(renumbered[i] for i in block))
    return Coupling(tuple(blocks), coupling.settings)


def _seen_from(port: Port, group: CoupledModelExchange | None) -> Port:
    """``port`` as a port of ``group`` (``member.variable``), or unchanged outside any group."""
    if group is None:
        return port
    return _Port(group.name, tuple(ElementRef(group.port_name(port.unit, r.variable), r.offset) for r in port.refs))
