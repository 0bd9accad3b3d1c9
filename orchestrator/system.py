"""The system: units, their ports and connections, checked to fit together.

:func:`build_system` turns a :class:`~orchestrator.spec.Spec` into a
:class:`System`: it creates every unit type, resolves every port of every
connection, parameter, recorded signal and objective to scalar elements, and
checks causality, types, sizes, ranges and algebraic loops.  It reports every
problem at once (:class:`~orchestrator.problems.SpecError`).

A System is picklable: it holds unit *types* (blueprints), never live units.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

from .connection_units import connection_conversion
from .design import size_problems
from .expressions import Expression, ExpressionError
from .errors import UserError
from .problems import Problem, SpecError, did_you_mean, json_path
from .spec import Spec, UnitSpec
from .unit import NUMERIC_TYPES, ElementRef, UnitDescription, UnitType, Variable, flatten_value, parse_port, resolve_port
from .unit_kinds import unit_kind
from .units.fmu import FmuProblems

SETTABLE_AS_PARAMETER = ("parameter", "structuralParameter")
SETTABLE_AS_START = ("input", "local", "output", "independent", "calculatedParameter")


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
    of measure are converted (see :mod:`orchestrator.connection_units`); (1, 0)
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


@dataclass(frozen=True)
class System:
    """A validated system, ready to run (see :class:`orchestrator.execution.Execution`)."""

    spec: Spec
    units: Mapping[str, SystemUnit]
    connections: tuple[Connection, ...]
    order: tuple[str, ...]
    init_order: tuple[Connection, ...]
    assignments: tuple[Assignment, ...]
    probes: tuple[Signal, ...]
    recorded: tuple[str, ...]

    def signal(self, text: str) -> Signal:
        """Resolve a 'unit.port' text against this system; raises SpecError if it does not fit."""
        problems: list[Problem] = []
        signal = _resolve_signal(text, self.units, problems, self.spec.path, "$")
        if signal is None:
            raise SpecError(problems)
        return signal

    def assignment_for(self, target: str, value: Any) -> Assignment:
        """An Assignment setting ``target`` ('unit.port') to ``value``, checked like a spec parameter.

        Raises SpecError when the target does not exist or the value does not fit.
        """
        problems: list[Problem] = []
        unit_name, _, port = split_unit_name(target, self.units)
        if unit_name not in self.units:
            raise SpecError([Problem(self.spec.path, "$", f"unknown unit '{unit_name}' in '{target}'."
                                     f"{did_you_mean(unit_name, self.units)}", "use 'unit.parameter'")])
        result = _assignment(self.units[unit_name], port, value, None, problems, self.spec.path, f"'{target}'")
        if result is None:
            raise SpecError(problems)
        return result

    def recording(self, texts: Sequence[str]) -> "System":
        """This system, also recording ``texts`` ('unit.port' or 'unit.*' for every output of a unit).

        The units are not loaded or described again.  Raises SpecError when a
        text does not name a signal of the system.
        """
        problems: list[Problem] = []
        probes = {s.text: s for s in self.probes}
        recorded = list(self.recorded)
        _add_recorded([(text, "$.record") for text in texts], self.units, problems, self.spec.path, probes, recorded)
        if problems:
            raise SpecError(problems)
        return replace(self, probes=tuple(probes.values()), recorded=tuple(recorded))

    def recording_all_outputs(self) -> "System":
        """This system recording every output of every unit besides its own record list (for re-runs)."""
        return self.recording([f"{name}.*" for name in self.units])


def split_unit_name(text: str, unit_names: Any) -> tuple[str, str, str]:
    """``('unit', '.', 'port')`` from ``'unit.port'``.

    Units flattened from an SSP are named by their path (``SuT.motor``), so a
    unit name may contain dots: the longest known unit name followed by a dot
    wins; without one, the text splits at its first dot.
    """
    best = ""
    for name in unit_names:
        if len(name) > len(best) and text.startswith(name) and text[len(name):len(name) + 1] == ".":
            best = name
    if not best:
        return text.partition(".")
    return best, ".", text[len(best) + 1:]


def make_unit_type(spec: UnitSpec, folder: str) -> UnitType:
    """The blueprint for one unit of a spec, made by its kind (see :mod:`orchestrator.unit_kinds`).

    No file is opened yet except builtin FMU builds.
    """
    return unit_kind(spec.kind).create(spec, folder)


def build_system(spec: Spec, broken_units: frozenset[str] = frozenset()) -> System:
    """Check that the spec's units, ports and connections fit, and build the System.

    ``broken_units`` names units already reported as broken elsewhere (by the
    schema check); references to them are not reported a second time.
    Raises SpecError listing every problem found.
    """
    file = spec.path
    problems: list[Problem] = []
    units = _LoadedUnits()
    units.failed.update(broken_units)
    for u in spec.units:
        system_unit = _load_unit(u, spec.folder, file, problems)
        if system_unit is not None:
            units[u.name] = system_unit
        else:
            units.failed.add(u.name)

    assignments = []
    for u in spec.units:
        if u.name not in units or u.kind == "player":  # a player replaying a unit plays what that unit's values gave
            continue
        for field_name, values in (("parameters", u.parameters), ("start", u.start)):
            for port, value in values.items():
                a = _assignment(units[u.name], port, value, field_name, problems, file,
                                json_path(["units", u.name, field_name, port]))
                if a is not None:
                    assignments.append(a)

    connections = _check_connections(spec, units, problems)
    order = _stepping_order([u.name for u in spec.units], connections)
    init_order = _check_algebraic_loops(units, connections, problems, file)

    probes: dict[str, Signal] = {}
    recorded: list[str] = []
    _add_recorded([(text, json_path(["record", i])) for i, text in enumerate(spec.record)], units, problems, file,
                  probes, recorded)
    for o in spec.objectives:
        if o.signal:
            s = _resolve_signal(o.signal, units, problems, file, json_path(["objectives", o.name, "signal"]))
            if s is not None and s.variable.type not in NUMERIC_TYPES:
                problems.append(Problem(file, json_path(["objectives", o.name, "signal"]),
                                        f"'{o.signal}' is {s.variable.type}: only numeric signals (Real, Integer, "
                                        "Boolean) reduce to an objective", "choose a numeric signal; String and "
                                        "Binary signals can be recorded under 'record'"))
            elif s is not None:
                probes.setdefault(s.text, s)
    if spec.experiment.stop_when:
        s = _resolve_signal(spec.experiment.stop_when, units, problems, file, "$.experiment.stop_when")
        if s is not None:
            if s.variable.type != "Boolean" or len(s.refs) != 1:
                problems.append(Problem(file, "$.experiment.stop_when", f"'{s.text}' is not a Boolean scalar",
                                        "name a Boolean output such as 'trajectory.finished'"))
            probes.setdefault(s.text, s)
    _check_objective_expressions(spec, problems)
    _check_design(spec, units, problems)
    if problems:
        raise SpecError(problems)
    return System(spec=spec, units=dict(units), connections=tuple(connections), order=tuple(order),
                  init_order=tuple(init_order), assignments=tuple(assignments), probes=tuple(probes.values()),
                  recorded=tuple(recorded))


def _add_recorded(texts: Sequence[tuple[str, str]], units: Mapping[str, SystemUnit], problems: list[Problem],
                  file: str, probes: dict[str, Signal], recorded: list[str]) -> None:
    """Resolve (text, JSON path) record entries into ``probes`` and the column list ``recorded``."""
    for text, path in texts:
        for expanded in _expand_wildcard(text, units):
            s = _resolve_signal(expanded, units, problems, file, path)
            if s is not None and s.variable.type == "Clock":
                problems.append(Problem(file, path, f"'{expanded}' is an FMI 3.0 Clock, which has no value to record",
                                        "record value variables only"))
            elif s is not None:
                probes.setdefault(s.text, s)
                recorded.extend(c for c in s.columns if c not in recorded)


class _LoadedUnits(dict):
    """Units that loaded, and the names of those that did not (already reported,
    so references to them are not reported again)."""

    def __init__(self) -> None:
        super().__init__()
        self.failed: set[str] = set()


def _load_unit(u: UnitSpec, folder: str, file: str, problems: list[Problem]) -> SystemUnit | None:
    path = json_path(["units", u.name, u.kind])
    try:
        unit_type = make_unit_type(u, folder)
        description = unit_type.describe()
    except FmuProblems as exc:
        for p in exc.problems:
            where = f" ({p.path})" if p.path else ""
            problems.append(Problem(file, path, f"FMU '{u.source}'{where}: {p.message}",
                                    p.fix or "re-export the FMU from its tool"))
        return None
    except UserError as exc:  # e.g. a plug-in kind's own check of its source
        for p in exc.problems:
            problems.append(Problem(file, path, f"{u.kind} '{u.source}': {p.message}", p.fix))
        return None
    except FileNotFoundError as exc:
        problems.append(Problem(file, path, str(exc), "check the path; relative paths start at the spec's folder"))
        return None
    except (ImportError, TypeError, ValueError) as exc:
        problems.append(Problem(file, path, f"cannot load '{u.source}': {exc}",
                                "check the module path and class name, and that the module imports cleanly"))
        return None
    except Exception as exc:  # a user's module may raise anything while importing
        problems.append(Problem(file, path, f"cannot load '{u.source}': {type(exc).__name__}: {exc}",
                                "fix the error in the unit's source"))
        return None
    names = {v.name for v in description.variables}
    if u.options.get("feedthrough"):
        description = _declared_feedthrough(u, description, file, problems)
    for port, actual in u.ports.items():
        if actual not in names:
            problems.append(Problem(file, json_path(["units", u.name, "ports", port]),
                                    f"unit '{u.name}' has no variable '{actual}'.{did_you_mean(actual, names)}",
                                    "map the spec's port name to one of the unit's variables"))
    return SystemUnit(u, unit_type, description)


def _declared_feedthrough(u: UnitSpec, description: UnitDescription, file: str,
                          problems: list[Problem]) -> UnitDescription:
    """The description with the spec's ``feedthrough`` (output -> inputs it depends on directly) applied."""
    declared: dict[str, tuple[str, ...]] = {}
    outputs = {v.name for v in description.outputs()}
    inputs = {v.name for v in description.inputs()}
    for output, depends in u.options["feedthrough"].items():
        path = json_path(["units", u.name, "feedthrough", output])
        name = u.ports.get(output, output)
        if name not in outputs:
            problems.append(Problem(file, path, f"'{output}' is not an output of unit '{u.name}'."
                                                f"{did_you_mean(name, outputs)}", "name an output of the unit"))
            continue
        wrong = [d for d in depends if u.ports.get(d, d) not in inputs]
        if wrong:
            problems.append(Problem(file, path, f"not inputs of unit '{u.name}': {', '.join(wrong)}",
                                    "list the inputs this output depends on directly ([] for none)"))
            continue
        declared[name] = tuple(u.ports.get(d, d) for d in depends)
    return replace(description, feedthrough={**description.feedthrough, **declared})


