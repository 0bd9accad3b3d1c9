"""The ``python`` unit kind: a :class:`~cosim.units.python.unit.PythonUnit` subclass named
``package.module:Class`` or ``file.py:Class``."""

from __future__ import annotations

from cosim.units.kind import UnitKind, UnitSpec
from cosim.units.python.unit import PythonUnitType


def _create_python(spec: UnitSpec, folder: str) -> PythonUnitType:
    return PythonUnitType(spec.source, folder)


KIND = UnitKind("python", {
    "python": {"type": "string", "pattern": "^[^:]+:[A-Za-z_][A-Za-z0-9_.]*$",
               "description": "'package.module:Class' or 'file.py:Class'."},
}, _create_python, example='"python": "module:Class"', description="a PythonUnit subclass")
