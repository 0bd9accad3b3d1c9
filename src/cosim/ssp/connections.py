"""The ``ssd:Connection``s of an SSP, and the flow they make: a chain ``A.y -> system connector -> ... -> B.u``
is followed back to the component output feeding it and becomes one connection ``A.y -> B.u`` whose factor and
offset compose the unit conversions (unless ``suppressUnitConversion``; a system connector without a unit passes
the unit through) and ``LinearTransformation``s along the chain (SSP: target = factor * converted source +
offset)."""

from __future__ import annotations

from itertools import islice
from typing import Any

from cosim.errors import did_you_mean
from cosim.ssp.measures import unit_conversion
from cosim.ssp.model import Edge, Node, unit_of, variable_of
from cosim.ssp.reading import Reading
from cosim.ssp.xml import element_path, short_name, tag

End = tuple[tuple[str, ...], str]  # (element path, connector)
_LINEAR = tag("ssc", "LinearTransformation")
_MAPPINGS = (tag("ssc", "BooleanMappingTransformation"), tag("ssc", "IntegerMappingTransformation"),
             tag("ssc", "EnumerationMappingTransformation"))


def read_connection(reading: Reading, element: Any, system: Node) -> None:
    """One ``ssd:Connection`` of ``system`` kept as an :class:`Edge` (a problem for an end it does not have)."""
    ends = []
    for side in ("start", "end"):
        owner_name = element.get(f"{side}Element")
        connector = element.get(f"{side}Connector")
        if not owner_name:  # left out, or "" as OMSimulator writes it: the system's own connector
            owner = system
        elif owner_name in system.children:
            owner = system.children[owner_name]
        else:
            reading.problem(element, f"{side}Element '{owner_name}' is not an element of system "
                            f"'{element_path(system.element)}'.{did_you_mean(owner_name, system.children)}",
                            "name a component or sub-system of this system, or leave it out (or write "
                            f"{side}Element=\"\") for the system's own connector")
            return
        if connector not in owner.connectors and variable_of(owner, connector) is None:
            what = "system" if owner.kind == "system" else "component"
            known = owner.connectors or owner.variables  # not copied: 10^5 wrong ends of 10^5 connectors
            reading.problem(element, f"{side}Connector '{connector}' is not a connector of {what} "
                            f"'{'.'.join(owner.path) or 'the root system'}'.{did_you_mean(connector, known)}",
                            f"use one of: {', '.join(islice(known, 12))}" if known else "declare the connector")
            return
        ends.append((owner.path, connector))
    suppress = element.get("suppressUnitConversion", "false") in ("true", "1")
    f, o = 1.0, 0.0
    if len(element):  # most connections have no children: no searches (10^5 connections)
        linear = element.find(_LINEAR)
        if linear is not None:
            f, o = float(linear.get("factor", 1.0)), float(linear.get("offset", 0.0))
        for other in _MAPPINGS:
            if element.find(other) is not None:
                reading.problem(element, f"{short_name(other)} is not supported", "map the values inside an FMU")
    reading.edges.append(Edge(ends[0], ends[1], f, o, suppress, element))


def _end_text(end: End) -> str:
    """'valve.p1' for a connection end (a system's own connector: its bare name)."""
    return ".".join((*end[0], end[1]))


