"""Read an SSP's system and flatten it into the content of a spec.json.

:func:`read_ssp` walks the root ``ssd:System``: every ``ssd:Component`` (an
FMU) becomes a unit named by its path below the root system, e.g.
``SuT.edrive_mass``; nested systems only contribute their connectors.  A
connection chain ``A.y -> system connector -> ... -> B.u`` becomes one
connection ``A.y -> B.u`` whose factor and offset compose the unit
conversions (from ``ssd:Units``, unless ``suppressUnitConversion``; a system
connector without a unit passes the unit through) and
``LinearTransformation``s along the chain (SSP: target = factor * converted
source + offset).  Parameter bindings (inline or .ssv, with ``prefix`` and
.ssm mappings) become unit parameters and start values; bindings of a higher
system win over lower ones, later bindings over earlier ones at one level.
A value reaching an FMU parameter through a parameter connection counts as
bound where the system connector's value was bound.  A table component (CSV,
``type="text/csv"``) becomes a player.  The experiment comes from
``DefaultExperiment`` and the step size from OMSimulator's ``FixedStepMaster``
or ``oms_ma`` solver, or OSP's ``FixedStepAlgorithm``; ``implementation`` and
OMSimulator's solvers give a component's interface and solver settings (see
:mod:`.annotations`); what is missing is left to the spec or the command line.
Forms tools write against the schema are read with a note (:mod:`.tolerant`).

Every problem is collected (file in the archive, element path, fix) and
raised at the end as one SpecError; nothing else escapes for any input file.
"""

from __future__ import annotations

import logging
import re
import urllib.parse
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lxml import etree

from cosim.errors import AnnotationNumberError, Problem, SpecError, did_you_mean
from cosim.master.algorithms import ALGORITHMS
from cosim.ssp.annotations import (Solvers, component_solver, cvode_settings, number, read_system_solvers,
                                   step_size_hint, unread_annotation_types)
from cosim.ssp.archive import SspFiles, open_ssp
from cosim.ssp.tolerant import tolerated
from cosim.ssp.xml import display_name, element_path, parse_file, schema_problems, short_name, tag
from cosim.util.quantities import BASE_UNITS, IncompatibleUnits, UnitDefinition, UnknownUnit, conversion

log = logging.getLogger("cosim.ssp")

