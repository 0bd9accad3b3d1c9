"""A spec's ``connectors`` units exported as the SSP system connectors they stand for.

A ``connectors`` unit named ``Root.sub`` (how :mod:`cosim.ssp` names the connectors of system ``sub`` below the
root system ``Root``) becomes the system ``sub`` (nested below the root system, which is then named ``Root``):

- each input ``c`` of the unit, fed by ``unit.port`` with a factor and offset, becomes the system's connector
  ``c`` of kind ``output``, fed by a connection from the component ``unit`` through the systems on the way, the
  factor and offset as the ``LinearTransformation`` of the first connection (units of measure: the connector
  declares the input's, and every connection suppresses conversion, as the factor already holds it); a system
  between the root and ``sub`` passes the value on through an ``input`` connector named by the rest of the path
  (``b_c`` for ``c`` of ``Root.a.b``);
- each parameter ``k`` becomes the system's ``parameter`` connector ``k`` with the value bound to it (inline
  ``ssd:ParameterValues``); the unit parameters it ``feeds`` (an SSP's parameter connections) are fed by a
  connection from it with the feed's factor and offset as ``LinearTransformation`` (through ``parameter``
  connectors ``b_k`` of the systems on the way) instead of a value of their own, so that a design parameter
  naming ``Root.sub.k`` sets them again when the archive is read back.

Reading the archive back (:mod:`cosim.ssp.system_connectors`) gives the same signals: ``Root.sub.c`` is factor
x ``unit.port`` + offset, ``Root.sub.k`` the constant, so a spec recording them records the same traces.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

from cosim.errors import Problem

_TYPES = ((bool, "Boolean"), (int, "Integer"), (float, "Real"), (str, "String"))


@dataclass
class _System:
    """A system to write: its connectors (name, kind, SSP type, unit), bound values, sub-systems, connections."""

    connectors: list[tuple[str, str, str, str | None]] = field(default_factory=list)
    values: list[tuple[str, str, Any]] = field(default_factory=list)
    children: dict[str, _System] = field(default_factory=dict)
    # (startElement, startConnector, endElement, endConnector, (factor, offset) or None)
    connections: list[tuple[str, str, str, str, tuple[float, float] | None]] = field(default_factory=list)


def connectors_units(system: Any) -> dict[str, Any]:
    """The ``connectors`` units of a built system, by name."""
    return {name: unit for name, unit in system.units.items() if unit.spec.kind == "connectors"}


def root_name(system: Any) -> str | None:
    """The root system's name the ``connectors`` units give (the first part of their names), None without any."""
    names = list(connectors_units(system))
    return names[0].split(".")[0] if names else None


def export_problems(system: Any) -> list[Problem]:
    """Why the ``connectors`` units cannot become one SSP's system connectors: they name different root systems,
    or a sub-system would have a component's name."""
    units = connectors_units(system)
    if not units:
        return []
    spec = system.spec
    root = root_name(system)
    problems = [Problem(spec.path, f"$.units.{name}", f"the connectors unit '{name}' names the root system "
                        f"'{name.split('.')[0]}', another connectors unit '{root}': an SSP has one root system",
                        f"name every connectors unit below one root system ('{root}.{name.split('.')[-1]}')")
                for name in units if name.split(".")[0] != root]
    components = {name for name in system.units if name not in units}
    for name in units:
        first = name.split(".")[1:2]
        if first and first[0] in components:
            problems.append(Problem(spec.path, f"$.units.{name}", f"the connectors unit '{name}' becomes the "
                                    f"sub-system '{first[0]}', which is also the name of a unit",
                                    f"rename the unit '{first[0]}' or the connectors unit"))
    return problems


def unit_feeds(system: Any, unit: Any) -> dict[str, list[dict]]:
    """The ``feeds`` of a ``connectors`` unit into unit parameters; feeds into another ``connectors`` unit's
    constant (a nested connector taking its value from this one) are left out: the export writes that constant
    with its own value."""
    others = connectors_units(system)
    return {connector: [f for f in feeds if f["to"].rpartition(".")[0] not in others]
            for connector, feeds in (unit.spec.options.get("feeds") or {}).items()}


def fed_parameters(system: Any) -> dict[str, tuple[str, str, float, float]]:
    """The unit parameters the ``connectors`` units feed: 'unit.param' -> (connectors unit, its parameter,
    factor, offset)."""
    fed = {}
    for name, unit in connectors_units(system).items():
        for connector, feeds in unit_feeds(system, unit).items():
            for feed in feeds:
                fed[feed["to"]] = (name, connector, float(feed.get("factor", 1.0)), float(feed.get("offset", 0.0)))
    return fed


def fed_value_problems(system: Any, values: dict[str, list[tuple[str, str, Any]]]) -> list[Problem]:
    """A problem for every fed parameter whose own value (``values``: unit -> (port, type, value)) is not what its
    connector feeds it: an SSP holds one of the two."""
    problems = []
    for target, (name, connector, factor, offset) in fed_parameters(system).items():
        unit, _, port = target.rpartition(".")
        constant = system.units[name].unit_type.constants.get(connector)
        fed = constant if (factor, offset) == (1.0, 0.0) else factor * constant + offset
        own = next((v for p, _, v in values.get(unit, ()) if p == port), fed)
        if own != fed:
            problems.append(Problem(system.spec.path, f"$.units.{unit}.parameters.{port}",
                                    f"'{target}' is {own!r} here, but the system connector '{name}.{connector}' "
                                    f"feeds it {fed!r}: an SSP holds one of them",
                                    f"drop the value of '{target}' (or set '{name}.{connector}' instead)"))
    return problems


