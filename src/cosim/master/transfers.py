"""Links between units' ports and the transfers that carry their values.

A :class:`Link` is what a master algorithm needs of a connection; a :class:`Transfer` copies the values of
a group of links from one unit to another with selections built once, so a step does no name lookup.
The master algorithms (:mod:`cosim.master.algorithms`) and the loop solver (:mod:`cosim.master.loops`)
both move values with them.
"""

from __future__ import annotations

from functools import partial
from typing import Any, Callable, Mapping, Protocol, Sequence

import numpy as np

from cosim.units.protocol import ElementRef, Unit


class Port(Protocol):
    """One end of a link: a unit's name and the elements of its port."""

    # read-only properties: the system's ports and links are frozen dataclasses, which a protocol's plain
    # (settable) attribute would not accept
    @property
    def unit(self) -> str: ...
    @property
    def refs(self) -> tuple[ElementRef, ...]: ...


class Link(Protocol):
    """What an algorithm needs of a connection: ``target = factor * source + offset``, element by element.

    The system's checked connections (:class:`cosim.system.parts.Connection`) are links; the algorithms know
    nothing else of a system, so they can be bound to any units and links.
    """

    @property
    def source(self) -> Port: ...
    @property
    def target(self) -> Port: ...
    @property
    def factor(self) -> float: ...
    @property
    def offset(self) -> float: ...


class Transfer:
    """Copies a group of output elements of one unit to input elements of another.

    Connections with a factor or offset (SSP transformations, unit
    conversions) deliver ``factor * value + offset``; a group without any
    keeps the plain copy.
    """

    __slots__ = ("source", "source_selection", "target", "target_selection", "read", "write")

    def __init__(self, source: Unit, target: Unit, connections: Sequence[Link]):
        self.source = source
        self.target = target
        self.source_selection = source.select([r for c in connections for r in c.source.refs])
        self.target_selection = target.select([r for c in connections for r in c.target.refs])
        read = source.reader(self.source_selection)  # valid until its next call
        # A unit with its own writer (an FMU: straight into the buffer its set call reads) takes the values
        # as they are read (numpy views of the source's buffer, or lists); others get them through set().
        own_writer = type(target).writer is not Unit.writer
        if any((c.factor, c.offset) != (1.0, 0.0) for c in connections):
            read = _converting(read, connections, as_list=not own_writer)
        self.read = read
        if own_writer:
            self.write = target.writer(self.target_selection)
        else:
            self.write = partial(target.set, self.target_selection)

    def run(self) -> None:
        self.write(self.read())


def _converting(read: Callable[[], Sequence[Any] | np.ndarray], connections: Sequence[Link],
                as_list: bool = True) -> Callable[[], Any]:
    """``read`` followed by each element's unit conversion ``factor * x + offset`` (one multiply-add, no drift);
    a list, or with ``as_list=False`` a numpy array."""
    factor = np.array([c.factor for c in connections for _ in c.source.refs])
    offset = np.array([c.offset for c in connections for _ in c.source.refs])
    if not as_list:
        return lambda: np.asarray(read(), dtype=float) * factor + offset
    return lambda: (np.asarray(read(), dtype=float) * factor + offset).tolist()


# how an algorithm makes its transfers: (units by name, links) -> objects with run(), read() and write(values)
TransferFactory = Callable[[Mapping[str, Any], Sequence[Link]], Sequence[Any]]


def group_transfers(units: Mapping[str, Unit], connections: Sequence[Link]) -> list[Transfer]:
    """One Transfer per (source unit, target unit) pair, in the order first seen (a :data:`TransferFactory`)."""
    groups: dict[tuple[str, str], list[Link]] = {}
    for c in connections:
        groups.setdefault((c.source.unit, c.target.unit), []).append(c)
    return [Transfer(units[s], units[t], cs) for (s, t), cs in groups.items()]
