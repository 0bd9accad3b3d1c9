"""The elements of an SSP as the reader holds them: components and systems (:class:`Node`), their connectors,
and the connections between them (:class:`Edge`); the SSP's value types and how a name means an FMU variable."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REAL = {"Real", "Float64", "Float32"}
INTEGER = {"Integer", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64"}
# an SSP type element (ssc:Real, ssv:Int32, ...) -> the kind of value cosim gives it
TYPE_OF = {**{t: "Real" for t in REAL}, **{t: "Integer" for t in INTEGER}, "Boolean": "Boolean",
           "String": "String", "Enumeration": "Integer"}
FMU_TYPES = ("application/x-fmu-sharedlibrary",)
TABLE_TYPES = ("text/csv", "application/table")  # OMSimulator 3 and 2: a table whose columns are outputs


@dataclass
class Connector:
    name: str
    kind: str
    type: str | None
    unit: str | None
    element: Any = None  # the ssd:Connector, for messages


@dataclass
class Node:
    """A component or system of the SSP, by its path below the root system."""

    path: tuple[str, ...]
    kind: str  # "component" | "system"
    element: Any
    connectors: dict[str, Connector] = field(default_factory=dict)
    children: dict[str, Node] = field(default_factory=dict)
    fmu: Path | None = None
    table: Path | None = None  # a table component (CSV): played by a player unit
    variables: dict[str, Any] = field(default_factory=dict)  # component: the FMU's variables by name
    unit_definitions: dict[str, Any] = field(default_factory=dict)  # component: the FMU's <UnitDefinitions>
    interface: str | None = None  # component: "model-exchange" | "co-simulation" (implementation, solver)
    settings: dict[str, float] = field(default_factory=dict)  # component: tolerance, max_step (from a solver)
    options: dict[str, Any] = field(default_factory=dict)  # component: cosim's own unit options (org.cosim)


@dataclass
class Edge:
    """One ssd:Connection: its ends (element path, connector), LinearTransformation and suppressUnitConversion."""

    start: tuple[tuple[str, ...], str]
    end: tuple[tuple[str, ...], str]
    factor: float  # LinearTransformation: end = factor * (start converted to the end's unit) + offset
    offset: float
    suppress: bool
    element: Any


def variable_of(node: Node, name: str) -> Any:
    """The FMU variable a connector or parameter name means: ``x`` or an element ``x[i]`` of an array.

    Called several times per connection (10^5 element connections): plain lookups, no properties.
    """
    variables = node.variables
    variable = variables.get(name)
    if variable is not None:
        return variable
    base, bracket, rest = name.partition("[")
    variable = variables.get(base) if bracket else None
    if variable is None or not variable.shape or not rest.endswith("]"):
        return None
    index = rest[:-1]
    return variable if index.isdigit() and 1 <= int(index) <= math.prod(variable.shape) else None


def unit_of(nodes: dict[tuple[str, ...], Node], path: tuple[str, ...], connector: str) -> tuple[str | None, dict]:
    """The unit of a connector: as the SSD declares it, else the FMU variable's; with the FMU's definitions."""
    node = nodes[path]
    if connector in node.connectors and node.connectors[connector].unit:
        return node.connectors[connector].unit, node.unit_definitions
    variable = variable_of(node, connector) if node.kind == "component" else None
    return (getattr(variable, "unit", None) if variable is not None else None), node.unit_definitions


def typed_value(kind: str, text: str | None) -> Any:
    """The value of an ssv type element ``kind`` written as ``text``; raises ValueError when it is none."""
    if text is None:
        raise ValueError(kind)
    if kind in REAL:
        return float(text)
    if kind in INTEGER:
        return int(text)
    if kind == "Boolean":
        if text not in ("true", "false", "1", "0"):
            raise ValueError(text)
        return text in ("true", "1")
    if kind == "Enumeration":
        raise ValueError(text)
    return text
