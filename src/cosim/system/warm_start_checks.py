"""What a warm start (``experiment.warm_start``) may vary: inputs and tunable parameters, nothing else.

A warm-started point restores the units' states saved at the warm-start time and sets its own values there
(:mod:`cosim.execution.warm_start`).  A fixed parameter, or the start value of a state, is part of that saved state
and cannot change after initialization (FMI allows setting only inputs and parameters of variability ``tunable``
between steps), so a design parameter or a run's value naming one is refused before anything runs.
"""

from __future__ import annotations

from typing import Any, Iterable, Mapping

from cosim.errors import Problem, json_path
from cosim.system.parts import SystemUnit
from cosim.system.signals import split_unit_name
from cosim.units.protocol import parse_port

FIX = ("vary inputs and tunable parameters only (an FMU's variability=\"tunable\", a Python unit's "
       "Variable(..., variability=\"tunable\")), or remove experiment.warm_start")


def untunable(unit: SystemUnit, port: str) -> str | None:
    """Why ``port`` of ``unit`` cannot be set at a warm start (a phrase), or None when it can."""
    base, index = parse_port(port)
    name = unit.variable_name(port if index is None else base)
    try:
        var = unit.description.variable(name)
    except KeyError:
        try:
            var = unit.description.variable(unit.variable_name(port))
        except KeyError:
            return None  # not a variable: reported by the value check
    if var.causality == "input" or (var.causality == "parameter" and var.variability == "tunable"):
        return None
    if var.causality == "parameter":
        return f"a {var.variability or 'fixed'} parameter, part of the state saved at the warm start"
    return f"the start value of {'an' if var.causality[0] in 'aeiou' else 'a'} {var.causality}, part of the state " \
           "saved at the warm start"


def warm_start_problems(spec: Any, units: Mapping[str, SystemUnit], targets: Iterable[tuple[str, str]]) -> list[Problem]:
    """Problems of ``targets`` ((target 'unit.port', JSON path)) under the spec's warm start; none without one."""
    if spec.experiment.warm_start is None:
        return []
    problems = []
    for target, path in targets:
        unit_name, _, port = split_unit_name(target, list(units))
        if unit_name not in units:
            continue  # reported where targets are resolved
        why = untunable(units[unit_name], port)
        if why is not None:
            problems.append(Problem(spec.path, path, f"'{target}' is {why}: a warm-started run (experiment."
                                    f"warm_start {spec.experiment.warm_start:g}) cannot change it", FIX))
    return problems


def check_warm_start_design(spec: Any, units: Mapping[str, SystemUnit], problems: list[Problem]) -> None:
    """Add the problems of the design parameters under the spec's warm start."""
    problems.extend(warm_start_problems(spec, units, [(p.target, json_path(["design", "parameters", p.target]))
                                                      for p in spec.design.parameters]))