def _port_names(unit: SystemUnit) -> list[str]:
    reverse = {v: k for k, v in unit.spec.ports.items()}
    return [reverse.get(v.name, v.name) for v in unit.description.variables]


def _resolve_signal(text: str, units: Mapping[str, SystemUnit], problems: list[Problem], file: str,
                    path: str) -> Signal | None:
    unit_name, dot, port = split_unit_name(text, [*units, *getattr(units, "failed", ())])
    if not dot or not port:
        problems.append(Problem(file, path, f"'{text}' is not 'unit.port'", "write 'unit.port' or 'unit.port[i]'"))
        return None
    if unit_name in getattr(units, "failed", ()):
        return None
    if unit_name not in units:
        problems.append(Problem(file, path, f"unknown unit '{unit_name}'.{did_you_mean(unit_name, units)}",
                                "use one of the units declared under 'units': " + ", ".join(units)))
        return None
    unit = units[unit_name]
    base, index = parse_port(port)
    actual = unit.variable_name(port) if index is None else f"{unit.variable_name(base)}[{index}]"
    try:
        var, refs = resolve_port(unit.description, actual)
    except KeyError:
        names = _port_names(unit)
        problems.append(Problem(file, path, f"unit '{unit_name}' has no variable '{port}'."
                                            f"{did_you_mean(base, names)}",
                                f"run 'cosim inspect' on the spec to list the variables of '{unit_name}'"))
        return None
    except IndexError as exc:
        problems.append(Problem(file, path, f"'{text}': {exc}", "use an index from 1 to the array's size"))
        return None
    if var.is_array and len(refs) > 1:
        columns = tuple(f"{unit_name}.{base}[{i}]" for i in range(1, len(refs) + 1))
    else:
        columns = (text,)
    return Signal(text, unit_name, var, tuple(refs), columns)


