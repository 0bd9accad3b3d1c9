"""The systems and components of an SSD read into :class:`~cosim.ssp.model.Node`s: their connectors, the FMU
(or CSV table) of each component with its variables, its interface and solver settings, and the unit name each
component gets when the system is flattened."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from cosim.errors import AnnotationNumberError, did_you_mean
from cosim.ssp.annotations import (
    component_solver,
    cosim_unit_options,
    cvode_settings,
    read_system_solvers,
    step_size_hint,
)
from cosim.ssp.bounds import table_size_problem
from cosim.ssp.connections import read_connection
from cosim.ssp.model import (
    FMU_TYPES,
    TABLE_TYPES,
    TYPE_OF,
    Connector,
    Node,
    variable_of,
)
from cosim.ssp.names import cosim_path
from cosim.ssp.reading import Reading
from cosim.ssp.xml import short_name, tag


def read_system(reading: Reading, element: Any, path: tuple[str, ...]) -> Node:
    """The ``ssd:System`` at ``path`` with its elements (recursively) and connections, kept in the reading."""
    node = Node(path, "system", element, read_connectors(element))
    reading.nodes[path] = node
    try:
        read_system_solvers(element, path, reading.solvers)  # before the elements: they are assigned by name
    except AnnotationNumberError as exc:
        reading.bad_number(exc)
    elements = element.find(tag("ssd", "Elements"))
    for child in (elements if elements is not None else []):
        if not isinstance(child.tag, str):
            continue
        name = child.get("name", "")
        child_path = (*path, name)
        if name in node.children:
            reading.problem(child, f"a second element named '{name}' in this system",
                            "give every element of a system its own name")
            continue
        if child.tag == tag("ssd", "System"):
            node.children[name] = read_system(reading, child, child_path)
        elif child.tag == tag("ssd", "Component"):
            node.children[name] = _read_component(reading, child, child_path)
        else:
            reading.problem(child, f"{short_name(child.tag)} is not supported by cosim",
                            "flatten signal dictionaries into plain connections")
    connections = element.find(tag("ssd", "Connections"))
    for connection in (connections if connections is not None else []):
        if isinstance(connection.tag, str) and connection.tag == tag("ssd", "Connection"):
            read_connection(reading, connection, node)
    return node


def read_connectors(element: Any) -> dict[str, Connector]:
    """The ``ssd:Connectors`` of a system or component, by name, with their type and unit."""
    result = {}
    container = element.find(tag("ssd", "Connectors"))
    for c in (container if container is not None else []):
        if not isinstance(c.tag, str) or c.tag != tag("ssd", "Connector"):
            continue
        kind_type, unit = None, None
        for child in c:
            if isinstance(child.tag, str) and child.tag.startswith(f"{{{tag('ssc', '')[1:-1]}}}"):
                local = child.tag.split("}")[1]
                if local in TYPE_OF:
                    kind_type, unit = TYPE_OF[local], child.get("unit")
        result[c.get("name")] = Connector(c.get("name"), c.get("kind"), kind_type, unit, c)
    return result


def components(reading: Reading) -> list[Node]:
    """The components that run: those whose FMU or table was found and read."""
    return [n for n in reading.nodes.values() if n.kind == "component" and (n.fmu or n.table) is not None]


def unit_names(reading: Reading) -> dict[tuple[str, ...], str]:
    """The unit name of every component (its path below the root system renamed by
    :func:`~cosim.ssp.names.cosim_path`, with a note); a problem when two flatten to one name."""
    names: dict[tuple[str, ...], str] = {}
    seen: dict[str, tuple[str, ...]] = {}
    for node in components(reading):
        name = cosim_path(node.path)  # a component's own name may hold dots (exported from a flattened system)
        if name != ".".join(node.path):
            reading.alike.add("renamed", f"component '{'.'.join(node.path)}' is called '{name}' (names keep ASCII "
                              "letters, digits, _)", f"'{name}'", "more components renamed likewise")
        if name in seen:
            reading.problem(node.element, f"two components flatten to the same unit name '{name}'",
                            "rename one of them")
        seen[name] = node.path
        names[node.path] = name
    return names


def _read_component(reading: Reading, element: Any, path: tuple[str, ...]) -> Node:
    node = Node(path, "component", element, read_connectors(element))
    reading.nodes[path] = node
    kind = element.get("type", FMU_TYPES[0])
    if kind in TABLE_TYPES:
        return _read_table(reading, node)
    if kind not in FMU_TYPES:
        reading.problem(element, f"component type '{kind}' is not supported (FMUs: {FMU_TYPES[0]}; "
                        f"CSV tables: {' or '.join(TABLE_TYPES)})",
                        "export the component as an FMU, or inline its SSD as an ssd:System")
        return node
    source = element.get("source")
    if not source:
        reading.problem(element, "the component has no 'source'", "set source=\"resources/model.fmu\"")
        return node
    if reading.leaves_ssp(source, reading.files.ssd.parent, element):
        return node
    fmu = reading.resolve(source, reading.files.ssd.parent)
    if fmu is None:
        where = "in the archive" if reading.files.beside else "in the SSP's folder"
        reading.problem(element, f"FMU '{source}' not found {where}"
                        + (" nor next to the archive" if reading.files.beside else ""),
                        "put the FMU under resources/ of the SSP, or fix the component's 'source'")
        return node
    node.fmu = fmu
    if not _choose_interface(reading, node):
        return node
    node.options = cosim_unit_options(element)
    from cosim.errors import FmuProblems
    from cosim.units.fmu.description import FmuUnitType

    try:
        description = FmuUnitType(fmu, reference=source, interface=node.interface).describe()
    except FmuProblems as exc:
        for problem in exc.problems:
            reading.problem(element, f"FMU '{source}' cannot be used: {problem.message}",
                            problem.fix or "re-export the FMU for co-simulation (FMI 2.0 or 3.0) with a binary "
                            "for this platform")
        return node
    except Exception as exc:  # noqa: BLE001 - a broken FMU is the user's file: a problem, never a traceback
        reading.problem(element, f"cannot read FMU '{source}': {type(exc).__name__}: {exc}",
                        "re-export the FMU from its tool (cosim inspect it alone to see more)")
        return node
    node.variables = {v.name: v for v in description.variables}
    node.unit_definitions = dict(description.unit_definitions)
    for name, connector in node.connectors.items():
        if variable_of(node, name) is None:
            reading.problem(connector.element, f"connector '{name}' is not a variable of FMU '{source}'."
                            + did_you_mean(name, node.variables),
                            f"use a variable the FMU has (cosim inspect {Path(source).name} lists them), "
                            "or remove the connector")
    return node


def _read_table(reading: Reading, node: Node) -> Node:
    """A table component (``type="text/csv"``, OMSimulator's form): its columns but ``time`` are outputs,
    played with linear interpolation (as OMSimulator does)."""
    element = node.element
    source = element.get("source")
    if not source:
        reading.problem(element, "the table component has no 'source'", "set source=\"resources/table.csv\"")
        return node
    if not source.lower().endswith(".csv"):
        reading.problem(element, f"table '{source}' is no CSV file: cosim reads table components from CSV only "
                        "(not MAT result files)", "export the table as CSV (a 'time' column, then one column per "
                        "output) and point the component's source at it")
        return node
    if reading.leaves_ssp(source, reading.files.ssd.parent, element):
        return node
    path = reading.resolve(source, reading.files.ssd.parent)
    if path is None:
        reading.problem(element, f"table '{source}' not found", "put the CSV under resources/ of the SSP, or fix "
                        "the component's 'source'")
        return node
    too_large = table_size_problem(path, reading.files.label(path))
    if too_large is not None:  # refused before pandas reads it (a table takes several times its size)
        reading.problems.append(too_large)
        return node
    from cosim.units.player import PlayerUnitType

    try:
        description = PlayerUnitType(path, all_real=True).describe()
    except Exception as exc:  # noqa: BLE001 - the user's file: a problem, never a traceback
        reading.problem(element, f"cannot read table '{source}': {exc}", "write a CSV with a 'time' column "
                        "(non-decreasing) and numeric columns")
        return node
    node.table = path
    node.variables = {v.name: v for v in description.variables}
    from cosim.units.player import csv_separator_line

    if csv_separator_line(path):
        reading.note(f"{reading.files.label(path)} starts with a 'sep=' line (a spreadsheet's separator hint, as "
                     "OMSimulator's result files have); CSV has none: skipped")
    for name, connector in node.connectors.items():
        if name not in node.variables:
            reading.problem(connector.element, f"connector '{name}' is not a column of {source}."
                            + did_you_mean(name, node.variables),
                            f"name a column: {', '.join(list(node.variables)[:12])}")
        elif connector.kind not in ("output", None):
            reading.problem(connector.element, f"connector '{name}' of a table is kind=\"{connector.kind}\"",
                            "a table's columns are outputs: write kind=\"output\"")
    return node


def _choose_interface(reading: Reading, node: Node) -> bool:
    """The component's interface and solver settings from ``implementation`` and an OMSimulator solver
    assigned to it (cvode or euler: model exchange); False when ``implementation`` is refused."""
    element = node.element
    implementation = element.get("implementation")
    if implementation == "ScheduledExecution":
        reading.problem(element, "implementation=\"ScheduledExecution\" is not supported",
                        "use implementation=\"CoSimulation\" or \"ModelExchange\" (or \"any\")")
        return False
    node.interface = {"ModelExchange": "model-exchange", "CoSimulation": "co-simulation"}.get(implementation or "")
    name = ".".join(node.path)
    solvers = reading.solvers
    solver = component_solver(element)
    if solver is not None:
        definition = solvers.definitions.get(solver)
        if definition is None:
            solvers.unused.add(f"component '{name}' is assigned solver '{solver}', which no system "
                               "defines: ignored")
        elif definition.get("method") in ("cvode", "euler"):
            if node.interface == "co-simulation":
                solvers.unused.add(f"component '{name}' has implementation=\"CoSimulation\" and the "
                                   f"model-exchange solver '{solver}': it runs as co-simulation")
            else:
                node.interface = "model-exchange"
                if definition.get("method") == "cvode":
                    node.settings = cvode_settings(definition)
    if node.interface == "model-exchange" and not node.settings:
        for depth in range(len(node.path) - 1, -1, -1):  # OMSimulator 2: the nearest system's cvode
            if node.path[:depth] in solvers.system_cvode:
                node.settings = cvode_settings(solvers.system_cvode[node.path[:depth]])
                break
    try:
        hint = step_size_hint(element)
    except AnnotationNumberError as exc:
        reading.bad_number(exc)
        hint = None
    if hint is not None:
        reading.hints.append(f"{name} {hint:g} s")
    return True
