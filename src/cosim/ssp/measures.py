"""Units of measure in an SSP: the ``ssd:Units`` (or an .ssv's ``ssv:Units``) definitions, and the conversion
between two connectors' units (problems recorded in the reading, identity returned)."""

from __future__ import annotations

import re
from typing import Any

from cosim.ssp.reading import Reading
from cosim.ssp.xml import element_path, tag
from cosim.util.quantities import (
    BASE_UNITS,
    IncompatibleUnits,
    UnitDefinition,
    UnknownUnit,
    conversion,
)


def read_unit_definitions(root: Any) -> dict[str, UnitDefinition]:
    """The ssd:Units (or ssv:Units) definitions: SI value = factor * value + offset."""
    units: dict[str, UnitDefinition] = {}
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


def _unbracketed(reading: Reading, end: tuple, element: Any, ssd_units: dict, label: str | None) -> tuple:
    """``end`` (unit name, definitions) with a unit written in brackets (``[m]``, as Dymola and OMSimulator
    show units and some of their exports write them into an .ssv) read as the name inside, with one note per
    file; a name ssd:Units defines with its brackets is kept."""
    bare = re.fullmatch(r"\[\s*([^\]]*?)\s*\]", end[0])
    if not bare or end[0] in ssd_units:
        return end
    where = f"{label or reading.label}: {element_path(element)}" if element is not None else label or reading.label
    if f"{where} {end[0]}" in reading.bracketed:
        return bare.group(1), end[1]
    reading.bracketed.add(f"{where} {end[0]}")
    reading.alike.add(("bracketed unit", label or reading.label),
                      f"{where}: unit '{end[0]}' is written in brackets (as tools show units); SSP and FMI write "
                      f"'{bare.group(1)}': read as such", f"'{end[0]}'", "more units in brackets read likewise")
    return bare.group(1), end[1]


def unit_conversion(reading: Reading, source: tuple | None, target: tuple | None, element: Any,
                    units: dict | None = None, label: str | None = None) -> tuple[float, float]:
    """(a, b) with value_in_target = a * value_in_source + b.

    ``source`` and ``target`` are (unit name, the FMU's own unit
    definitions); ssd:Units (and an .ssv's Units) define names first, then
    the FMU's, then :mod:`cosim.util.quantities` reads the name.
    Identity when a unit is missing or both are equal, and (with a problem recorded) when they do not convert.
    A unit written in brackets is read without them, with a note.
    """
    if not source or not target or not source[0] or not target[0] or source[0] == target[0]:
        return 1.0, 0.0
    ssd_units = {**reading.units, **(units or {})}
    source, target = (_unbracketed(reading, end, element, ssd_units, label) for end in (source, target))
    if source[0] == target[0]:
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