def _expand_wildcard(text: str, units: Mapping[str, SystemUnit]) -> list[str]:
    unit_name, _, port = split_unit_name(text, units)
    if port != "*" or unit_name not in units:
        return [text]
    unit = units[unit_name]
    grouped = {v.name for v in unit.description.variables if v.is_array}
    out = []
    for v, port_name in zip(unit.description.variables, _port_names(unit)):
        if v.causality != "output" or v.type == "Clock":  # clocks carry no value to record
            continue
        base, index = parse_port(v.name)
        if index is not None and base in grouped:
            continue  # already recorded through its array
        out.append(f"{unit_name}.{port_name}")
    return out


def _check_connections(spec: Spec, units: Mapping[str, SystemUnit], problems: list[Problem]) -> list[Connection]:
    file = spec.path
    connections = []
    fed: dict[tuple[str, str, int], int] = {}
    players = {u.name for u in spec.units if u.kind == "player"}
    for c in spec.connections:
        if split_unit_name(str(c.target), units)[0] in players:
            continue  # the input of a unit now replayed by a player: the recording already has what it caused
        base = ["connections", c.index]
        source = _resolve_signal(c.source, units, problems, file, json_path([*base, "from"]))
        target = _resolve_signal(c.target, units, problems, file, json_path([*base, "to"]))
        if source is None or target is None:
            continue
        ok = True
        if source.variable.causality != "output":
            problems.append(Problem(file, json_path([*base, "from"]),
                                    f"'{c.source}' is {_article(source.variable.causality)}, not an output",
                                    "a connection goes from an output to an input"))
            ok = False
        if target.variable.causality != "input":
            problems.append(Problem(file, json_path([*base, "to"]),
                                    f"'{c.target}' is {_article(target.variable.causality)}, not an input",
                                    "a connection goes from an output to an input; swap 'from' and 'to' if "
                                    "they are reversed"))
            ok = False
        if "Clock" in (source.variable.type, target.variable.type):
            problems.append(Problem(file, json_path(base), f"'{c.source}' -> '{c.target}' connects an FMI 3.0 "
                                    "Clock; cosim does not run clocked partitions or events",
                                    "remove the connection; connect value variables only"))
            ok = False
        elif not _types_fit(source.variable.type, target.variable.type):
            problems.append(Problem(file, json_path(base), f"type mismatch: '{c.source}' is "
                                    f"{source.variable.type}, '{c.target}' is {target.variable.type}",
                                    "connect variables of the same type (Integer may feed Real; Binary "
                                    "connects only to Binary)"))
            ok = False
        if len(source.refs) != len(target.refs):
            problems.append(Problem(file, json_path(base), f"size mismatch: '{c.source}' has {len(source.refs)} "
                                    f"element(s), '{c.target}' has {len(target.refs)}",
                                    "connect arrays of the same size, or single elements like 'x[2]'"))
            ok = False
        for ref in target.refs:
            key = (target.unit, ref.variable, ref.offset)
            if key in fed:
                problems.append(Problem(file, json_path([*base, "to"]),
                                        f"input '{c.target}' is already fed by connection {fed[key]}",
                                        "an input takes exactly one source; remove one of the connections"))
                ok = False
                break
            fed[key] = c.index
        (factor, offset), unit_problem = connection_conversion(
            c.source, source.variable, units[source.unit].description, c.target, target.variable,
            units[target.unit].description, c.convert, file, json_path(base))
        if unit_problem is not None:
            problems.append(unit_problem)
            ok = False
        if (c.factor != 1.0 or c.offset != 0.0) and target.variable.type != "Real":
            problems.append(Problem(file, json_path(base), f"'{c.target}' is {target.variable.type}: only Real "
                                    "connections take a factor or offset", "remove 'factor' and 'offset'"))
            ok = False
        if ok:  # the connection's own transformation after the unit conversion
            connections.append(Connection(source, target, c.factor * factor, c.factor * offset + c.offset))
    return connections


