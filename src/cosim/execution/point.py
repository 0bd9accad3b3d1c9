"""One design point, from values to a result: the one pipeline every caller uses.

``values`` ({'unit.param': value}) -> checked :class:`~cosim.system.builder.Assignment`
objects -> one :class:`~cosim.execution.run.Execution` -> a
:class:`~cosim.execution.run.RunResult`.  :func:`cosim.run`,
``cosim run`` (with ``--set`` and ``--point``), the re-run of a table row and
the isolated child process of a sweep all call :func:`run_point`, so a value
is checked and applied the same way everywhere.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

from cosim.errors import Problem, SpecError
from cosim.execution.run import Execution, RunResult
from cosim.master.observers import Observer
from cosim.system.builder import Assignment, System
from cosim.system.study_checks import converted
from cosim.units.protocol import Unit


def assignments_for(system: System, values: Mapping[str, Any] | None) -> list[Assignment]:
    """The checked assignments setting ``values`` ('unit.param' -> value) on ``system``, in order.

    A design parameter's value is in its design ``unit`` (as in the results table) and is converted to its
    port's unit here.  Raises SpecError listing every target or value that does not fit (not only the first).
    """
    assignments: list[Assignment] = []
    problems: list[Problem] = []
    conversions = getattr(system, "design_conversions", {})
    for target, value in (values or {}).items():
        if target in conversions:
            value = converted(value, *conversions[target])
        try:
            assignments.append(system.assignment_for(target, value))
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
    watch the run.  Raises SpecError when a value does not fit; a failing run
    is reported in the result instead (see :class:`~cosim.execution.run.RunResult`).
    """
    return Execution(system, assignments_for(system, values), record=record, units=units,
                     observers=observers).run()
