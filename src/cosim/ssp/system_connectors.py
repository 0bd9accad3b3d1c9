"""What every system connector of an SSP carries, and the units that make those connectors signals of their own.

A spec naming the SSP (or the SSP run alone) may name a system connector as its tool's users do:
``Root.sub.connector`` (with the root system's name) or ``sub.connector``.  A connector carrying a component
output unchanged stands for that output; one that scales it (unit conversions, ``LinearTransformation``) or
holds a bound constant becomes a port of a ``connectors`` unit named by its system (``Root.sub``, see
:mod:`cosim.units.connectors`): an input fed by the component output with the chain's factor and offset, or a
parameter holding the constant.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from cosim.ssp.bindings import Bindings
from cosim.ssp.connections import Flow
from cosim.ssp.model import variable_of
from cosim.ssp.names import cosim_part, cosim_path
from cosim.ssp.reading import Reading


@dataclass(frozen=True)
class ConnectorSignal:
    """What one system connector carries: ``factor`` x ``port`` + ``offset`` (``port`` a unit's 'unit.port'),
    or the constant ``value`` (``port`` None)."""

    system: str  # the system's name with the root system's: 'default.sub' ('default' for the root's own)
    connector: str
    port: str | None = None
    factor: float = 1.0
    offset: float = 0.0
    value: Any = None
    unit: str | None = None  # of measure, of a scaled port's value as the connector carries it
    # a parameter connector's parameter connections: (unit.variable, factor, offset) it sets, as 'feeds' says
    feeds: tuple[tuple[str, float, float], ...] = ()
    # a constant taken from another connector (a parameter connection between systems): that connector's name
    # and the chain's factor and offset, so a value set on it reaches this one too (as the tool shows it)
    via: tuple[str, float, float] | None = None

    @property
    def name(self) -> str:
        return f"{self.system}.{self.connector}"

    @property
    def unchanged(self) -> bool:
        """True for a connector carrying a unit port as it is: it stands for that port."""
        return self.port is not None and self.factor == 1.0 and self.offset == 0.0


def connector_signals(reading: Reading, flow: Flow, bindings: Bindings, unit_names: dict,
                      root_name: str) -> dict[str, ConnectorSignal]:
    """What every system connector carries, by its cosim name (:mod:`cosim.ssp.names`) with and without the
    root system's (``root_name``, a cosim name already).

    A connector fed (through a chain) by a component output carries factor x that output + offset (the
    chain's conversions and transformations); one holding a bound value (or fed by a connector that holds one)
    carries that value.  A connector whose chain cannot be followed (a loop, units that do not convert) carries
    nothing known and is left out: this is for naming connectors in a spec, the SSP was checked already.
    """
    signals: dict[str, ConnectorSignal] = {}
    problems = list(reading.problems)
    system_values = bindings.system_values

    def constant(start: tuple, chain: list | None = None) -> Any:
        """The value bound to the connector ``start``, in its unit, then along ``chain`` (as a parameter
        connection carries it)."""
        _depth, _order, value, unit, extra, label = system_values[start]
        if isinstance(value, float):
            value = bindings.converted(value, unit, extra, label, flow.unit_of(start))
            if chain:
                factor, offset = flow.compose(chain, flow.unit_of(start))
                value = factor * value + offset
        return value

    def system_name(path: tuple[str, ...]) -> str:
        return cosim_path((root_name, *path)) if root_name else cosim_path(path)

    feeds = _parameter_feeds(reading, flow, bindings, unit_names)
    for node in reading.nodes.values():
        if node.kind != "system":
            continue
        system = system_name(node.path)
        for name in node.connectors:
            end = (node.path, name)
            port = cosim_part(name)  # one port of the system's connectors unit: a dot in its name becomes _
            carried: ConnectorSignal | None = None
            chain = flow.chain(end) if end in flow.into else []
            if chain and reading.nodes[chain[0].start[0]].kind == "component":
                start = chain[0].start
                if start[0] in unit_names:
                    factor, offset = flow.compose(chain, flow.unit_of(start))
                    carried = ConnectorSignal(system, port, f"{unit_names[start[0]]}.{start[1]}", factor, offset,
                                              unit=flow.unit_after(chain, flow.unit_of(start))[0])
            else:  # a constant: fed by a connector holding a value, or bound here (the higher binding wins)
                valued, own = bindings.valued_chain(chain), system_values.get(end)
                if valued is not None and (own is None or system_values[valued[0].start][0] <= own[0]):
                    start = valued[0].start
                    factor, offset = flow.compose(valued, flow.unit_of(start))
                    source = f"{system_name(start[0])}.{cosim_part(start[1])}"
                    carried = ConnectorSignal(system, port, value=constant(start, valued),
                                              via=(source, factor, offset))
                elif own is not None:
                    carried = ConnectorSignal(system, port, value=constant(end), feeds=feeds.get(end, ()))
            if carried is not None:
                signals[carried.name] = carried
                signals.setdefault(f"{cosim_path(node.path)}.{port}" if node.path else port, carried)
    reading.problems[:] = problems  # a chain only named here (no FMU input at its end) reports nothing new
    return signals


def _parameter_feeds(reading: Reading, flow: Flow, bindings: Bindings,
                     unit_names: dict) -> dict[tuple, tuple[tuple[str, float, float], ...]]:
    """Per system connector, the FMU variables it sets through parameter connections, each with the chain's
    factor and offset (unit conversions and LinearTransformations: variable = factor x connector + offset); a
    variable whose direct binding beats the connector's value is left out (it keeps that binding)."""
    feeds: dict[tuple, list[tuple[str, float, float]]] = {}
    nodes = reading.nodes
    for end in flow.into:
        node = nodes[end[0]]
        if node.kind != "component" or node.fmu is None or end in bindings.kept or end[0] not in unit_names:
            continue
        variable = variable_of(node, end[1])
        if variable is None or variable.causality not in ("parameter", "structuralParameter"):
            continue
        chain = flow.chain(end)
        if nodes[chain[0].start[0]].kind != "system":
            continue
        # the connector whose value reaches the variable (a connector bound by nobody passes one further down
        # through); a chain holding no value at all still feeds from its first connector
        chain = bindings.valued_chain(chain) or chain
        start = chain[0].start
        factor, offset = flow.compose(chain, flow.unit_of(start))
        feeds.setdefault(start, []).append((f"{unit_names[end[0]]}.{end[1]}", factor, offset))
    return {start: tuple(targets) for start, targets in feeds.items()}


def connector_units(signals: list[ConnectorSignal]) -> tuple[dict[str, dict], list[dict]]:
    """The ``connectors`` units (one per system, named by it) and the connections feeding them that make
    ``signals`` ports of their own: a scaled connector an input fed with its factor and offset, a constant a
    parameter (which ``feeds`` the FMU parameters its parameter connections set, and the constants among
    ``signals`` that take their value from it)."""
    units: dict[str, dict] = {}
    connections: list[dict] = []
    for signal in signals:
        unit = units.setdefault(signal.system, {"connectors": signal.system})
        if signal.port is None:
            unit.setdefault("parameters", {})[signal.connector] = signal.value
            if signal.feeds:  # a value set on the connector (design, --set) sets the parameters it feeds
                unit.setdefault("feeds", {})[signal.connector] = [
                    {"to": to, "factor": factor, "offset": offset} for to, factor, offset in signal.feeds]
            continue
        inputs = unit.setdefault("inputs", {})
        if signal.connector in inputs:
            continue
        inputs[signal.connector] = signal.unit or ""
        # the SSP's conversions are all in factor and offset: cosim must not convert again
        connection: dict[str, Any] = {"from": signal.port, "to": signal.name, "convert": False}
        if not signal.unchanged:
            connection.update(factor=signal.factor, offset=signal.offset)
        connections.append(connection)
    for signal in signals:  # a constant taken from a connector that is a port too: a value set there reaches it
        if signal.port is None and signal.via is not None:
            source, factor, offset = signal.via
            system, _, connector = source.rpartition(".")
            if connector in (units.get(system) or {}).get("parameters", {}):
                units[system].setdefault("feeds", {}).setdefault(connector, []).append(
                    {"to": signal.name, "factor": factor, "offset": offset})
    return units, connections