def _article(causality: str) -> str:
    return ("an " if causality[0] in "aeiou" else "a ") + causality


def _types_fit(source: str, target: str) -> bool:
    return source == target or (source == "Integer" and target == "Real")


def _assignment(unit: SystemUnit, port: str, value: Any, field_name: str | None, problems: list[Problem],
                file: str, path: str) -> Assignment | None:
    base, index = parse_port(port)
    actual = unit.variable_name(port) if index is None else f"{unit.variable_name(base)}[{index}]"
    try:
        var, refs = resolve_port(unit.description, actual)
    except KeyError:
        problems.append(Problem(file, path, f"unit '{unit.name}' has no variable '{port}'."
                                            f"{did_you_mean(base, _port_names(unit))}",
                                f"run 'cosim inspect' on the spec to list the variables of '{unit.name}'"))
        return None
    except IndexError as exc:
        problems.append(Problem(file, path, str(exc), "use an index from 1 to the array's size"))
        return None
    if field_name == "parameters" and var.causality not in SETTABLE_AS_PARAMETER:
        problems.append(Problem(file, path, f"'{port}' of unit '{unit.name}' is {_article(var.causality)}, "
                                            "not a parameter", "set it under 'start' instead of 'parameters'"))
        return None
    if field_name == "start" and var.causality not in SETTABLE_AS_START:
        problems.append(Problem(file, path, f"'{port}' of unit '{unit.name}' is a {var.causality}",
                                "set it under 'parameters' instead of 'start'"))
        return None
    if field_name is None and var.causality not in SETTABLE_AS_PARAMETER + ("input",):
        problems.append(Problem(file, path, f"'{port}' of unit '{unit.name}' is {_article(var.causality)}; "
                                            "only parameters and inputs can be set", "choose a parameter"))
        return None
    if field_name is None and var.causality == "structuralParameter":
        problems.append(Problem(file, path, f"'{port}' of unit '{unit.name}' is a structural parameter: it may "
                                            "size arrays, which are fixed when the spec is checked",
                                f"set it under units.{unit.name}.parameters (one value per spec)"))
        return None
    try:
        flat = flatten_value(var, value) if len(refs) > 1 else [value]
    except ValueError as exc:
        problems.append(Problem(file, path, str(exc), f"give {len(refs)} values"))
        return None
    checked = []
    for v in flat:
        message = _value_problem(var, v)
        if message:
            problems.append(Problem(file, path, message[0], message[1]))
            return None
        checked.append(float(v) if var.type == "Real" else int(v) if var.type == "Integer"
                       else bytes.fromhex(v) if var.type == "Binary" else v)
    return Assignment(unit.name, tuple(refs), tuple(checked))