def is_connectors_target(system: Any, connection: Any) -> bool:
    """Whether ``connection`` feeds a ``connectors`` unit (written by :func:`write_system_connectors`)."""
    return system.units[connection.target.unit].spec.kind == "connectors"


def write_system_connectors(system: Any, top: Any, elements: Any, connections: Any, e: Callable,
                            element_names: Callable) -> None:
    """The ``connectors`` units of ``system`` as system connectors: the root system's own (on ``top``, whose
    ``ssd:Connectors`` and ``ssd:ParameterBindings`` are inserted before its ``elements``) and nested sub-systems
    (appended to ``elements``), with the connections feeding them (appended to ``connections``).  ``e`` makes an
    element (``e(parent, prefix, tag, **attributes)``), ``element_names`` gives a connection end's connectors."""
    tree = _tree(system, element_names)
    if tree.connectors:
        position = list(top).index(elements)
        holder = e(top, "ssd", "Connectors")
        top.remove(holder)
        top.insert(position, holder)
        _fill_connectors(holder, tree, e)
        if tree.values:
            bindings = _bindings(top, tree, e)
            top.remove(bindings)
            top.insert(position + 1, bindings)
    for name, child in tree.children.items():
        _write(elements, name, child, e)
    _write_connections(connections, tree, e)


def _tree(system: Any, element_names: Callable) -> _System:
    root = _System()
    feeding = {(c.target.unit, c.target.variable.name): c for c in system.connections
               if is_connectors_target(system, c)}
    for name, unit in connectors_units(system).items():
        path = tuple(name.split(".")[1:])
        systems = [root]
        for part in path:
            systems.append(systems[-1].children.setdefault(part, _System()))
        target = systems[-1]
        unit_type = unit.unit_type
        for connector, measure in unit_type.inputs.items():
            target.connectors.append((connector, "output", "Real", measure or None))
            connection = feeding.get((name, connector))
            if connection is None:
                continue
            [start] = element_names(connection.source)
            transform = (connection.factor, connection.offset) if connection.transforms else None
            if not path:
                root.connections.append((connection.source.unit, start, "", connector, transform))
                continue
            # root: unit.port -> path[0].via ... path[-1]: "" via -> "" connector (its own, kind output)
            via = ["_".join((*path[k + 1:], connector)) for k in range(len(path))]
            root.connections.append((connection.source.unit, start, path[0], via[0], transform))
            for depth in range(1, len(path)):
                systems[depth].connectors.append((via[depth - 1], "input", "Real", measure or None))
                systems[depth].connections.append(("", via[depth - 1], path[depth], via[depth], None))
        feeds = unit_feeds(system, unit)
        for constant, value in unit_type.constants.items():
            kind = next(t for python, t in _TYPES if isinstance(value, python))
            target.connectors.append((constant, "parameter", kind, None))
            target.values.append((constant, kind, value))
            if not feeds.get(constant):
                continue
            # outwards: path[-1].k -> path[:-1]'s own via ... -> the root: path[0].via -> each fed unit parameter
            via = ["_".join((*path[d:], constant)) for d in range(len(path) + 1)]  # via[len(path)] == k
            for depth in range(len(path) - 1, 0, -1):
                systems[depth].connectors.append((via[depth], "parameter", kind, None))
                systems[depth].connections.append((path[depth], via[depth + 1], "", via[depth], None))
            for feed in feeds[constant]:
                fed_unit, _, fed_port = feed["to"].rpartition(".")
                factor, offset = float(feed.get("factor", 1.0)), float(feed.get("offset", 0.0))
                transform = (factor, offset) if (factor, offset) != (1.0, 0.0) else None
                root.connections.append((path[0] if path else "", via[1] if path else constant, fed_unit, fed_port,
                                         transform))
    return root


def _write(parent_elements: Any, name: str, node: _System, e: Callable) -> None:
    element = e(parent_elements, "ssd", "System", name=name)
    if node.connectors:
        _fill_connectors(e(element, "ssd", "Connectors"), node, e)
    if node.values:
        _bindings(element, node, e)
    if node.children:
        elements = e(element, "ssd", "Elements")
        for child_name, child in node.children.items():
            _write(elements, child_name, child, e)
    if node.connections:
        _write_connections(e(element, "ssd", "Connections"), node, e)


def _fill_connectors(holder: Any, node: _System, e: Callable) -> None:
    for name, kind, ssp_type, measure in node.connectors:
        connector = e(holder, "ssd", "Connector", name=name, kind=kind)
        e(connector, "ssc", ssp_type, **({"unit": measure} if measure and ssp_type == "Real" else {}))


def _bindings(element: Any, node: _System, e: Callable) -> Any:
    bindings = e(element, "ssd", "ParameterBindings")
    values = e(e(bindings, "ssd", "ParameterBinding"), "ssd", "ParameterValues")
    parameters = e(e(values, "ssv", "ParameterSet", version="2.0", name="connectors"), "ssv", "Parameters")
    for name, kind, value in node.values:
        e(e(parameters, "ssv", "Parameter", name=name), "ssv", kind, value=value)
    return bindings


def _write_connections(holder: Any, node: _System, e: Callable) -> None:
    for start_element, start, end_element, end, transform in node.connections:
        connection = e(holder, "ssd", "Connection", startElement=start_element or None, startConnector=start,
                       endElement=end_element or None, endConnector=end, suppressUnitConversion="true")
        if transform is not None:
            e(connection, "ssc", "LinearTransformation", factor=transform[0], offset=transform[1])
