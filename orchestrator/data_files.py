"""Files a Python unit reads, found from its parameters so they travel with the unit.

A :class:`~orchestrator.units.python.PythonUnit` declares in ``data_files``
the String parameters whose values are paths of files it reads (a plant
description, a URDF, a table)::

    class Planner(PythonUnit):
        variables = (Variable("plant_file", "parameter", type="String", start=""), ...)
        data_files = ("plant_file",)

:func:`attach` (run when a :class:`~orchestrator.system.System` is built)
collects every value such a parameter can take in the study -- the unit's
start value, the spec's ``parameters`` and the ``values`` of a design
parameter -- and resolves each relative path against the spec's folder (an
absolute path stays).  Values that name an existing file go into the unit
type's ``data_paths`` (value as written -> file): the unit opens that file
(also when cosim runs from another working directory), and a sweep's payload
carries the file's bytes with the unit's own source
(:meth:`PythonUnitType.files`), so workers without the client's folders read
the copy written beside the unit on the worker.  A value that names no
existing file is left to the unit (an empty string meaning "the built-in
default", a path inside an installed package).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator


def attach(system: Any) -> None:
    """Fill ``data_paths`` of every Python unit type of ``system`` whose class declares ``data_files``."""
    from .units.python import PythonUnitType

    for name, system_unit in system.units.items():
        unit_type = system_unit.unit_type
        if not isinstance(unit_type, PythonUnitType):
            continue
        declared = set(unit_type.load_class().data_files)
        if not declared:
            continue
        paths = {}
        for value in sorted(set(_values(system, name, declared))):
            found = _resolve(value, system.spec.folder)
            if found is not None:
                paths[value] = found
        unit_type.data_paths = paths


def _values(system: Any, unit: str, declared: set[str]) -> Iterator[str]:
    """Every string the declared parameters of ``unit`` may hold in this study."""
    from .problems import SpecError

    for variable in system.units[unit].description.variables:
        if variable.name in declared and isinstance(variable.start, str):
            yield variable.start
    for assignment in system.assignments:
        if assignment.unit == unit:
            yield from _strings(assignment, declared)
    for parameter in system.spec.design.parameters:
        for value in parameter.values or ():
            try:
                assignment = system.assignment_for(parameter.target, value)
            except SpecError:  # reported by the design check, not here
                continue
            if assignment.unit == unit:
                yield from _strings(assignment, declared)


def _strings(assignment: Any, declared: set[str]) -> Iterator[str]:
    for ref, value in zip(assignment.refs, assignment.values):
        if ref.variable in declared and isinstance(value, str):
            yield value


def _resolve(value: str, folder: str) -> str | None:
    """The absolute path of the file ``value`` names (relative: in ``folder``), or None when it names none."""
    if not value:
        return None
    path = Path(value).expanduser()
    if not path.is_absolute():
        path = Path(folder) / path
    return str(path.resolve()) if path.is_file() else None