def _value_problem(var: Variable, value: Any) -> tuple[str, str] | None:
    kind = var.type
    if kind == "Real" and (isinstance(value, bool) or not isinstance(value, (int, float))):
        return f"'{var.name}' is Real, got {type(value).__name__} {value!r}", "write a number"
    if kind == "Integer" and (isinstance(value, bool) or not isinstance(value, int)):
        if not (isinstance(value, float) and value.is_integer()):
            return f"'{var.name}' is Integer, got {type(value).__name__} {value!r}", "write a whole number"
    if kind == "Boolean" and not isinstance(value, bool):
        return f"'{var.name}' is Boolean, got {type(value).__name__} {value!r}", "write true or false"
    if kind == "String" and not isinstance(value, str):
        return f"'{var.name}' is String, got {type(value).__name__} {value!r}", "write a string in quotes"
    if kind == "Binary":
        try:
            bytes.fromhex(value if isinstance(value, str) else "?")
        except ValueError:
            return (f"'{var.name}' is Binary, got {type(value).__name__} {value!r}",
                    "write the bytes as a hex string, e.g. \"0a0bfe\"")
    if kind == "Clock":
        return f"'{var.name}' is an FMI 3.0 Clock; cosim does not set clocks", "remove it"
    if kind in ("Real", "Integer"):
        if isinstance(value, float) and not math.isfinite(value):
            return f"'{var.name}' must be finite, got {value}", "write a finite number"
        low, high = _scalar_bound(var.min), _scalar_bound(var.max)
        if low is not None and value < low or high is not None and value > high:
            return (f"{value} is outside the range of '{var.name}' [{_fmt(low, '-inf')}, {_fmt(high, 'inf')}]",
                    "choose a value inside the declared range")
    return None