class Flow:
    """Which connection feeds every connector (a problem for a connector fed twice), and the chains back."""

    def __init__(self, reading: Reading):
        self.reading = reading
        self.into: dict[End, Edge] = {}  # connection end -> the connection feeding it
        for edge in reading.edges:
            first = self.into.get(edge.end)
            if first is None:
                self.into[edge.end] = edge
            elif (first.start, first.factor, first.offset, first.suppress) == \
                    (edge.start, edge.factor, edge.offset, edge.suppress):  # the same connection written twice
                reading.alike.add(("duplicate connection", reading.label),
                                  f"{reading.label}: {element_path(edge.element)} repeats the connection "
                                  f"{_end_text(edge.start)} -> {_end_text(edge.end)} of "
                                  f"{element_path(first.element)}: read once", _end_text(edge.end),
                                  "more connections repeated, read once")
            else:  # two sources: which one the connector holds would depend on the order of evaluation
                reading.problem(edge.element, f"connector '{edge.end[1]}' of "
                                f"'{'.'.join(edge.end[0]) or 'the root system'}' is fed by "
                                f"{_end_text(edge.start)} here and already by {_end_text(first.start)} "
                                f"({element_path(first.element)}): a connector holds one value, and which of the two "
                                "it would hold depends on the order a tool evaluates them (OMSimulator refuses a "
                                "second connection into a connector of one system: 'Connector ... is already "
                                "connected to ...')",
                                "remove one of the two connections, or feed the second source to a connector of "
                                "its own")

    def unit_of(self, end: End) -> tuple[str | None, dict]:
        return unit_of(self.reading.nodes, *end)

    def chain(self, end: End) -> list[Edge]:
        """The connections from a component (or a system connector fed by nothing) to ``end``, in flow order."""
        nodes = self.reading.nodes
        chain = [self.into[end]]
        visited = {end}
        while True:
            start = chain[0].start
            if nodes[start[0]].kind == "component" or start in visited or start not in self.into:
                return chain
            visited.add(start)
            chain.insert(0, self.into[start])

    def compose(self, chain: list[Edge], unit: tuple) -> tuple[float, float]:
        """(factor, offset) of a chain: per connection, units converted (unless suppressed), then its transformation.

        ``unit`` is the (name, definitions) of the value entering the chain.  A
        system connector that declares no unit passes the unit through, so a
        chain rpm -> (no unit) -> rad/s still converts.
        """
        factor, offset = 1.0, 0.0
        for edge in chain:
            end_unit = self.unit_of(edge.end)
            a, b = (1.0, 0.0) if edge.suppress else unit_conversion(self.reading, unit, end_unit, edge.element)
            f, o = edge.factor * a, edge.factor * b + edge.offset
            factor, offset = f * factor, f * offset + o
            if end_unit[0] or edge.suppress:
                unit = end_unit  # after a suppressed conversion only a declared unit is known
        return factor, offset

    def unit_after(self, chain: list[Edge], unit: tuple) -> tuple[str | None, dict]:
        """The unit of measure of the value leaving ``chain`` when ``unit`` enters it (as :meth:`compose` tracks
        it: a connector declaring no unit passes the unit through)."""
        for edge in chain:
            end_unit = self.unit_of(edge.end)
            if end_unit[0] or edge.suppress:
                unit = end_unit
        return unit

    def connections(self, unit_names: dict[tuple[str, ...], str]) -> list[dict]:
        """The spec's connections: every FMU or table input fed through a chain from a component output."""
        nodes = self.reading.nodes
        connections = []
        for end in self.into:
            node = nodes[end[0]]
            if node.kind != "component" or (node.fmu or node.table) is None:
                continue
            variable = variable_of(node, end[1])
            if variable is None or variable.causality != "input":
                continue  # parameters fed from system connectors are handled with the bindings
            chain = self.chain(end)
            source, through = chain[0].start, chain[0]
            if nodes[source[0]].kind != "component":
                continue  # a system connector fed by nothing (or a loop): no connection
            factor, offset = self.compose(chain, self.unit_of(source))
            source_variable = variable_of(nodes[source[0]], source[1])
            if source_variable is None or source_variable.causality != "output":
                causality = getattr(source_variable, "causality", "unknown")
                self.reading.problem(through.element, f"'{'.'.join(source[0])}.{source[1]}' is {causality}, not "
                                     "an output", "a connection chain starts at a component's output")
                continue
            # the SSP's unit conversions are all in factor and offset: cosim must not convert again
            entry: dict[str, Any] = {"from": f"{unit_names[source[0]]}.{source[1]}",
                                     "to": f"{unit_names[end[0]]}.{end[1]}", "convert": False}
            if factor != 1.0 or offset != 0.0:
                entry.update(factor=factor, offset=offset)
            connections.append(entry)
        return connections
