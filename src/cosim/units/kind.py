"""What a unit kind is (:class:`UnitKind`) and what it is given (:class:`UnitSpec`); the registry of kinds is
:mod:`cosim.units.registry`, the built-in kinds sit beside their units (``cosim.units.fmu.kind``, ...)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Mapping

if TYPE_CHECKING:
    from cosim.units.protocol import UnitType


@dataclass(frozen=True)
class UnitSpec:
    """One unit of a system as its spec (or SSP) declares it: what a unit kind's ``create`` is given."""

    name: str
    kind: str  # a registered unit kind: "fmu", "python", "player" or a plug-in's (cosim.units.registry)
    source: str
    parameters: Mapping[str, Any] = field(default_factory=dict)
    start: Mapping[str, Any] = field(default_factory=dict)
    ports: Mapping[str, str] = field(default_factory=dict)
    options: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class UnitKind:
    """One kind of unit (see the module docstring).

    ``name`` is the spec key naming the unit's source (``{"fmu": "a.fmu"}``);
    ``fields`` maps every field the kind adds to a unit (its key first) to its
    JSON Schema; ``create(unit_spec, folder)`` returns the unit's blueprint,
    resolving relative paths against ``folder`` (the spec's folder) and
    raising UserError (or FileNotFoundError, ImportError, ValueError) when the
    source cannot be used; ``example`` shows the key in use, for messages.
    ``replays`` marks a kind whose units stand in for a recorded unit (the
    ``player``): the parameters, start values, incoming connections and design
    parameters of such a unit are not used, since the recording already holds
    what they gave.
    """

    name: str
    fields: Mapping[str, Any]
    create: Callable[[UnitSpec, str], "UnitType"]
    example: str = ""
    description: str = ""
    replays: bool = False

    @property
    def options(self) -> tuple[str, ...]:
        """The fields besides the kind's key (e.g. a player's ``columns``)."""
        return tuple(k for k in self.fields if k != self.name)