def _scalar_bound(bound: Any) -> float | None:
    if bound is None:
        return None
    if isinstance(bound, tuple):
        return min(bound) if bound else None
    return float(bound)


def _fmt(bound: float | None, unbounded: str) -> str:
    return unbounded if bound is None else f"{bound:g}"


def _stepping_order(names: list[str], connections: list[Connection]) -> list[str]:
    """Gauss-Seidel order: sources before the units they feed, spec order where free.

    Units in a feedback cycle form one group, ordered as in the spec; groups are
    sorted topologically, preferring the group whose first unit comes first.
    """
    edges: dict[str, set[str]] = {n: set() for n in names}
    for c in connections:
        if c.source.unit != c.target.unit:
            edges[c.source.unit].add(c.target.unit)
    components = [sorted(comp, key=names.index) for comp in _strongly_connected(names, edges)]
    group_of = {n: i for i, comp in enumerate(components) for n in comp}
    successors: dict[int, set[int]] = {i: set() for i in range(len(components))}
    indegree = {i: 0 for i in range(len(components))}
    for a, targets in edges.items():
        for b in targets:
            ga, gb = group_of[a], group_of[b]
            if ga != gb and gb not in successors[ga]:
                successors[ga].add(gb)
                indegree[gb] += 1
    ready = [(names.index(components[i][0]), i) for i in indegree if indegree[i] == 0]
    heapq.heapify(ready)
    ordered: list[str] = []
    while ready:
        _, g = heapq.heappop(ready)
        ordered.extend(components[g])
        for nxt in successors[g]:
            indegree[nxt] -= 1
            if indegree[nxt] == 0:
                heapq.heappush(ready, (names.index(components[nxt][0]), nxt))
    return ordered


def _strongly_connected(nodes: list[Any], edges: Mapping[Any, set[Any]]) -> list[list[Any]]:
    """Tarjan's algorithm, iterative; components come in reverse topological order."""
    index: dict[Any, int] = {}
    low: dict[Any, int] = {}
    on_stack: set[Any] = set()
    stack: list[Any] = []
    result: list[list[Any]] = []
    counter = 0
    for root in nodes:
        if root in index:
            continue
        work = [(root, iter(sorted(edges.get(root, ()), key=str)))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            advanced = False
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges.get(child, ()), key=str))))
                    advanced = True
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            if advanced:
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                result.append(component)
    return result


def _check_algebraic_loops(units: Mapping[str, SystemUnit], connections: list[Connection],
                           problems: list[Problem], file: str) -> list[Connection]:
    """Find cycles of direct feed-through; return the connections in initialization order.

    Nodes are (unit, variable); a connection is an edge output -> input and a
    unit's declared feed-through is an edge input -> output.
    """
    edges: dict[tuple[str, str], set[tuple[str, str]]] = {}
    nodes: list[tuple[str, str]] = []

    def add(a: tuple[str, str], b: tuple[str, str]) -> None:
        for n in (a, b):
            if n not in edges:
                edges[n] = set()
                nodes.append(n)
        edges[a].add(b)

    for c in connections:
        add((c.source.unit, c.source.variable.name), (c.target.unit, c.target.variable.name))
    connected_inputs = {(c.target.unit, c.target.variable.name) for c in connections}
    for name, unit in units.items():
        for out in unit.description.outputs():
            for inp in unit.description.depends_on(out.name):
                if (name, inp) in connected_inputs or _element_input_connected(name, inp, connected_inputs):
                    add((name, inp), (name, out.name))
        # array elements: an element input depends on the whole array's dependencies
    for comp in _strongly_connected(nodes, edges):
        if len(comp) > 1 or comp[0] in edges.get(comp[0], set()):
            involved = sorted({u for u, _ in comp})
            ports = ", ".join(sorted(f"{u}.{v}" for u, v in comp))
            # outputs whose dependencies nobody declared are assumed to depend on every input (FMI's rule)
            assumed = sorted({u for u, v in comp if u in units and v in {o.name for o in units[u].description.outputs()}
                              and v not in units[u].description.feedthrough})
            why = (f"; unit(s) {', '.join(assumed)} declare no dependencies for their outputs, so every output "
                   "is assumed to depend directly on every input" if assumed else "")
            fix = ("break the loop: connect through a unit without direct feed-through, or change one connection"
                   + (f"; if an output does not depend on an input directly, declare it in the spec, e.g. "
                      f"\"units\": {{\"{assumed[0]}\": {{\"feedthrough\": {{\"<output>\": []}}}}}}" if assumed else ""))
            problems.append(Problem(file, "$.connections",
                                    f"algebraic loop through units {', '.join(involved)} (ports {ports}){why}", fix))
    rank: dict[tuple[str, str], int] = {}
    for i, comp in enumerate(reversed(_strongly_connected(nodes, edges))):
        for n in comp:
            rank[n] = i
    return sorted(connections, key=lambda c: rank.get((c.source.unit, c.source.variable.name), 0))


