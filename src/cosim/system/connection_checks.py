"""Connection checks: each connection goes from an output to an input of a fitting type, size and unit."""

from __future__ import annotations

from typing import Mapping

from cosim.errors import Problem, json_path
from cosim.spec.loader import Spec
from cosim.system.connection_units import connection_conversion
from cosim.system.parts import Connection, SystemUnit
from cosim.system.signals import resolve_signal, split_unit_name
from cosim.system.value_checks import article
from cosim.units.registry import replaying_units


def check_connections(spec: Spec, units: Mapping[str, SystemUnit], problems: list[Problem]) -> list[Connection]:
    """The spec's connections that fit (output to input, type, size, unit); a Problem for each that does not."""
    file = spec.path
    connections = []
    fed: dict[tuple[str, str, int], int] = {}
    players = replaying_units(spec.units)
    for c in spec.connections:
        if players and split_unit_name(str(c.target), units)[0] in players:
            continue  # the input of a unit now replayed by a player: the recording already has what it caused
        base = ["connections", c.index]
        where = json_path(base)  # f-strings below: json_path per end cost a tenth of the time of 10^5 connections
        # a misspelt end is suggested only what it may be: an output for 'from', an input for 'to'
        source = resolve_signal(c.source, units, problems, file, f"{where}.from", suggest=("output",))
        target = resolve_signal(c.target, units, problems, file, f"{where}.to", suggest=("input",))
        if source is None or target is None:
            continue
        ok = True
        if source.variable.causality != "output":
            problems.append(Problem(file, f"{where}.from",
                                    f"'{c.source}' is {article(source.variable.causality)}, not an output",
                                    "a connection goes from an output to an input"))
            ok = False
        if target.variable.causality != "input":
            problems.append(Problem(file, f"{where}.to",
                                    f"'{c.target}' is {article(target.variable.causality)}, not an input",
                                    "a connection goes from an output to an input; swap 'from' and 'to' if "
                                    "they are reversed"))
            ok = False
        if "Clock" in (source.variable.type, target.variable.type):
            problems.append(Problem(file, where, f"'{c.source}' -> '{c.target}' connects an FMI 3.0 "
                                    "Clock; cosim does not run clocked partitions or events",
                                    "remove the connection; connect value variables only"))
            ok = False
        elif not types_fit(source.variable.type, target.variable.type):
            problems.append(Problem(file, where, f"type mismatch: '{c.source}' is "
                                    f"{source.variable.type}, '{c.target}' is {target.variable.type}",
                                    "connect variables of the same type (Integer may feed Real; Binary "
                                    "connects only to Binary)"))
            ok = False
        if len(source.refs) != len(target.refs):
            problems.append(Problem(file, where, f"size mismatch: '{c.source}' has {len(source.refs)} "
                                    f"element(s), '{c.target}' has {len(target.refs)}",
                                    "connect arrays of the same size, or single elements like 'x[2]'"))
            ok = False
        for ref in target.refs:
            key = (target.unit, ref.variable, ref.offset)
            if key in fed:
                problems.append(Problem(file, f"{where}.to",
                                        f"input '{c.target}' is already fed by connection {fed[key]}",
                                        "an input takes exactly one source; remove one of the connections"))
                ok = False
                break
            fed[key] = c.index
        (factor, offset), unit_problem = connection_conversion(
            c.source, source.variable, units[source.unit].description, c.target, target.variable,
            units[target.unit].description, c.convert, file, where)
        if unit_problem is not None:
            problems.append(unit_problem)
            ok = False
        if (c.factor != 1.0 or c.offset != 0.0) and target.variable.type != "Real":
            problems.append(Problem(file, where, f"'{c.target}' is {target.variable.type}: only Real "
                                    "connections take a factor or offset", "remove 'factor' and 'offset'"))
            ok = False
        if ok:  # the connection's own transformation after the unit conversion
            connections.append(Connection(source, target, c.factor * factor, c.factor * offset + c.offset))
    return connections


def types_fit(source: str, target: str) -> bool:
    """Whether a ``source`` type may feed a ``target`` type (the same, or Integer into Real)."""
    return source == target or (source == "Integer" and target == "Real")
