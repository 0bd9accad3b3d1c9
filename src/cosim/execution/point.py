"""One design point, from values to a result: the one pipeline every caller uses.

``values`` ({'unit.param': value}) -> checked :class:`~cosim.system.builder.Assignment`
objects -> one :class:`~cosim.execution.run.Execution` -> a
:class:`~cosim.execution.run.RunResult`.  :func:`cosim.run`,
``cosim run`` (with ``--set`` and ``--point``), the re-run of a table row and
the isolated child process of a sweep all call :func:`run_point`, so a value
is checked and applied the same way everywhere.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Mapping, Sequence

from cosim.errors import Problem, SpecError
from cosim.execution.run import Execution, RunResult
from cosim.execution.warm_up import warm_up
from cosim.master.observers import Observer
from cosim.system.builder import System
from cosim.system.parts import Assignment
from cosim.system.study_checks import converted
from cosim.system.warm_start_checks import warm_start_problems
from cosim.units.protocol import Unit


def assignments_for(system: System, values: Mapping[str, Any] | None) -> list[Assignment]:
    """The checked assignments setting ``values`` ('unit.param' -> value) on ``system``, in order.

    A design parameter's value is in its design ``unit`` (as in the results table) and is converted to its
    port's unit here; a target that feeds other parameters (an SSP system's parameter connector, see
    :meth:`~cosim.system.builder.System.fed_by`) sets them too.  Raises SpecError listing every target or value that does not fit (not only the first).
    """
    assignments: list[Assignment] = []
    problems: list[Problem] = []
    conversions = getattr(system, "design_conversions", {})
    for target, value in (values or {}).items():
        if target in conversions:
            value = converted(value, *conversions[target])
        try:
            assignments.append(system.assignment_for(target, value))
            # an SSP system's parameter connector sets the FMU parameters its parameter connections reach
            assignments.extend(system.assignment_for(fed, fed_value) for fed, fed_value in system.fed_by(target, value))
        except SpecError as exc:
            problems.extend(exc.problems)
    if problems:
        raise SpecError(problems)
    return assignments


def run_point(system: System, values: Mapping[str, Any] | None = None, *, record: bool = False,
              units: Mapping[str, Unit] | None = None, observers: Sequence[Observer] = ()) -> RunResult:
    """Run ``system`` once with ``values`` applied after the spec's own parameters.

    ``record`` keeps full traces of the recorded signals; ``units`` are live
    instances to reuse (fresh or reset; the caller owns them); ``observers``
    watch the run.  Raises SpecError when a value does not fit (under ``experiment.warm_start``: names anything
    but an input or a tunable parameter); a failing run (or warm-up) is reported in the result instead (see :class:`~cosim.execution.run.RunResult`).
    """
    assignments = assignments_for(system, values)
    problems = warm_start_problems(system.spec, system.units, [(target, "$") for target in values or {}])
    if problems:
        raise SpecError(problems)
    if system.spec.experiment.warm_start is not None and system.warm_start is None:
        state, result = warm_up(system)  # a study makes it once (make_payload); a single run makes its own
        if state is None:
            result.message = f"the warm-up to t={system.spec.experiment.warm_start:g} failed: {result.message}"
            return result
        system = replace(system, warm_start=state)
    return Execution(system, assignments, record=record, units=units, observers=observers).run()
