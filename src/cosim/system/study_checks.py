"""Checks of a study's objectives and design space against its system."""

from __future__ import annotations

from typing import Any

from cosim.errors import ExpressionError, Problem, did_you_mean, json_path
from cosim.master.loops import strongly_connected
from cosim.spec.design import range_problem, size_problems
from cosim.spec.expressions import Expression
from cosim.spec.loader import Spec
from cosim.system.parts import LoadedUnits
from cosim.system.signals import split_unit_name
from cosim.system.value_checks import assignment
from cosim.units.protocol import parse_port, resolve_port
from cosim.units.registry import replaying_units
from cosim.util.quantities import IncompatibleUnits, UnitConversionError, conversion


def check_objective_expressions(spec: Spec, problems: list[Problem]) -> None:
    """Problems of the objectives' expressions: syntax, unknown names, cycles."""
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
    components = strongly_connected(list(depends), {k: v & set(depends) for k, v in depends.items()})
    for comp in components:
        if len(comp) > 1 or comp[0] in depends.get(comp[0], set()):
            problems.append(Problem(spec.path, "$.objectives", "objectives refer to each other in a cycle: "
                                    + ", ".join(sorted(comp)), "make one of them a signal reduction"))


def converted(value: Any, factor: float, offset: float) -> Any:
    """``value`` (a number, or a list of them; booleans and text as they are) as ``factor * value + offset``."""
    if isinstance(value, (list, tuple)):
        return [converted(v, factor, offset) for v in value]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return value
    return factor * value + offset


def fed_values(units: Any, target: str, value: Any) -> list[tuple[str, Any]]:
    """The unit parameters a value set on ``target`` ('unit.port') sets too, each as ``(target, value)``: the
    unit's ``feeds`` for that port (a ``connectors`` unit's parameter connector, whose parameter connections
    set ``to`` = factor x value + offset); empty for any other target."""
    unit_name, _, port = split_unit_name(target, units)
    unit = units.get(unit_name)
    feeds = ((unit.spec.options.get("feeds") or {}).get(port) or ()) if unit is not None else ()
    result = []
    for feed in feeds:
        factor, offset = float(feed.get("factor", 1.0)), float(feed.get("offset", 0.0))
        result.append((feed["to"], value if (factor, offset) == (1.0, 0.0) else converted(value, factor, offset)))
    return result


def _check_fed(units: Any, target: str, samples: list[Any], file: str, path: str, problems: list[Problem]) -> None:
    """Problems of the values the parameters fed by ``target`` get (see :func:`fed_values`)."""
    for sample in samples:
        for fed, value in fed_values(units, target, sample):
            unit_name, _, port = split_unit_name(fed, units, units.failed)
            if unit_name not in units:
                if unit_name not in units.failed:
                    problems.append(Problem(file, path, f"'{target}' feeds '{fed}', a port of no unit",
                                            f"name units of the spec in the 'feeds' of '{target.rsplit('.', 1)[0]}'"))
                return
            if assignment(units[unit_name], port, value, None, problems, file, f"{path} (feeding '{fed}')") is None:
                return


def _design_unit_conversion(p: Any, unit: Any, port: str, file: str, path: str,
                            problems: list[Problem]) -> tuple[float, float] | None:
    """``(factor, offset)`` from a design parameter's ``unit`` to its port's declared unit; None (after adding a
    Problem) when the two are not the same quantity or a unit is not understood.  A port that declares no unit
    takes the values as written (the design's unit only labels the table's column)."""
    base, index = parse_port(port)
    actual = unit.variable_name(port) if index is None else f"{unit.variable_name(base)}[{index}]"
    try:
        var, _ = resolve_port(unit.description, actual)
    except (KeyError, IndexError):
        return (1.0, 0.0)  # reported by the value check
    if not var.unit:
        return (1.0, 0.0)
    try:
        return conversion(p.unit, var.unit, None, unit.description.unit_definitions)
    except UnitConversionError as exc:
        what = "different quantities" if isinstance(exc, IncompatibleUnits) else "not understood"
        problems.append(Problem(file, path + ".unit", f"'{p.unit}' cannot be converted to '{var.unit}', the unit "
                                f"of '{p.target}' ({what}): {exc}", f"write the range in '{var.unit}' (or a unit of the same "
                                "quantity, converted when the point is set), or drop 'unit'"))
        return None


def check_design(spec: Spec, units: LoadedUnits, problems: list[Problem]) -> dict[str, tuple[float, float]]:
    """Problems of the design space: unknown targets, values that do not fit, bad ranges, size, constraint.

    Returns the conversions ``target -> (factor, offset)`` from each design parameter's ``unit`` to its port's
    unit, for the parameters where they are not the identity: a point's values are in the design's units (as the
    table's columns are) and are converted when they are set (:func:`cosim.execution.point.assignments_for`).
    The values and range ends are checked against the port's range after conversion.
    """
    conversions: dict[str, tuple[float, float]] = {}
    players = replaying_units(spec.units)
    for p in spec.design.parameters:
        path = json_path(["design", "parameters", p.target])
        unit_name, _, port = split_unit_name(p.target, units, units.failed)
        if unit_name in players:
            continue  # a replayed unit: `cosim run` needs no design; a sweep refuses it (cosim.studies.sweep)
        if unit_name not in units:
            if unit_name not in units.failed:
                problems.append(Problem(spec.path, path, f"unknown unit '{unit_name}'."
                                        f"{did_you_mean(unit_name, units)}", "use 'unit.parameter'"))
            continue
        samples = list(p.values) if p.values is not None else [p.min, p.max] if p.min is not None else [False, True]
        if p.unit:
            factor_offset = _design_unit_conversion(p, units[unit_name], port, spec.path, path, problems)
            if factor_offset is None:
                continue
            if factor_offset != (1.0, 0.0):
                conversions[p.target] = factor_offset
                samples = [converted(value, *factor_offset) for value in samples]
        for value in samples:
            if assignment(units[unit_name], port, value, None, problems, spec.path, path) is None:
                break
        else:
            _check_fed(units, p.target, samples, spec.path, path, problems)
        if p.values is None and not p.is_bool:
            # the ends only: whether a range needs a step is the study's (a sweep's grid does, cosim optimize and
            # cosim sensitivity draw from [min, max]); DesignSpace checks it for a sweep, validate --for chooses
            problem = range_problem(p.min, p.max, p.step, grid=False)
            if problem is not None:
                problems.append(Problem(spec.path, path, *problem))
    if spec.design.method != "grid" and spec.design.parameters and spec.design.samples is None:
        problems.append(Problem(spec.path, "$.design.samples", f"method '{spec.design.method}' needs 'samples'",
                                "add e.g. \"samples\": 100"))
    problems.extend(size_problems(spec))  # counted, never made
    if spec.design.constraint:
        try:
            Expression(spec.design.constraint)
        except ExpressionError as exc:
            problems.append(Problem(spec.path, "$.design.constraint", str(exc), "write a comparison of parameters"))
    return conversions
