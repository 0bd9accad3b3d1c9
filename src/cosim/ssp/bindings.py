"""Parameter bindings of an SSP (``ssd:ParameterBinding`` inline or ``.ssv``, with ``prefix`` and ``.ssm``
mappings) resolved into unit parameters and start values.

Bindings of a higher system win over lower ones, later bindings over earlier ones at one level.  A value bound
to a system's connector reaches the FMU variables that connector is connected to (a parameter connection) and
counts as bound where the connector's value was bound, so it beats the component's own binding.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from cosim.ssp.connections import Flow
from cosim.ssp.measures import read_unit_definitions, unit_conversion
from cosim.ssp.model import (
    TABLE_TYPES,
    TYPE_OF,
    Node,
    typed_value,
    unit_of,
    variable_of,
)
from cosim.ssp.reading import Reading
from cosim.ssp.xml import element_path, tag

Target = tuple[tuple[str, ...], str]  # (element path, connector or variable)


class Bindings:
    """The bindings of every system and component, collected by :meth:`read`, chosen and applied by :meth:`apply`.

    After :meth:`apply`, ``system_values`` holds the chosen value of every system connector that has one:
    connector -> (depth, order, value, unit, (transformation, .ssv units, type, element), file label).
    """

    def __init__(self, reading: Reading):
        self.reading = reading
        self.found: list[tuple[int, int, Target, Any, str | None, Any, str]] = []
        self._order = 0
        self._prefixed: set[tuple[str, tuple[str, ...]]] = set()  # (file, component) noted for Component.param
        self.system_values: dict[Target, tuple] = {}
        # FMU variables a direct binding keeps although a system connector with a value is connected to them
        self.kept: set[Target] = set()

    # --- reading ------------------------------------------------------------

    def read(self, element: Any, path: tuple[str, ...]) -> None:
        """The bindings of the system ``element`` at ``path`` and of everything below it."""
        self._read_bindings(element, path)
        elements = element.find(tag("ssd", "Elements"))
        for child in (elements if elements is not None else []):
            if isinstance(child.tag, str) and child.tag in (tag("ssd", "System"), tag("ssd", "Component")):
                child_path = (*path, child.get("name", ""))
                if child.tag == tag("ssd", "System"):
                    self.read(child, child_path)
                else:
                    self._read_bindings(child, child_path)

    def _read_bindings(self, element: Any, path: tuple[str, ...]) -> None:
        reading = self.reading
        container = element.find(tag("ssd", "ParameterBindings"))
        if container is None or path not in reading.nodes:
            return
        owner = reading.nodes[path]
        if owner.table is not None or owner.element.get("type") in TABLE_TYPES:
            reading.problem(container, "a table component has no parameters to bind",
                            "remove the ssd:ParameterBindings of the table component")
            return
        for binding in container.findall(tag("ssd", "ParameterBinding")):
            prefix = binding.get("prefix", "")
            base = reading.files.ssd.parent
            if binding.get("sourceBase") == "component":
                reading.problem(binding, "sourceBase=\"component\" is not supported",
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
                    if target is None and reading.problems:
                        continue  # an FMU that did not load has no variables to match: already reported
                    if target is None:
                        owner_name = ".".join(path) or "the root system"
                        reading.alike.add(("unmatched", label, path),
                                          f"parameter '{target_name}' of {label} matches no variable of "
                                          f"'{owner_name}' and is ignored (as SSP prescribes)", f"'{target_name}'",
                                          "more parameters of that file match none and are ignored")
                        continue
                    self._order += 1
                    self.found.append((len(path), self._order, target, value,
                                       unit, (transform, units, type_, where), label))

    def _parameter_set(self, binding: Any, base: Path) -> tuple[dict | None, str, dict]:
        """The binding's parameters (inline or .ssv): name -> (value, unit, type, element); its file; its units."""
        reading = self.reading
        source = binding.get("source")
        if source:
            if reading.leaves_ssp(source, base, binding):
                return None, "", {}
            path = reading.resolve(source, base)
            if path is None:
                reading.problem(binding, f"parameter file '{source}' not found", "fix the binding's 'source'")
                return None, "", {}
            label = reading.files.label(path)
            root = reading.parse(path, label, "ssv")
            if root is None:
                return None, label, {}
        else:
            values = binding.find(tag("ssd", "ParameterValues"))
            root = values.find(tag("ssv", "ParameterSet")) if values is not None else None
            label = reading.label
            if root is None:
                reading.problem(binding, "the binding has neither 'source' nor an inline ssv:ParameterSet",
                                "add source=\"resources/x.ssv\" or an ssd:ParameterValues with an ssv:ParameterSet")
                return None, label, {}
            root = reading.checked_inline(root, label, "ssv")
            if root is None:
                return None, label, {}
        units = read_unit_definitions(root)
        parameters = {}
        for parameter in root.iter(tag("ssv", "Parameter")):
            for child in parameter:
                if not isinstance(child.tag, str):
                    continue
                local = child.tag.split("}")[-1]
                if local not in TYPE_OF:
                    continue
                type_ = TYPE_OF[local]
                text = child.get("value")
                if local == "Enumeration" and text is not None and re.fullmatch(r"[+-]?\d+", text.strip()):
                    # OMSimulator 3 writes an enumeration value as its integer; SSP writes the item's name
                    reading.alike.add(("enumeration integer", label),
                                      f"{label}: {element_path(child)} gives the enumeration value as the integer "
                                      f"{text}; SSP gives the item's name: read as the integer",
                                      f"'{parameter.get('name')}'", "more enumeration values of that file likewise")
                    parameters[parameter.get("name")] = (int(text), child.get("unit"), type_, child)
                    continue
                try:
                    value = typed_value(local, text)
                except ValueError:
                    reading.problem(child, f"'{text}' is not a valid {local} value", f"write a {local} value", label)
                    continue
                parameters[parameter.get("name")] = (value, child.get("unit"), type_, child)
        return parameters, label, units

    def _mapping(self, binding: Any, base: Path) -> dict[str, list[tuple[str, Any]]] | None:
        """The binding's .ssm (inline or file): source name -> [(target name, transformation)], one or many."""
        reading = self.reading
        element = binding.find(tag("ssd", "ParameterMapping"))
        if element is None:
            return {}
        source = element.get("source")
        if source:
            if reading.leaves_ssp(source, base, element):
                return None
            path = reading.resolve(source, base)
            if path is None:
                reading.problem(element, f"parameter mapping '{source}' not found", "fix the mapping's 'source'")
                return None
            label = reading.files.label(path)
            root = reading.parse(path, label, "ssm")
            if root is None:
                return None
        else:
            root, label = element.find(tag("ssm", "ParameterMapping")), reading.label
            if root is None:
                return {}
            root = reading.checked_inline(root, label, "ssm")
            if root is None:
                return None
        mapping: dict[Any, list[tuple[Any, Any]]] = {}  # as the file (checked by the schema) gives them
        for entry in root.findall(tag("ssm", "MappingEntry")):
            linear = entry.find(tag("ssc", "LinearTransformation"))
            transform = (float(linear.get("factor", 1.0)), float(linear.get("offset", 0.0))) \
                if linear is not None else None
            suppress = entry.get("suppressUnitConversion", "false") in ("true", "1")
            mapping.setdefault(entry.get("source"), []).append((entry.get("target"),
                                                                 (transform, suppress, entry, label)))
        return mapping

    def _find_target(self, owner: Node, name: str) -> Target | None:
        """The (element path, connector) a hierarchical parameter name means inside ``owner``."""
        if owner.kind == "component":
            return (owner.path, name) if variable_of(owner, name) is not None else None
        if name in owner.connectors:
            return owner.path, name
        best = ""
        for child in owner.children:
            if name.startswith(child + ".") and len(child) > len(best):
                best = child
        if not best:
            return None
        return self._find_target(owner.children[best], name[len(best) + 1:])

    def _component_prefixed(self, owner: Node, name: str, label: str) -> Target | None:
        """A component's own parameter named ``Component.param`` (OMSimulator's whole-model .ssv template, bound
        to one component): read as ``param``, with one note per file.  Only when the full name is no variable
        (FMU variable names may hold dots)."""
        own = owner.path[-1] + "."
        if not name.startswith(own) or variable_of(owner, name[len(own):]) is None:
            return None
        if (label, owner.path) in self._prefixed:
            return owner.path, name[len(own):]
        self._prefixed.add((label, owner.path))
        self.reading.note(f"{label} names the parameters of component '{'.'.join(owner.path)}' with the "
                          f"component's name ('{name}'); SSP names them relative to the component "
                          f"('{name[len(own):]}'): read as such")
        return owner.path, name[len(own):]

    # --- choosing and applying --------------------------------------------------

    def apply(self, units: dict, unit_names: dict, flow: Flow) -> None:
        """Set the chosen values into the spec's ``units`` (``parameters`` or ``start``)."""
        nodes = self.reading.nodes
        # a higher level (smaller depth) wins, then the later binding at the same level
        chosen: dict[tuple, tuple] = {}
        for depth, order, target, value, unit, extra, label in self.found:
            current = chosen.get(target)
            if current is None or (depth, -order) < (current[0], -current[1]):
                chosen[target] = (depth, order, value, unit, extra, label)
        system_values = {t: v for t, v in chosen.items() if nodes[t[0]].kind == "system"}
        self.system_values = system_values
        # system connectors with values feed the component variables they are connected to (a parameter
        # connection); such a value counts as bound where the system connector's value was bound, so it beats
        # the component's own binding (a higher system wins) and loses to a binding of a still higher system
        fed: dict[tuple, tuple] = {}
        for end in flow.into:
            node = nodes[end[0]]
            if node.kind != "component" or node.fmu is None or variable_of(node, end[1]) is None:
                continue
            chain = self.valued_chain(flow.chain(end))
            if chain is None:
                continue
            start = chain[0].start
            depth, order, value, unit, extra, label = system_values[start]
            via = f"system connector '{'.'.join((*start[0], start[1]))}' (parameter connection)"
            direct = chosen.get(end)
            if direct is not None and direct[0] <= depth:
                self.kept.add(end)
                if direct[0] == depth:
                    self.reading.alike.add("bound twice", f"'{'.'.join(end[0])}.{end[1]}' is bound directly "
                                           f"({direct[5]}) and through {via} by the same system: the direct "
                                           f"binding {direct[2]!r} is used", f"'{'.'.join(end[0])}.{end[1]}'",
                                           "more variables bound both ways keep their direct binding")
                continue
            if isinstance(value, float):  # into the system connector's unit, then along the chain
                value = self.converted(value, unit, extra, label, flow.unit_of(start))
                factor, offset = flow.compose(chain, flow.unit_of(start))
                value = factor * value + offset
            if direct is not None:
                binder = ".".join(end[0][:direct[0]]) or "the root system"
                self.reading.alike.add("overridden", f"'{'.'.join(end[0])}.{end[1]}': {value!r} from {via} "
                                       f"overrides the value {direct[2]!r} bound by '{binder}' ({direct[5]}), as "
                                       "bindings of a higher system win", f"'{'.'.join(end[0])}.{end[1]}'",
                                       "more values from parameter connections override a lower binding likewise")
            fed[end] = (value, (None, {}, extra[2], extra[3]), label)
        for target, (depth, order, value, unit, extra, label) in chosen.items():
            node = nodes[target[0]]
            if node.kind == "component" and node.fmu is not None and target not in fed:
                self._assign(units, unit_names, target, value, unit, extra, label, node)
        for end, (value, extra, label) in fed.items():
            self._assign(units, unit_names, end, value, None, extra, label, nodes[end[0]])

    def valued_chain(self, chain: list) -> list | None:
        """The part of a connection ``chain`` (as :meth:`Flow.chain` gives it) from the system connector whose
        bound value reaches its end: the one bound by the highest system (SSP: a higher level wins), the
        upstream one at one level (a connection feeds the connector it ends at).  A connector bound by nobody
        passes the value of one further down through, so a root connector without a value, connected to a
        sub-system's bound connector, leaves that binding in force.  None when no connector of the chain
        holds a value.  Valid after :meth:`apply` chose ``system_values``."""
        best: int | None = None
        for i, edge in enumerate(chain):
            value = self.system_values.get(edge.start)
            if value is not None and (best is None or value[0] < self.system_values[chain[best].start][0]):
                best = i
        return None if best is None else chain[best:]

    def converted(self, value: float, unit: str | None, extra: tuple, label: str, target_unit: tuple) -> float:
        """A bound Real value in the target's unit: the .ssv unit converted (unless the mapping suppresses it),
        then the mapping entry's LinearTransformation."""
        transform, ssv_units, _, where = extra
        if not (transform is not None and transform[1]):
            a, b = unit_conversion(self.reading, (unit, {}), target_unit, where, ssv_units, label)
            value = a * value + b
        if transform is not None and transform[0] is not None:
            f, o = transform[0]
            value = f * value + o
        return value

    def _assign(self, units: dict, unit_names: dict, target: Target, value: Any, unit: str | None,
                extra: tuple, label: str, node: Node) -> None:
        where = extra[3]
        variable = variable_of(node, target[1])
        if isinstance(value, float):
            value = self.converted(value, unit, extra, label, unit_of(self.reading.nodes, *target))
        if variable.causality in ("parameter", "structuralParameter"):
            field_name = "parameters"
        elif variable.causality in ("input", "local", "output", "calculatedParameter"):
            field_name = "start"
        else:
            self.reading.problem(where, f"'{target[1]}' of '{'.'.join(target[0])}' is {variable.causality} and "
                                 "cannot be set", "bind parameters, inputs or start values only", label)
            return
        units[unit_names[target[0]]].setdefault(field_name, {})[target[1]] = value