_REAL = {"Real", "Float64", "Float32"}
_INTEGER = {"Integer", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64"}
_TYPE_OF = {**{t: "Real" for t in _REAL}, **{t: "Integer" for t in _INTEGER}, "Boolean": "Boolean",
            "String": "String", "Enumeration": "Integer"}
FMU_TYPES = ("application/x-fmu-sharedlibrary",)
TABLE_TYPES = ("text/csv", "application/table")  # OMSimulator 3 and 2: a table whose columns are outputs
_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_LOGGED: set[tuple[str, str]] = set()


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
    children: dict[str, "Node"] = field(default_factory=dict)
    fmu: Path | None = None
    table: Path | None = None  # a table component (CSV): played by a player unit
    variables: dict[str, Any] = field(default_factory=dict)  # component: the FMU's variables by name
    unit_definitions: dict[str, Any] = field(default_factory=dict)  # component: the FMU's <UnitDefinitions>
    interface: str | None = None  # component: "model-exchange" | "co-simulation" (implementation, solver)
    settings: dict[str, float] = field(default_factory=dict)  # component: tolerance, max_step (from a solver)


@dataclass
class Edge:
    """One ssd:Connection: its ends (element path, connector), LinearTransformation and suppressUnitConversion."""

    start: tuple[tuple[str, ...], str]
    end: tuple[tuple[str, ...], str]
    factor: float  # LinearTransformation: end = factor * (start converted to the end's unit) + offset
    offset: float
    suppress: bool
    element: Any


@dataclass
class SspSystem:
    """An SSP read and flattened: ``raw`` is the content of an equivalent spec.json."""

    files: SspFiles
    raw: dict
    notes: list[str]
    system_connectors: list[str] = field(default_factory=list)  # 'Root.sub.connector', for messages
    # 'Root.sub.connector' (and 'sub.connector') -> what it carries: ("port", 'unit.port', factor, offset) for a
    # connector fed by a component output, ("value", v) for one holding a bound value (see connector_signals)
    connector_signals: dict[str, tuple] = field(default_factory=dict)
    root_system: str = ""


def read_ssp(path: str | Path, variant: str | None = None) -> SspSystem:
    """Read, check and flatten the SSP at ``path`` (.ssp, folder or .ssd), its SSD of ``variant`` if given (see
    :func:`~cosim.ssp.archive.open_ssp`); raises SpecError."""
    return _Reader(open_ssp(path, variant)).read()


class _Reader:
    def __init__(self, files: SspFiles):
        self.files = files
        self.label = files.label(files.ssd)
        self.problems: list[Problem] = []
        self.notes: list[str] = []
        for note in files.notes:
            self._note(note)
        self.units: dict[str, UnitDefinition] = {}  # ssd:Units
        self.nodes: dict[tuple[str, ...], Node] = {}
        self.edges: list[Edge] = []
        self.bindings: list[tuple[int, int, tuple[tuple[str, ...], str], Any, str | None, Any, str]] = []
        self._order = 0
        self._into: dict[tuple, Edge] = {}  # connection end -> the connection feeding it (see _connections)
        self._system_values: dict[tuple, tuple] = {}  # system connector -> its chosen binding
        self._prefixed: set[tuple[str, tuple[str, ...]]] = set()  # (file, component) noted for Component.param
        self.solvers = Solvers()
        self._hints: list[str] = []  # OSP step size hints, for one note

    # --- the document ---------------------------------------------------

    def read(self) -> SspSystem:
        root = self._parse(self.files.ssd, self.label, "ssd")
        if root is None:
            raise SpecError(self.problems)
        self.units.update(self._read_units(root, self.label))
        system = root.find(tag("ssd", "System"))
        self._read_system(system, ())
        self._read_bindings_everywhere(system, ())
        experiment = self._experiment(root)
        if self.problems:
            raise SpecError(self.problems)
        unit_names = self._unit_names()
        if self.problems:
            raise SpecError(self.problems)
        units = {unit_names[n.path]: self._raw_unit(n) for n in self._components()}
        self._note_unread(root)
        connections = self._connections(unit_names)
        self._apply_bindings(units, unit_names)
        if self.problems:
            raise SpecError(self.problems)
        raw = {"name": root.get("name", self.files.ssd.stem), "units": units, "connections": connections,
               "experiment": experiment, "record": [f"{name}.*" for name in units]}
        if root.get("description"):
            raw["description"] = root.get("description")
        root_name = system.get("name", "")
        connectors = [".".join((root_name, *n.path, c)) for n in self.nodes.values() if n.kind == "system"
                      for c in n.connectors]
        return SspSystem(self.files, raw, self.notes, connectors, self._connector_signals(unit_names, root_name),
                         root_name)

    def _connector_signals(self, unit_names: dict, root_name: str) -> dict[str, tuple]:
        """What every system connector carries, by its name with and without the root system's name.

        A connector fed (through a chain) by a component output carries factor x that output + offset (the
        chain's conversions and transformations); one holding a bound value carries that value.  A connector
        whose chain cannot be followed (a loop, units that do not convert) carries nothing known and is left
        out: this is for naming connectors in a spec, the SSP was checked already.
        """
        signals: dict[str, tuple] = {}
        problems = list(self.problems)
        for node in self.nodes.values():
            if node.kind != "system":
                continue
            for name in node.connectors:
                end = (node.path, name)
                carried: tuple | None = None
                if end in self._into:
                    chain = self._chain(end)
                    start = chain[0].start
                    if self.nodes[start[0]].kind == "component" and start[0] in unit_names:
                        factor, offset = self._compose(chain, self._unit_of(*start))
                        carried = ("port", f"{unit_names[start[0]]}.{start[1]}", factor, offset)
                    elif start in self._system_values:
                        carried = ("value", self._system_values[start][2])
                elif end in self._system_values:
                    carried = ("value", self._system_values[end][2])
                if carried is not None:
                    signals[".".join((root_name, *node.path, name))] = carried
                    signals.setdefault(".".join((*node.path, name)), carried)
        self.problems[:] = problems  # a chain only named here (no FMU input at its end) reports nothing new
        return signals

    def _parse(self, path: Path, label: str, kind: str) -> Any:
        """The root of an SSP file checked against the schema, or None (its problems recorded).

        A file in a form popular tools write against the schema (see :mod:`.tolerant`) is read as corrected,
        with a note per correction; when the correction does not satisfy the schema either, the original's
        problems are reported, so that they point at the user's own file.
        """
        root, problems = parse_file(path, label, kind)
        if root is not None and problems:
            fixed, notes = tolerated(root, label)
            if notes and not schema_problems(fixed, label, kind):
                for note in notes:
                    self._note(note)
                return fixed
        self.problems.extend(problems)
        return None if problems else root

    def _checked_inline(self, root: Any, label: str, kind: str) -> Any:
        """An inline ssv:ParameterSet or ssm:ParameterMapping checked against its schema (tolerated forms
        corrected, as :meth:`_parse`), or None with its problems recorded."""
        problems = schema_problems(root, label, kind)
        if problems:
            fixed, notes = tolerated(root, label)
            if notes and not schema_problems(fixed, label, kind):
                for note in notes:
                    self._note(note)
                return fixed
            self.problems.extend(problems)
            return None
        return root

    def _raw_unit(self, node: Node) -> dict:
        """The spec entry of one component: an FMU unit, or a player of a table component."""
        if node.table is not None:
            # every column Real and interpolated linearly, as OMSimulator plays a table
            unit: dict[str, Any] = {"player": self.files.reference(node.table), "interpolation": "linear",
                                    "all_real": True}
            if node.connectors:
                unit["columns"] = list(node.connectors)
            return unit
        return {"fmu": self.files.reference(node.fmu), **({"interface": node.interface} if node.interface else {}),
                **node.settings}

    def _note(self, text: str) -> None:
        self.notes.append(text)
        if (self.files.given, text) not in _LOGGED:  # an SSP is often read twice (validate, then run)
            _LOGGED.add((self.files.given, text))
            log.warning("%s: %s", self.files.given, text)

    def _problem(self, element: Any, message: str, fix: str, label: str | None = None) -> None:
        where = element_path(element) if element is not None else "/"
        self.problems.append(Problem(label or self.label, where, message, fix))

    # --- units (ssd:Units / ssv:Units) ------------------------------------

    @staticmethod
    def _read_units(root: Any, label: str) -> dict[str, UnitDefinition]:
        """The ssd:Units (or ssv:Units) definitions: SI value = factor * value + offset."""
        units = {}
        container = root.find(tag("ssd", "Units"))
        if container is None:
            container = root.find(tag("ssv", "Units"))
        if container is None:
            return units
        for unit in container.findall(tag("ssc", "Unit")):
            base = unit.find(tag("ssc", "BaseUnit"))
            get = (lambda k, d=0: base.get(k, d)) if base is not None else (lambda k, d=0: d)
            exponents = tuple(int(get(k)) for k in BASE_UNITS)
            name = unit.get("name")
            units[name] = UnitDefinition(name, exponents, float(get("factor", 1)), float(get("offset", 0)))
        return units

    def _conversion(self, source: tuple | None, target: tuple | None, element: Any,
                    units: dict | None = None, label: str | None = None) -> tuple[float, float]:
        """(a, b) with value_in_target = a * value_in_source + b.

        ``source`` and ``target`` are (unit name, the FMU's own unit
        definitions); ssd:Units (and an .ssv's Units) define names first, then
        the FMU's, then :mod:`cosim.util.quantities` reads the name.
        Identity when a unit is missing or both are equal.
        """
        if not source or not target or not source[0] or not target[0] or source[0] == target[0]:
            return 1.0, 0.0
        ssd_units = {**self.units, **(units or {})}
        for name in (source[0], target[0]):
            bare = re.fullmatch(r"\[\s*([^\]]*?)\s*\]", name)
            if bare and name not in ssd_units:
                self._problem(element, f"unit '{name}' is written in brackets; SSP and FMI write units without them",
                              f"write unit=\"{bare.group(1)}\"", label)
                return 1.0, 0.0
        try:
            return conversion(source[0], target[0], {**source[1], **ssd_units}, {**target[1], **ssd_units})
        except UnknownUnit as exc:
            self._problem(element, f"cannot convert '{source[0]}' to '{target[0]}': {exc}",
                          "define the unit under ssd:Units (ssc:Unit with its ssc:BaseUnit), or set "
                          "suppressUnitConversion=\"true\"", label)
        except IncompatibleUnits as exc:
            self._problem(element, f"units '{source[0]}' and '{target[0]}' measure different quantities: {exc}",
                          "connect compatible quantities, or set suppressUnitConversion=\"true\" and give a "
                          "LinearTransformation", label)
        return 1.0, 0.0

    # --- systems, components, connectors ----------------------------------

    def _read_system(self, element: Any, path: tuple[str, ...]) -> Node:
        node = Node(path, "system", element, self._connectors(element))
        self.nodes[path] = node
        try:
            read_system_solvers(element, path, self.solvers)  # before the elements: they are assigned by name
        except AnnotationNumberError as exc:
            self._bad_number(exc)
        elements = element.find(tag("ssd", "Elements"))
        for child in (elements if elements is not None else []):
            if not isinstance(child.tag, str):
                continue
            name = child.get("name", "")
            child_path = (*path, name)
            if name in node.children:
                self._problem(child, f"a second element named '{name}' in this system",
                              "give every element of a system its own name")
                continue
            if child.tag == tag("ssd", "System"):
                node.children[name] = self._read_system(child, child_path)
            elif child.tag == tag("ssd", "Component"):
                node.children[name] = self._read_component(child, child_path)
            else:
                self._problem(child, f"{short_name(child.tag)} is not supported by cosim",
                              "flatten signal dictionaries into plain connections")
        connections = element.find(tag("ssd", "Connections"))
        for connection in (connections if connections is not None else []):
            if isinstance(connection.tag, str) and connection.tag == tag("ssd", "Connection"):
                self._read_connection(connection, node)
        return node

    def _connectors(self, element: Any) -> dict[str, Connector]:
        result = {}
        container = element.find(tag("ssd", "Connectors"))
        for c in (container if container is not None else []):
            if not isinstance(c.tag, str) or c.tag != tag("ssd", "Connector"):
                continue
            kind_type, unit = None, None
            for child in c:
                if isinstance(child.tag, str) and child.tag.startswith(f"{{{tag('ssc', '')[1:-1]}}}"):
                    local = child.tag.split("}")[1]
                    if local in _TYPE_OF:
                        kind_type, unit = _TYPE_OF[local], child.get("unit")
            result[c.get("name")] = Connector(c.get("name"), c.get("kind"), kind_type, unit, c)
        return result

    def _read_component(self, element: Any, path: tuple[str, ...]) -> Node:
        node = Node(path, "component", element, self._connectors(element))
        self.nodes[path] = node
        kind = element.get("type", FMU_TYPES[0])
        if kind in TABLE_TYPES:
            return self._read_table(node)
        if kind not in FMU_TYPES:
            self._problem(element, f"component type '{kind}' is not supported (FMUs: {FMU_TYPES[0]}; "
                          f"CSV tables: {' or '.join(TABLE_TYPES)})",
                          "export the component as an FMU, or inline its SSD as an ssd:System")
            return node
        source = element.get("source")
        if not source:
            self._problem(element, "the component has no 'source'", "set source=\"resources/model.fmu\"")
            return node
        fmu = self._resolve(source, self.files.ssd.parent)
        if fmu is None:
            where = "in the archive" if self.files.beside else "in the SSP's folder"
            self._problem(element, f"FMU '{source}' not found {where}"
                          + (" nor next to the archive" if self.files.beside else ""),
                          "put the FMU under resources/ of the SSP, or fix the component's 'source'")
            return node
        node.fmu = fmu
        if not self._choose_interface(node):
            return node
        from cosim.units.fmu.description import FmuProblems, FmuUnitType

        try:
            description = FmuUnitType(fmu, reference=source, interface=node.interface).describe()
        except FmuProblems as exc:
            for problem in exc.problems:
                self._problem(element, f"FMU '{source}' cannot be used: {problem.message}",
                              problem.fix or "re-export the FMU for co-simulation (FMI 2.0 or 3.0) with a binary "
                              "for this platform")
            return node
        except Exception as exc:  # noqa: BLE001 - a broken FMU is the user's file: a problem, never a traceback
            self._problem(element, f"cannot read FMU '{source}': {type(exc).__name__}: {exc}",
                          "re-export the FMU from its tool (cosim inspect it alone to see more)")
            return node
        node.variables = {v.name: v for v in description.variables}
        node.unit_definitions = dict(description.unit_definitions)
        for name, connector in node.connectors.items():
            if _variable(node, name) is None:
                self._problem(connector.element, f"connector '{name}' is not a variable of FMU '{source}'."
                              + did_you_mean(name, node.variables),
                              f"use a variable the FMU has (cosim inspect {Path(source).name} lists them), "
                              "or remove the connector")
        return node

    def _read_table(self, node: Node) -> Node:
        """A table component (``type="text/csv"``, OMSimulator's form): its columns but ``time`` are outputs,
        played with linear interpolation (as OMSimulator does)."""
        element = node.element
        source = element.get("source")
        if not source:
            self._problem(element, "the table component has no 'source'", "set source=\"resources/table.csv\"")
            return node
        if not source.lower().endswith(".csv"):
            self._problem(element, f"table '{source}' is no CSV file: cosim reads table components from CSV only "
                          "(not MAT result files)", "export the table as CSV (a 'time' column, then one column per "
                          "output) and point the component's source at it")
            return node
        path = self._resolve(source, self.files.ssd.parent)
        if path is None:
            self._problem(element, f"table '{source}' not found", "put the CSV under resources/ of the SSP, or fix "
                          "the component's 'source'")
            return node
        from cosim.units.player import PlayerUnitType

        try:
            description = PlayerUnitType(path, all_real=True).describe()
        except Exception as exc:  # noqa: BLE001 - the user's file: a problem, never a traceback
            self._problem(element, f"cannot read table '{source}': {exc}", "write a CSV with a 'time' column "
                          "(non-decreasing) and numeric columns")
            return node
        node.table = path
        node.variables = {v.name: v for v in description.variables}
        from cosim.units.player import csv_separator_line

        if csv_separator_line(path):
            self._note(f"{self.files.label(path)} starts with a 'sep=' line (a spreadsheet's separator hint, as "
                       "OMSimulator's result files have); CSV has none: skipped")
        for name, connector in node.connectors.items():
            if name not in node.variables:
                self._problem(connector.element, f"connector '{name}' is not a column of {source}."
                              + did_you_mean(name, node.variables),
                              f"name a column: {', '.join(list(node.variables)[:12])}")
            elif connector.kind not in ("output", None):
                self._problem(connector.element, f"connector '{name}' of a table is kind=\"{connector.kind}\"",
                              "a table's columns are outputs: write kind=\"output\"")
        return node

    def _choose_interface(self, node: Node) -> bool:
        """The component's interface and solver settings from ``implementation`` and an OMSimulator solver
        assigned to it (cvode or euler: model exchange); False when ``implementation`` is refused."""
        element = node.element
        implementation = element.get("implementation")
        if implementation == "ScheduledExecution":
            self._problem(element, "implementation=\"ScheduledExecution\" is not supported",
                          "use implementation=\"CoSimulation\" or \"ModelExchange\" (or \"any\")")
            return False
        node.interface = {"ModelExchange": "model-exchange", "CoSimulation": "co-simulation"}.get(implementation or "")
        name = ".".join(node.path)
        solver = component_solver(element)
        if solver is not None:
            definition = self.solvers.definitions.get(solver)
            if definition is None:
                self.solvers.unused.add(f"component '{name}' is assigned solver '{solver}', which no system "
                                        "defines: ignored")
            elif definition.get("method") in ("cvode", "euler"):
                if node.interface == "co-simulation":
                    self.solvers.unused.add(f"component '{name}' has implementation=\"CoSimulation\" and the "
                                            f"model-exchange solver '{solver}': it runs as co-simulation")
                else:
                    node.interface = "model-exchange"
                    if definition.get("method") == "cvode":
                        node.settings = cvode_settings(definition)
        if node.interface == "model-exchange" and not node.settings:
            for depth in range(len(node.path) - 1, -1, -1):  # OMSimulator 2: the nearest system's cvode
                if node.path[:depth] in self.solvers.system_cvode:
                    node.settings = cvode_settings(self.solvers.system_cvode[node.path[:depth]])
                    break
        try:
            hint = step_size_hint(element)
        except AnnotationNumberError as exc:
            self._bad_number(exc)
            hint = None
        if hint is not None:
            self._hints.append(f"{name} {hint:g} s")
        return True

    def _bad_number(self, exc: AnnotationNumberError) -> None:
        message = f"{display_name(exc.element)} {exc}"
        if any(p.message == message and p.path == element_path(exc.element) for p in self.problems):
            return  # read twice (a system's solvers and the experiment's step)
        self._problem(exc.element, message,
                      f"write {exc.attribute} as a positive number, e.g. {exc.attribute}=\"0.01\"")

    def _note_unread(self, root: Any) -> None:
        """One note per kind of annotation content cosim does not use."""
        for text in sorted(self.solvers.unused):
            self._note(text)
        if self._hints:
            self._note(f"OSP step size hints ignored ({', '.join(self._hints)}): cosim steps every unit with one "
                       "communication step")
        for kind in unread_annotation_types(root):
            self._note(f"annotations of type '{kind}' are not read")

    def _resolve(self, uri: str, base: Path) -> Path | None:
        """A file a component or binding refers to: inside the SSP first, then next to the archive."""
        parsed = urllib.parse.urlparse(uri)
        if parsed.scheme == "file":
            candidate = Path(urllib.parse.unquote(parsed.path))
            return candidate if candidate.is_file() else None
        if parsed.scheme:
            return None  # no network: http(s) sources are not fetched
        relative = urllib.parse.unquote(parsed.path)
        candidate = base / relative
        if self.files.inside(candidate) and candidate.is_file():
            return candidate
        if self.files.beside is not None:
            beside = self.files.beside / relative
            if beside.is_file():
                return beside
            beside = self.files.beside / Path(relative).name
            if beside.is_file():
                return beside
        return None

    def _read_connection(self, element: Any, system: Node) -> None:
        ends = []
        for side in ("start", "end"):
            owner_name = element.get(f"{side}Element")
            connector = element.get(f"{side}Connector")
            if not owner_name:  # left out, or "" as OMSimulator writes it: the system's own connector
                owner = system
            elif owner_name in system.children:
                owner = system.children[owner_name]
            else:
                self._problem(element, f"{side}Element '{owner_name}' is not an element of system "
                              f"'{element_path(system.element)}'.{did_you_mean(owner_name, system.children)}",
                              "name a component or sub-system of this system, or leave it out (or write "
                              f"{side}Element=\"\") for the system's own connector")
                return
            if connector not in owner.connectors and _variable(owner, connector) is None:
                what = "system" if owner.kind == "system" else "component"
                known = list(owner.connectors) or list(owner.variables)
                self._problem(element, f"{side}Connector '{connector}' is not a connector of {what} "
                              f"'{'.'.join(owner.path) or 'the root system'}'.{did_you_mean(connector, known)}",
                              f"use one of: {', '.join(known[:12])}" if known else "declare the connector")
                return
            ends.append((owner.path, connector))
        suppress = element.get("suppressUnitConversion", "false") in ("true", "1")
        linear = element.find(tag("ssc", "LinearTransformation"))
        f, o = 1.0, 0.0
        if linear is not None:
            f, o = float(linear.get("factor", 1.0)), float(linear.get("offset", 0.0))
        for other in (tag("ssc", "BooleanMappingTransformation"), tag("ssc", "IntegerMappingTransformation"),
                      tag("ssc", "EnumerationMappingTransformation")):
            if element.find(other) is not None:
                self._problem(element, f"{short_name(other)} is not supported", "map the values inside an FMU")
        self.edges.append(Edge(ends[0], ends[1], f, o, suppress, element))

    def _unit_of(self, path: tuple[str, ...], connector: str) -> tuple[str | None, dict]:
        """The unit of a connector: as the SSD declares it, else the FMU variable's; with the FMU's definitions."""
        node = self.nodes[path]
        if connector in node.connectors and node.connectors[connector].unit:
            return node.connectors[connector].unit, node.unit_definitions
        variable = _variable(node, connector) if node.kind == "component" else None
        return (getattr(variable, "unit", None) if variable is not None else None), node.unit_definitions

    def _components(self) -> list[Node]:
        return [n for n in self.nodes.values() if n.kind == "component" and (n.fmu or n.table) is not None]

    def _unit_names(self) -> dict[tuple[str, ...], str]:
        names: dict[tuple[str, ...], str] = {}
        seen: dict[str, tuple[str, ...]] = {}
        for node in self._components():
            # a component's own name may hold dots (an SSP exported from a flattened system)
            parts = [p if _NAME_RE.match(p) else re.sub(r"\W", "_", p if p[:1].isalpha() or p[:1] == "_" else f"_{p}")
                     for p in ".".join(node.path).split(".")]
            name = ".".join(parts)
            if name != ".".join(node.path):
                self._note(f"component '{'.'.join(node.path)}' is called '{name}' (names keep letters, digits, _)")
            if name in seen:
                self._problem(node.element, f"two components flatten to the same unit name '{name}'",
                              "rename one of them")
            seen[name] = node.path
            names[node.path] = name
        return names

    # --- connections, flattened ---------------------------------------------

    def _connections(self, unit_names: dict[tuple[str, ...], str]) -> list[dict]:
        into: dict[tuple, Edge] = {}
        for edge in self.edges:
            if edge.end in into:
                self._problem(edge.element, f"connector '{edge.end[1]}' of '{'.'.join(edge.end[0])}' is "
                              "already fed by another connection", "an input takes exactly one source")
                continue
            into[edge.end] = edge
        self._into = into
        connections = []
        for end, edge in into.items():
            node = self.nodes[end[0]]
            if node.kind != "component" or (node.fmu or node.table) is None:
                continue
            variable = _variable(node, end[1])
            if variable is None or variable.causality != "input":
                continue  # parameters fed from system connectors are handled with the bindings
            chain = self._chain(end)
            source, through = chain[0].start, chain[0]
            if self.nodes[source[0]].kind != "component":
                continue  # a system connector fed by nothing (or a loop): no connection
            factor, offset = self._compose(chain, self._unit_of(*source))
            source_node = self.nodes[source[0]]
            source_variable = _variable(source_node, source[1])
            if source_variable is None or source_variable.causality != "output":
                causality = getattr(source_variable, "causality", "unknown")
                self._problem(through.element, f"'{'.'.join(source[0])}.{source[1]}' is {causality}, not an "
                              "output", "a connection chain starts at a component's output")
                continue
            # the SSP's unit conversions are all in factor and offset: cosim must not convert again
            entry: dict[str, Any] = {"from": f"{unit_names[source[0]]}.{source[1]}",
                                     "to": f"{unit_names[end[0]]}.{end[1]}", "convert": False}
            if factor != 1.0 or offset != 0.0:
                entry.update(factor=factor, offset=offset)
            connections.append(entry)
        return connections

    def _chain(self, end: tuple) -> list[Edge]:
        """The connections from a component (or a system connector fed by nothing) to ``end``, in flow order."""
        chain = [self._into[end]]
        visited = {end}
        while True:
            start = chain[0].start
            if self.nodes[start[0]].kind == "component" or start in visited or start not in self._into:
                return chain
            visited.add(start)
            chain.insert(0, self._into[start])

    def _compose(self, chain: list[Edge], unit: tuple) -> tuple[float, float]:
        """(factor, offset) of a chain: per connection, units converted (unless suppressed), then its transformation.

        ``unit`` is the (name, definitions) of the value entering the chain.  A
        system connector that declares no unit passes the unit through, so a
        chain rpm -> (no unit) -> rad/s still converts.
        """
        factor, offset = 1.0, 0.0
        for edge in chain:
            end_unit = self._unit_of(*edge.end)
            a, b = (1.0, 0.0) if edge.suppress else self._conversion(unit, end_unit, edge.element)
            f, o = edge.factor * a, edge.factor * b + edge.offset
            factor, offset = f * factor, f * offset + o
            if end_unit[0] or edge.suppress:
                unit = end_unit  # after a suppressed conversion only a declared unit is known
        return factor, offset

    # --- experiment -----------------------------------------------------------

    def _experiment(self, root: Any) -> dict:
        experiment: dict[str, Any] = {}
        default = root.find(tag("ssd", "DefaultExperiment"))
        if default is not None:
            if default.get("startTime") is not None:
                experiment["start"] = float(default.get("startTime"))
            if default.get("stopTime") is not None:
                experiment["stop"] = float(default.get("stopTime"))
        step = None
        for element in root.iter():
            if not isinstance(element.tag, str):
                continue
            local = element.tag.split("}")[-1]
            try:
                if local == "FixedStepMaster" and element.get("stepSize"):
                    step = number(element, "stepSize")  # OMSimulator
                elif local == "FixedStepAlgorithm" and (element.get("baseStepSize") or element.get("stepSize")):
                    step = number(element, "baseStepSize" if element.get("baseStepSize") else "stepSize")  # OSP
            except AnnotationNumberError as exc:
                self._bad_number(exc)
                break
            if step is not None:
                break
        if step is None and self.solvers.steps:  # OMSimulator 3: oms_ma solvers' fixedStepSize
            step = min(self.solvers.steps)
            if len(set(self.solvers.steps)) > 1:
                self._note(f"OMSimulator solvers give several steps ({', '.join(f'{s:g}' for s in self.solvers.steps)}"
                           f"): cosim steps every unit with the smallest, {step:g} s")
        if step is not None:
            experiment["step"] = step
        for annotation in root.iter(tag("ssc", "Annotation")):
            if annotation.get("type") == "org.cosim":  # written by cosim export: its master algorithm
                for child in annotation:
                    if isinstance(child.tag, str) and child.get("algorithm") in ALGORITHMS:
                        experiment["algorithm"] = child.get("algorithm")
        # no note for a missing stop time or step size: the spec or the command line may give them, and
        # ssp_raw_spec reports them when neither does
        return experiment

    # --- parameter bindings ---------------------------------------------------

    def _read_bindings_everywhere(self, element: Any, path: tuple[str, ...]) -> None:
        self._read_bindings(element, path)
        elements = element.find(tag("ssd", "Elements"))
        for child in (elements if elements is not None else []):
            if isinstance(child.tag, str) and child.tag in (tag("ssd", "System"), tag("ssd", "Component")):
                child_path = (*path, child.get("name", ""))
                if child.tag == tag("ssd", "System"):
                    self._read_bindings_everywhere(child, child_path)
                else:
                    self._read_bindings(child, child_path)

    def _read_bindings(self, element: Any, path: tuple[str, ...]) -> None:
        container = element.find(tag("ssd", "ParameterBindings"))
        if container is None or path not in self.nodes:
            return
        owner = self.nodes[path]
        if owner.table is not None or owner.element.get("type") in TABLE_TYPES:
            self._problem(container, "a table component has no parameters to bind",
                          "remove the ssd:ParameterBindings of the table component")
            return
        for binding in container.findall(tag("ssd", "ParameterBinding")):
            prefix = binding.get("prefix", "")
            base = self.files.ssd.parent
            if binding.get("sourceBase") == "component":
                self._problem(binding, "sourceBase=\"component\" is not supported",
                              "put the parameter file into the SSP and refer to it from the SSD")
                continue
            parameters, label, units = self._parameter_set(binding, base)
            if parameters is None:
                continue
            mapping = self._mapping(binding, base)
            if mapping is None:
                continue
            for name, (value, unit, type_, where) in parameters.items():
                name = prefix + name
                # an .ssm may map one source to several targets: each gets the value, with its own transformation
                for target_name, transform in mapping.get(name, [(name, None)]):
                    target = self._find_target(owner, target_name)
                    if target is None and owner.kind == "component":
                        target = self._component_prefixed(owner, target_name, label)
                    if target is None and self.problems:
                        continue  # an FMU that did not load has no variables to match: already reported
                    if target is None:
                        self._note(f"parameter '{target_name}' of {label} matches no variable of "
                                   f"'{'.'.join(path) or 'the root system'}' and is ignored (as SSP prescribes)")
                        continue
                    self._order += 1
                    self.bindings.append((len(path), self._order, target, value,
                                          unit, (transform, units, type_, where), label))

    def _parameter_set(self, binding: Any, base: Path) -> tuple[dict | None, str, dict]:
        source = binding.get("source")
        if source:
            path = self._resolve(source, base)
            if path is None:
                self._problem(binding, f"parameter file '{source}' not found", "fix the binding's 'source'")
                return None, "", {}
            label = self.files.label(path)
            root = self._parse(path, label, "ssv")
            if root is None:
                return None, label, {}
        else:
            values = binding.find(tag("ssd", "ParameterValues"))
            root = values.find(tag("ssv", "ParameterSet")) if values is not None else None
            label = self.label
            if root is None:
                self._problem(binding, "the binding has neither 'source' nor an inline ssv:ParameterSet",
                              "add source=\"resources/x.ssv\" or an ssd:ParameterValues with an ssv:ParameterSet")
                return None, label, {}
            root = self._checked_inline(root, label, "ssv")
            if root is None:
                return None, label, {}
        units = self._read_units(root, label)
        parameters = {}
        for parameter in root.iter(tag("ssv", "Parameter")):
            for child in parameter:
                if not isinstance(child.tag, str):
                    continue
                local = child.tag.split("}")[-1]
                if local not in _TYPE_OF:
                    continue
                type_ = _TYPE_OF[local]
                text = child.get("value")
                if local == "Enumeration" and text is not None and re.fullmatch(r"[+-]?\d+", text.strip()):
                    # OMSimulator 3 writes an enumeration value as its integer; SSP writes the item's name
                    self._note(f"{label}: {element_path(child)} gives the enumeration value as the integer {text}; "
                               "SSP gives the item's name: read as the integer")
                    parameters[parameter.get("name")] = (int(text), child.get("unit"), type_, child)
                    continue
                try:
                    value = _typed(local, text)
                except ValueError:
                    self._problem(child, f"'{text}' is not a valid {local} value", f"write a {local} value", label)
                    continue
                parameters[parameter.get("name")] = (value, child.get("unit"), type_, child)
        return parameters, label, units

    def _mapping(self, binding: Any, base: Path) -> dict[str, list[tuple[str, Any]]] | None:
        """The binding's .ssm (inline or file): source name -> [(target name, transformation)], one or many."""
        element = binding.find(tag("ssd", "ParameterMapping"))
        if element is None:
            return {}
        source = element.get("source")
        if source:
            path = self._resolve(source, base)
            if path is None:
                self._problem(element, f"parameter mapping '{source}' not found", "fix the mapping's 'source'")
                return None
            label = self.files.label(path)
            root = self._parse(path, label, "ssm")
            if root is None:
                return None
        else:
            root, label = element.find(tag("ssm", "ParameterMapping")), self.label
            if root is None:
                return {}
            root = self._checked_inline(root, label, "ssm")
            if root is None:
                return None
        mapping = {}
        for entry in root.findall(tag("ssm", "MappingEntry")):
            linear = entry.find(tag("ssc", "LinearTransformation"))
            transform = (float(linear.get("factor", 1.0)), float(linear.get("offset", 0.0))) \
                if linear is not None else None
            suppress = entry.get("suppressUnitConversion", "false") in ("true", "1")
            mapping.setdefault(entry.get("source"), []).append((entry.get("target"),
                                                                 (transform, suppress, entry, label)))
        return mapping

    def _find_target(self, owner: Node, name: str) -> tuple[tuple[str, ...], str] | None:
        """The (element path, connector) a hierarchical parameter name means inside ``owner``."""
        if owner.kind == "component":
            return (owner.path, name) if _variable(owner, name) is not None else None
        if name in owner.connectors:
            return owner.path, name
        best = ""
        for child in owner.children:
            if name.startswith(child + ".") and len(child) > len(best):
                best = child
        if not best:
            return None
        return self._find_target(owner.children[best], name[len(best) + 1:])

    def _component_prefixed(self, owner: Node, name: str, label: str) -> tuple[tuple[str, ...], str] | None:
        """A component's own parameter named ``Component.param`` (OMSimulator's whole-model .ssv template, bound
        to one component): read as ``param``, with one note per file.  Only when the full name is no variable
        (FMU variable names may hold dots)."""
        own = owner.path[-1] + "."
        if not name.startswith(own) or _variable(owner, name[len(own):]) is None:
            return None
        if (label, owner.path) in self._prefixed:
            return owner.path, name[len(own):]
        self._prefixed.add((label, owner.path))
        self._note(f"{label} names the parameters of component '{'.'.join(owner.path)}' with the component's name "
                   f"('{name}'); SSP names them relative to the component ('{name[len(own):]}'): read as such")
        return owner.path, name[len(own):]

    def _apply_bindings(self, units: dict, unit_names: dict) -> None:
        # a higher level (smaller depth) wins, then the later binding at the same level
        chosen: dict[tuple, tuple] = {}
        for depth, order, target, value, unit, extra, label in self.bindings:
            current = chosen.get(target)
            if current is None or (depth, -order) < (current[0], -current[1]):
                chosen[target] = (depth, order, value, unit, extra, label)
        system_values = {t: v for t, v in chosen.items() if self.nodes[t[0]].kind == "system"}
        self._system_values = system_values
        # system connectors with values feed the component variables they are connected to (a parameter
        # connection); such a value counts as bound where the system connector's value was bound, so it beats
        # the component's own binding (a higher system wins) and loses to a binding of a still higher system
        fed: dict[tuple, tuple] = {}
        for end in getattr(self, "_into", {}):
            node = self.nodes[end[0]]
            if node.kind != "component" or node.fmu is None or _variable(node, end[1]) is None:
                continue
            chain = self._chain(end)
            start = chain[0].start
            if start not in system_values:
                continue
            depth, order, value, unit, extra, label = system_values[start]
            via = f"system connector '{'.'.join((*start[0], start[1]))}' (parameter connection)"
            direct = chosen.get(end)
            if direct is not None and direct[0] <= depth:
                if direct[0] == depth:
                    self._note(f"'{'.'.join(end[0])}.{end[1]}' is bound directly ({direct[5]}) and through "
                               f"{via} by the same system: the direct binding {direct[2]!r} is used")
                continue
            if isinstance(value, float):  # into the system connector's unit, then along the chain
                value = self._converted(value, unit, extra, label, self._unit_of(*start))
                factor, offset = self._compose(chain, self._unit_of(*start))
                value = factor * value + offset
            if direct is not None:
                binder = ".".join(end[0][:direct[0]]) or "the root system"
                self._note(f"'{'.'.join(end[0])}.{end[1]}': {value!r} from {via} overrides the value "
                           f"{direct[2]!r} bound by '{binder}' ({direct[5]}), as bindings of a higher system win")
            fed[end] = (value, (None, {}, extra[2], extra[3]), label)
        for target, (depth, order, value, unit, extra, label) in chosen.items():
            node = self.nodes[target[0]]
            if node.kind == "component" and node.fmu is not None and target not in fed:
                self._assign(units, unit_names, target, value, unit, extra, label, node)
        for end, (value, extra, label) in fed.items():
            self._assign(units, unit_names, end, value, None, extra, label, self.nodes[end[0]])

    def _converted(self, value: float, unit: str | None, extra: tuple, label: str, target_unit: tuple) -> float:
        """A bound Real value in the target's unit: the .ssv unit converted (unless the mapping suppresses it),
        then the mapping entry's LinearTransformation."""
        transform, ssv_units, _, where = extra
        if not (transform is not None and transform[1]):
            a, b = self._conversion((unit, {}), target_unit, where, ssv_units, label)
            value = a * value + b
        if transform is not None and transform[0] is not None:
            f, o = transform[0]
            value = f * value + o
        return value

    def _assign(self, units: dict, unit_names: dict, target: tuple, value: Any, unit: str | None,
                extra: tuple, label: str, node: Node) -> None:
        where = extra[3]
        variable = _variable(node, target[1])
        if isinstance(value, float):
            value = self._converted(value, unit, extra, label, self._unit_of(*target))
        if variable.causality in ("parameter", "structuralParameter"):
            field_name = "parameters"
        elif variable.causality in ("input", "local", "output", "calculatedParameter"):
            field_name = "start"
        else:
            self._problem(where, f"'{target[1]}' of '{'.'.join(target[0])}' is {variable.causality} and cannot "
                          "be set", "bind parameters, inputs or start values only", label)
            return
        units[unit_names[target[0]]].setdefault(field_name, {})[target[1]] = value


def _variable(node: Node, name: str) -> Any:
    """The FMU variable a connector or parameter name means: ``x`` or an element ``x[i]`` of an array."""
    if name in node.variables:
        return node.variables[name]
    base, _, rest = name.partition("[")
    variable = node.variables.get(base)
    if variable is not None and variable.is_array and rest.endswith("]") and rest[:-1].isdigit() \
            and 1 <= int(rest[:-1]) <= variable.size:
        return variable
    return None


def _typed(kind: str, text: str | None) -> Any:
    if text is None:
        raise ValueError(kind)
    if kind in _REAL:
        return float(text)
    if kind in _INTEGER:
        return int(text)
    if kind == "Boolean":
        if text not in ("true", "false", "1", "0"):
            raise ValueError(text)
        return text in ("true", "1")
    if kind == "Enumeration":
        raise ValueError(text)
    return text
