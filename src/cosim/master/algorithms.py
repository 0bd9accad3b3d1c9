"""Fixed-step master algorithms: Gauss-Seidel and Jacobi.

An algorithm is bound to live units once (:meth:`MasterAlgorithm.bind`),
which resolves every connection into a :class:`Transfer` with pre-built
selections; after that, :meth:`step` does no name lookup and no I/O.
Time is counted in whole steps by the caller (``t_k = start + k*h``), so
long runs do not drift.
"""

from __future__ import annotations

from functools import partial
from typing import Any, Callable, Mapping, Protocol, Sequence

import numpy as np

from cosim.units.protocol import ElementRef, SimulationEnded, Unit, UnitError


class Port(Protocol):
    """One end of a link: a unit's name and the elements of its port."""

    unit: str
    refs: tuple[ElementRef, ...]


class Link(Protocol):
    """What an algorithm needs of a connection: ``target = factor * source + offset``, element by element.

    The system's checked connections (:class:`cosim.system.parts.Connection`) are links; the algorithms know
    nothing else of a system, so they can be bound to any units and links.
    """

    source: Port
    target: Port
    factor: float
    offset: float


def step_unit(unit: Unit, t: float, h: float) -> None:
    """``unit.do_step(t, h)``; any exception becomes a UnitError naming the unit and time."""
    try:
        unit.do_step(t, h)
    except (UnitError, SimulationEnded):
        raise
    except Exception as exc:  # a Python unit's own bug, reported like an FMU's error status
        raise UnitError(unit.name, f"do_step raised {type(exc).__name__}: {exc}", t) from exc


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


def _converting(read: Callable[[], Sequence], connections: Sequence[Link],
                as_list: bool = True) -> Callable[[], Any]:
    """``read`` followed by each element's unit conversion ``factor * x + offset`` (one multiply-add, no drift);
    a list, or with ``as_list=False`` a numpy array."""
    factor = np.array([c.factor for c in connections for _ in c.source.refs])
    offset = np.array([c.offset for c in connections for _ in c.source.refs])
    if not as_list:
        return lambda: np.asarray(read(), dtype=float) * factor + offset
    return lambda: (np.asarray(read(), dtype=float) * factor + offset).tolist()


def group_transfers(units: Mapping[str, Unit], connections: Sequence[Link]) -> list[Transfer]:
    """One Transfer per (source unit, target unit) pair, in the order first seen."""
    groups: dict[tuple[str, str], list[Link]] = {}
    for c in connections:
        groups.setdefault((c.source.unit, c.target.unit), []).append(c)
    return [Transfer(units[s], units[t], cs) for (s, t), cs in groups.items()]


class MasterAlgorithm:
    """Base: ``bind`` to live units, then ``step(t, h)`` advances all of them."""

    name = "abstract"

    def bind(self, units: Mapping[str, Unit], order: Sequence[str], connections: Sequence[Link]) -> None:
        raise NotImplementedError

    def step(self, t: float, h: float) -> None:
        raise NotImplementedError


class GaussSeidel(MasterAlgorithm):
    """Units step one after another in ``order``; each first takes its inputs
    from the *latest* outputs, so a unit later in the order sees the values its
    sources computed in this same step."""

    name = "gauss-seidel"

    def bind(self, units: Mapping[str, Unit], order: Sequence[str], connections: Sequence[Link]) -> None:
        self._plan = []
        for name in order:
            incoming = [c for c in connections if c.target.unit == name]
            self._plan.append((units[name], group_transfers(units, incoming)))

    def step(self, t: float, h: float) -> None:
        for unit, transfers in self._plan:
            for transfer in transfers:
                transfer.run()
            step_unit(unit, t, h)


class Jacobi(MasterAlgorithm):
    """All units step from the outputs at ``t``: step every unit (in any order;
    they are independent), then read every output and set every input.

    The transfers come at the end of the step, not at its start: the inputs a
    unit steps from are the same (initialization already set them for the
    first step), but whoever reads the units after ``step`` (the trace, the
    objectives) sees inputs consistent with the outputs at ``t + h``, also at
    the stop time.  A unit that ends the simulation skips the transfers.
    """

    name = "jacobi"

    def bind(self, units: Mapping[str, Unit], order: Sequence[str], connections: Sequence[Link]) -> None:
        self._transfers = group_transfers(units, connections)
        self._units = [units[n] for n in order]

    def step(self, t: float, h: float) -> None:
        try:  # step_unit's rule, with the try around the loop: one Python call less per unit and step
            for unit in self._units:
                unit.do_step(t, h)
        except (UnitError, SimulationEnded):
            raise
        except Exception as exc:
            raise UnitError(unit.name, f"do_step raised {type(exc).__name__}: {exc}", t) from exc
        # each transfer reads into its source's buffer, so all reads stay valid until the writes
        values = [transfer.read() for transfer in self._transfers]
        for transfer, v in zip(self._transfers, values):
            transfer.write(v)


ALGORITHMS = {GaussSeidel.name: GaussSeidel, Jacobi.name: Jacobi}  # the one list of master algorithm names
DEFAULT_ALGORITHM = GaussSeidel.name


def make_algorithm(name: str) -> MasterAlgorithm:
    """The algorithm called ``name``; raises ValueError for an unknown name."""
    try:
        return ALGORITHMS[name]()
    except KeyError:
        raise ValueError(f"unknown master algorithm '{name}'; use one of {', '.join(ALGORITHMS)}") from None
