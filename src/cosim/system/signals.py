"""Signal resolution: 'unit.port' and 'unit.port[i]' texts to the scalar elements of a system's units.

Every function adds a :class:`~cosim.errors.Problem` (file, JSON path,
fix) for a text that does not fit, instead of raising, so a spec's checks can
report every mistake at once.
"""

from __future__ import annotations

from typing import Collection, Mapping, Sequence

from cosim.errors import Problem, can_suggest, did_you_mean
from cosim.system.parts import Signal, SystemUnit
from cosim.units.protocol import parse_port, resolve_port


def split_unit_name(text: str, *unit_names: Collection[str]) -> tuple[str, str, str]:
    """``('unit', '.', 'port')`` from ``'unit.port'``; ``unit_names``: the known names (one or more mappings or
    sets, e.g. the units and the units that failed to load).

    Units flattened from an SSP are named by their path (``SuT.motor``), so a
    unit name may contain dots: the longest known unit name followed by a dot
    wins; without one, the text splits at its first dot.  The text's prefixes
    are looked up (from its last dot back), so the cost does not grow with the
    number of units: 10^5 connections among 10^4 units stay linear.
    """
    end = text.rfind(".")
    while end > 0:
        prefix = text[:end]
        for names in unit_names:
            if prefix in names:
                return prefix, ".", text[end + 1:]
        end = text.rfind(".", 0, end)
    return text.partition(".")


def port_names(unit: SystemUnit, causalities: Collection[str] | None = None) -> list[str]:
    """The unit's variable names as the spec calls them (after the port mapping); with ``causalities``, only
    the variables of those causalities."""
    reverse = {v: k for k, v in unit.spec.ports.items()}
    return [reverse.get(v.name, v.name) for v in unit.description.variables
            if causalities is None or v.causality in causalities]


def resolve_signal(text: str, units: Mapping[str, SystemUnit], problems: list[Problem], file: str,
                    path: str, suggest: Collection[str] | None = None) -> Signal | None:
    """The Signal 'unit.port' or 'unit.port[i]' names, or None after adding a Problem at ``path``.

    ``suggest``: the causalities a "did you mean" may name for a port that does not exist (a connection's
    target suggests inputs only: issue 39, 'p_tota' suggested the output 'p_total'); None suggests any."""
    unit_name, dot, port = split_unit_name(text, units, getattr(units, "failed", ()))
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
    except KeyError:  # the names only for a suggestion, which a huge unit does not get (per problem: quadratic)
        names = port_names(unit, suggest) if can_suggest(len(unit.description.variables)) else ()
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


def expand_wildcard(text: str, units: Mapping[str, SystemUnit]) -> list[str]:
    """'unit.*' as every output port of the unit (arrays once); any other text as itself."""
    unit_name, _, port = split_unit_name(text, units)
    if port != "*" or unit_name not in units:
        return [text]
    unit = units[unit_name]
    grouped = {v.name for v in unit.description.variables if v.is_array}
    out = []
    for v, port_name in zip(unit.description.variables, port_names(unit)):
        if v.causality != "output" or v.type == "Clock":  # clocks carry no value to record
            continue
        base, index = parse_port(v.name)
        if index is not None and base in grouped:
            continue  # already recorded through its array
        out.append(f"{unit_name}.{port_name}")
    return out


def add_recorded(texts: Sequence[tuple[str, str]], units: Mapping[str, SystemUnit], problems: list[Problem],
                  file: str, probes: dict[str, Signal], recorded: list[str]) -> None:
    """Resolve (text, JSON path) record entries (``unit.*``: every output) into ``probes`` and ``recorded``."""
    seen = set(recorded)  # a set beside the list: an array of 10^5 elements is recorded in linear time
    for text, path in texts:
        for expanded in expand_wildcard(text, units):
            s = resolve_signal(expanded, units, problems, file, path)
            if s is not None and s.variable.type == "Clock":
                problems.append(Problem(file, path, f"'{expanded}' is an FMI 3.0 Clock, which has no value to record",
                                        "record value variables only"))
            elif s is not None:
                probes.setdefault(s.text, s)
                for column in s.columns:
                    if column not in seen:
                        seen.add(column)
                        recorded.append(column)
