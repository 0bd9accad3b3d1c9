"""The units of measure at both ends of a connection: equal, converted, or refused.

Every connection knows the unit of its source and its target (an FMU's
``unit``/``declaredType`` and ``<UnitDefinitions>``, a Python unit's
``Variable(unit=...)``, a player's ``"units"``).  :func:`connection_conversion`
decides what the master does with the values:

* no unit at one end, or equal units: values pass unchanged;
* convertible units (rpm -> rad/s, degC -> K, mm -> m): the master applies
  ``target = factor * source + offset`` at every transfer (without the offset
  when either end is an FMI ``relativeQuantity``, e.g. a temperature difference);
* different quantities, or a unit cosim cannot read: a Problem naming the file,
  the connection, both ends with their units, and the fix;
* ``"convert": false`` on the connection: values pass unchanged, unchecked.
"""

from __future__ import annotations

from cosim.errors import Problem
from cosim.units.protocol import UnitDescription, Variable
from cosim.util.quantities import IncompatibleUnits, UnitConversionError, conversion

IDENTITY = (1.0, 0.0)


def connection_conversion(source_text: str, source: Variable, source_unit: UnitDescription,
                          target_text: str, target: Variable, target_unit: UnitDescription,
                          convert: bool, file: str, path: str) -> tuple[tuple[float, float], Problem | None]:
    """``((factor, offset), None)`` for a connection that fits, ``(IDENTITY, problem)`` when it does not."""
    if not convert or not source.unit or not target.unit or source.type not in ("Real", "Integer"):
        return IDENTITY, None
    try:
        factor, offset = conversion(source.unit, target.unit, source_unit.unit_definitions,
                                    target_unit.unit_definitions)
    except UnitConversionError as exc:
        what = "different quantities" if isinstance(exc, IncompatibleUnits) else "units cosim cannot compare"
        return IDENTITY, Problem(
            file, path, f"units do not fit ({what}): '{source_text}' is in '{source.unit}', '{target_text}' is in "
                        f"'{target.unit}': {exc}",
            "connect ports of the same quantity, correct the unit where it is declared, or add "
            "\"convert\": false to this connection to pass the values unchanged")
    if source.relative_quantity or target.relative_quantity:
        offset = 0.0  # a difference of temperatures converts by the factor alone (FMI relativeQuantity)
    if (factor, offset) != IDENTITY and target.type != "Real":
        return IDENTITY, Problem(
            file, path, f"'{source_text}' in '{source.unit}' would need converting to '{target.unit}' "
                        f"(x {factor:g} + {offset:g}), but '{target_text}' is {target.type}",
            "connect to a Real input, or add \"convert\": false to pass the values unchanged")
    return (factor, offset), None