def _element_input_connected(unit: str, variable: str, connected: set[tuple[str, str]]) -> bool:
    return any(u == unit and parse_port(v)[0] == variable for u, v in connected)


def _check_objective_expressions(spec: Spec, problems: list[Problem]) -> None:
    names = {o.name for o in spec.objectives}
    depends: dict[str, set[str]] = {}
    for o in spec.objectives:
        if not o.expr:
            continue
        path = json_path(["objectives", o.name, "expr"])
        try:
            expression = Expression(o.expr)
        except ExpressionError as exc:
            problems.append(Problem(file=spec.path, path=path, message=str(exc),
                                    fix="use numbers, other objectives' names, + - * / ** and abs, sqrt, min, max"))
            continue
        unknown = sorted(expression.free_names - names)
        for n in unknown:
            problems.append(Problem(spec.path, path, f"'{n}' is not an objective.{did_you_mean(n, names)}",
                                    "refer to objectives defined in this spec"))
        depends[o.name] = expression.names & names
    components = _strongly_connected(list(depends), {k: v & set(depends) for k, v in depends.items()})
    for comp in components:
        if len(comp) > 1 or comp[0] in depends.get(comp[0], set()):
            problems.append(Problem(spec.path, "$.objectives", "objectives refer to each other in a cycle: "
                                    + ", ".join(sorted(comp)), "make one of them a signal reduction"))


def _check_design(spec: Spec, units: _LoadedUnits, problems: list[Problem]) -> None:
    players = {u.name for u in spec.units if u.kind == "player"}
    for p in spec.design.parameters:
        path = json_path(["design", "parameters", p.target])
        unit_name, _, port = split_unit_name(p.target, [*units, *units.failed])
        if unit_name in players:
            continue  # a replayed unit: `cosim run` needs no design; a sweep refuses it (orchestrator.sweep)
        if unit_name not in units:
            if unit_name not in units.failed:
                problems.append(Problem(spec.path, path, f"unknown unit '{unit_name}'."
                                        f"{did_you_mean(unit_name, units)}", "use 'unit.parameter'"))
            continue
        samples = list(p.values) if p.values is not None else [p.min, p.max] if p.min is not None else [False, True]
        for value in samples:
            if _assignment(units[unit_name], port, value, None, problems, spec.path, path) is None:
                break
        if p.values is None and not p.is_bool:
            if isinstance(p.min, (int, float)) and isinstance(p.max, (int, float)) and p.max < p.min:
                problems.append(Problem(spec.path, path, f"max ({p.max}) is below min ({p.min})", "swap them"))
            if p.step is not None and isinstance(p.step, (int, float)) and p.step <= 0:
                problems.append(Problem(spec.path, path, f"step must be positive, got {p.step}",
                                        "write a positive step"))
            if spec.design.method == "grid" and p.step is None and "optimize" not in spec.raw:
                problems.append(Problem(spec.path, path, "a grid needs a 'step' for each range",
                                        "add 'step', or use method 'lhs', 'sobol' or 'random' with 'samples'"))
    if spec.design.method != "grid" and spec.design.parameters and spec.design.samples is None:
        problems.append(Problem(spec.path, "$.design.samples", f"method '{spec.design.method}' needs 'samples'",
                                "add e.g. \"samples\": 100"))
    problems.extend(size_problems(spec))  # counted, never made
    if spec.design.constraint:
        try:
            Expression(spec.design.constraint)
        except ExpressionError as exc:
            problems.append(Problem(spec.path, "$.design.constraint", str(exc), "write a comparison of parameters"))
