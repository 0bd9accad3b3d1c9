"""The pieces a checked system is made of: units, resolved signals, connections, assignments.

Plain frozen dataclasses shared by the checks (:mod:`.signals`, :mod:`.value_checks`,
:mod:`.connection_checks`, :mod:`.stepping`) and :class:`cosim.system.builder.System`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from cosim.units.kind import UnitSpec
from cosim.units.protocol import ElementRef, UnitDescription, UnitType, Variable


@dataclass(frozen=True)
class SystemUnit:
    """One unit of a system: its spec, blueprint, description and port mapping."""

    spec: UnitSpec
    unit_type: UnitType
    description: UnitDescription

    @property
    def name(self) -> str:
        return self.spec.name

    def variable_name(self, port: str) -> str:
        """The unit's own name for a spec-level port name (after the port mapping)."""
        return self.spec.ports.get(port, port)


@dataclass(frozen=True)
class Signal:
    """A resolved 'unit.port' or 'unit.port[i]': its scalar elements and column names."""

    text: str
    unit: str
    variable: Variable
    refs: tuple[ElementRef, ...]
    columns: tuple[str, ...]


@dataclass(frozen=True)
class Connection:
    """A checked connection between element lists of equal length.

    The master sets ``target = factor * source + offset``: the connection's own
    factor and offset (e.g. an SSP LinearTransformation) applied after the units
    of measure are converted (see :mod:`cosim.system.connection_units`); (1, 0)
    passes values unchanged.
    """

    source: Signal
    target: Signal
    factor: float = 1.0
    offset: float = 0.0

    @property
    def transforms(self) -> bool:
        return self.factor != 1.0 or self.offset != 0.0


@dataclass(frozen=True)
class Assignment:
    """Values set on one unit before initialization: elements and flat values."""

    unit: str
    refs: tuple[ElementRef, ...]
    values: tuple[Any, ...]


class LoadedUnits(dict[str, Any]):
    """Units that loaded, and the names of those that did not (already reported,
    so references to them are not reported again)."""

    def __init__(self) -> None:
        super().__init__()
        self.failed: set[str] = set()
