"""Value checks: a value set on a unit's port fits its causality, type, size and declared range.

Used for a spec's ``parameters`` and ``start`` values, for design-point
values (:meth:`cosim.system.builder.System.assignment_for`) and for the
samples of a design parameter's range.
"""

from __future__ import annotations

import math
from typing import Any

from cosim.errors import Problem, did_you_mean
from cosim.system.parts import Assignment, SystemUnit
from cosim.system.signals import port_names
from cosim.units.protocol import Variable, flatten_value, parse_port, resolve_port

SETTABLE_AS_PARAMETER = ("parameter", "structuralParameter")
SETTABLE_AS_START = ("input", "local", "output", "independent", "calculatedParameter")


def article(causality: str) -> str:
    """'an input' / 'a parameter': a causality with its article, for messages."""
    return ("an " if causality[0] in "aeiou" else "a ") + causality


def assignment(unit: SystemUnit, port: str, value: Any, field_name: str | None, problems: list[Problem],
                file: str, path: str) -> Assignment | None:
    """The checked Assignment of ``value`` to ``port`` of ``unit``, or None after adding a Problem at ``path``.

    ``field_name`` is 'parameters', 'start' or None (a design or command-line value: parameters and inputs)."""
    base, index = parse_port(port)
    actual = unit.variable_name(port) if index is None else f"{unit.variable_name(base)}[{index}]"
    try:
        var, refs = resolve_port(unit.description, actual)
    except KeyError:
        problems.append(Problem(file, path, f"unit '{unit.name}' has no variable '{port}'."
                                            f"{did_you_mean(base, port_names(unit))}",
                                f"run 'cosim inspect' on the spec to list the variables of '{unit.name}'"))
        return None
    except IndexError as exc:
        problems.append(Problem(file, path, str(exc), "use an index from 1 to the array's size"))
        return None
    if field_name == "parameters" and var.causality not in SETTABLE_AS_PARAMETER:
        problems.append(Problem(file, path, f"'{port}' of unit '{unit.name}' is {article(var.causality)}, "
                                            "not a parameter", "set it under 'start' instead of 'parameters'"))
        return None
    if field_name == "start" and var.causality not in SETTABLE_AS_START:
        problems.append(Problem(file, path, f"'{port}' of unit '{unit.name}' is a {var.causality}",
                                "set it under 'parameters' instead of 'start'"))
        return None
    if field_name == "start" and var.causality in ("output", "local") and var.initial == "calculated":
        # FMI: a variable the unit calculates (initial="calculated") has no start value an environment may set;
        # the FMU refused it only at run time, after the spec had passed validate
        problems.append(Problem(file, path, f"'{port}' of unit '{unit.name}' is {article(var.causality)}"
                                            f"{_calculated(var)}: FMI initial=\"calculated\"",
                                "remove it from 'start'; set the parameter, input or state it is calculated "
                                "from instead ('cosim inspect' lists them)"))
        return None
    if field_name is None and var.causality not in SETTABLE_AS_PARAMETER + ("input",) and not has_start(var):
        problems.append(Problem(file, path, f"'{port}' of unit '{unit.name}' is {article(var.causality)}"
                                            f"{_calculated(var)}; only parameters, inputs and start values the "
                                            "unit declares (FMI initial=\"exact\" or \"approx\", e.g. a state's) "
                                            "can be set", "choose a parameter"))
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
        message = value_problem(var, v)
        if message:
            problems.append(Problem(file, path, message[0], message[1]))
            return None
        checked.append(float(v) if var.type == "Real" else int(v) if var.type == "Integer"
                       else bytes.fromhex(v) if var.type == "Binary" else v)
    return Assignment(unit.name, tuple(refs), tuple(checked))


def has_start(var: Variable) -> bool:
    """True for an output or local with a start value the unit lets be set (FMI initial="exact" or "approx":
    a state's start value, as the Reference FMUs declare BouncingBall's h or Dahlquist's x)."""
    return var.causality in ("output", "local") and var.initial in ("exact", "approx")


def _calculated(var: Variable) -> str:
    return " the unit calculates (no start value to set)" if var.causality in ("output", "local") else ""


def value_problem(var: Variable, value: Any) -> tuple[str, str] | None:
    """(what is wrong, the fix) when ``value`` does not fit ``var``'s type, finiteness or range; else None."""
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
