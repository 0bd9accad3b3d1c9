"""Units of measure in an SSP: the ``ssd:Units`` (or an .ssv's ``ssv:Units``) definitions, and the conversion
between two connectors' units (problems recorded in the reading, identity returned)."""

from __future__ import annotations

import re
from typing import Any

from cosim.ssp.reading import Reading
from cosim.ssp.xml import tag
from cosim.util.quantities import (
    BASE_UNITS,
    IncompatibleUnits,
    UnitDefinition,
    UnknownUnit,
    conversion,
)


def read_unit_definitions(root: Any) -> dict[str, UnitDefinition]:
    """The ssd:Units (or ssv:Units) definitions: SI value = factor * value + offset."""
    units = {}
    container = root.find(tag("ssd", "Units"))
    if container is None:
        container = root.find(tag("ssv", "Units"))
    if container is None:
        return units
    for unit in container.findall(tag("ssc", "Unit")):
        base = unit.find(tag("ssc", "BaseUnit"))
        attributes = dict(base.attrib) if base is not None else {}
        exponents = tuple(int(attributes.get(k, 0)) for k in BASE_UNITS)
        name = unit.get("name")
        units[name] = UnitDefinition(name, exponents, float(attributes.get("factor", 1)),
                                     float(attributes.get("offset", 0)))
    return units


def unit_conversion(reading: Reading, source: tuple | None, target: tuple | None, element: Any,
                    units: dict | None = None, label: str | None = None) -> tuple[float, float]:
    """(a, b) with value_in_target = a * value_in_source + b.

    ``source`` and ``target`` are (unit name, the FMU's own unit
    definitions); ssd:Units (and an .ssv's Units) define names first, then
    the FMU's, then :mod:`cosim.util.quantities` reads the name.
    Identity when a unit is missing or both are equal, and (with a problem recorded) when they do not convert.
    """
    if not source or not target or not source[0] or not target[0] or source[0] == target[0]:
        return 1.0, 0.0
    ssd_units = {**reading.units, **(units or {})}
    for name in (source[0], target[0]):
        bare = re.fullmatch(r"\[\s*([^\]]*?)\s*\]", name)
        if bare and name not in ssd_units:
            reading.problem(element, f"unit '{name}' is written in brackets; SSP and FMI write units without them",
                            f"write unit=\"{bare.group(1)}\"", label)
            return 1.0, 0.0
    try:
        return conversion(source[0], target[0], {**source[1], **ssd_units}, {**target[1], **ssd_units})
    except UnknownUnit as exc:
        reading.problem(element, f"cannot convert '{source[0]}' to '{target[0]}': {exc}",
                        "define the unit under ssd:Units (ssc:Unit with its ssc:BaseUnit), or set "
                        "suppressUnitConversion=\"true\"", label)
    except IncompatibleUnits as exc:
        reading.problem(element, f"units '{source[0]}' and '{target[0]}' measure different quantities: {exc}",
                        "connect compatible quantities, or set suppressUnitConversion=\"true\" and give a "
                        "LinearTransformation", label)
    return 1.0, 0.0
