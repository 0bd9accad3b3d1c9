"""Units of measure: what a unit string means, and how to convert between two.

FMI describes a unit by its exponents of the eight base units kg, m, s, A, K,
mol, cd and rad, a ``factor`` and an ``offset``:  a value ``v`` in the unit is
``factor * v + offset`` in SI base units (``<BaseUnit kg="1" m="1" s="-2"/>``
is a newton; degC is K with offset 273.15).  :class:`UnitDefinition` holds
exactly that.  An FMU may define its units itself (``<UnitDefinitions>``,
:func:`fmi_unit_definitions`); every other unit string is read with the
Modelica/FMI unit syntax by :func:`parse_unit`: factors joined by ``.``, one
``/``, integer exponents written after the name (``m/s2``, ``kg.m2``,
``N.m``, ``W/(m.K)``, ``s-1``), SI prefixes (``mm``, ``kW``, ``µs``) and a few
common non-SI names (``rpm``, ``deg``, ``degC``, ``min``, ``h``, ``bar``, ``l``).

:func:`conversion` gives the ``(factor, offset)`` that turns a value in one
unit into the other (``to = factor * from + offset``), or raises
:class:`IncompatibleUnits` / :class:`UnknownUnit` with a message that names
both units and what they mean.  FMI's base units count ``rad`` as a base unit,
so rad/s and Hz are different quantities, and rpm converts to rad/s.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Mapping

from cosim.errors import IncompatibleUnits, UnitConversionError, UnknownUnit  # noqa: F401 (raised here, caught by callers)

BASE_UNITS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


@dataclass(frozen=True)
class UnitDefinition:
    """A unit as FMI defines it: SI value = ``factor * value + offset``.

    ``exponents`` are those of kg, m, s, A, K, mol, cd, rad (in that order).
    """

    name: str
    exponents: tuple[int, ...] = (0,) * 8
    factor: float = 1.0
    offset: float = 0.0

    def dimension(self) -> str:
        """The exponents as a readable product, e.g. ``kg.m2.s-2`` ('1' when dimensionless)."""
        parts = [name + ("" if e == 1 else str(e)) for name, e in zip(BASE_UNITS, self.exponents) if e]
        return ".".join(parts) or "1"

    def times(self, other: "UnitDefinition", power: int = 1) -> "UnitDefinition":
        """This unit multiplied by ``other ** power`` (offsets are dropped: they only mean something alone)."""
        exponents = tuple(a + power * b for a, b in zip(self.exponents, other.exponents))
        return UnitDefinition(f"{self.name}.{other.name}", exponents, self.factor * other.factor ** power)


def _unit(name: str, factor: float = 1.0, offset: float = 0.0, **exponents: int) -> UnitDefinition:
    return UnitDefinition(name, tuple(exponents.get(b, 0) for b in BASE_UNITS), factor, offset)


# Names that take SI prefixes (mm, kN, MPa, µs, mA, mbar, ml ...).  "g" is the gram:
# the SI base unit of mass is the kilogram, so g = 1e-3 kg.
_PREFIXABLE = {u.name: u for u in (
    _unit("m", m=1), _unit("g", 1e-3, kg=1), _unit("s", s=1), _unit("A", A=1), _unit("K", K=1),
    _unit("mol", mol=1), _unit("cd", cd=1), _unit("rad", rad=1),
    _unit("Hz", s=-1), _unit("N", kg=1, m=1, s=-2), _unit("Pa", kg=1, m=-1, s=-2),
    _unit("J", kg=1, m=2, s=-2), _unit("W", kg=1, m=2, s=-3), _unit("C", A=1, s=1),
    _unit("V", kg=1, m=2, s=-3, A=-1), _unit("F", kg=-1, m=-2, s=4, A=2), _unit("Ohm", kg=1, m=2, s=-3, A=-2),
    _unit("Ω", kg=1, m=2, s=-3, A=-2), _unit("S", kg=-1, m=-2, s=3, A=2), _unit("Wb", kg=1, m=2, s=-2, A=-1),
    _unit("T", kg=1, s=-2, A=-1), _unit("H", kg=1, m=2, s=-2, A=-2), _unit("lm", cd=1), _unit("lx", cd=1, m=-2),
    _unit("Bq", s=-1), _unit("Gy", m=2, s=-2), _unit("Sv", m=2, s=-2), _unit("kat", mol=1, s=-1),
    _unit("l", 1e-3, m=3), _unit("L", 1e-3, m=3), _unit("bar", 1e5, kg=1, m=-1, s=-2),
    _unit("Wh", 3600.0, kg=1, m=2, s=-2), _unit("eV", 1.602176634e-19, kg=1, m=2, s=-2),
)}

# Names that take no prefix.  Factors are written so that the double is the
# correctly rounded value (pi/30 for rpm, not 2*pi/60 computed in two steps).
_PLAIN = {u.name: u for u in (
    _unit("1"), _unit("%", 0.01), _unit("kg", kg=1),
    _unit("min", 60.0, s=1), _unit("h", 3600.0, s=1), _unit("d", 86400.0, s=1),
    _unit("rpm", math.pi / 30.0, rad=1, s=-1), _unit("rev", 2.0 * math.pi, rad=1),
    _unit("deg", math.pi / 180.0, rad=1), _unit("°", math.pi / 180.0, rad=1),
    _unit("degC", 1.0, 273.15, K=1), _unit("°C", 1.0, 273.15, K=1),
    _unit("degF", 5.0 / 9.0, 273.15 - 32.0 * 5.0 / 9.0, K=1), _unit("degRk", 5.0 / 9.0, K=1),
    _unit("sr"), _unit("bit"), _unit("byte"),
)}

PREFIXES = {"Y": 1e24, "Z": 1e21, "E": 1e18, "P": 1e15, "T": 1e12, "G": 1e9, "M": 1e6, "k": 1e3, "h": 1e2,
            "da": 1e1, "d": 1e-1, "c": 1e-2, "m": 1e-3, "u": 1e-6, "µ": 1e-6, "μ": 1e-6, "n": 1e-9,
            "p": 1e-12, "f": 1e-15, "a": 1e-18, "z": 1e-21, "y": 1e-24}

_FACTOR_RE = re.compile(r"^(?P<name>[^\d\s^+-][^\d\s^+-]*?)\^?(?P<exp>[+-]?\d+)?$")


def _named(name: str) -> UnitDefinition | None:
    """A unit name without exponent: plain name, prefixable name, or prefix + prefixable name."""
    if name in _PLAIN:
        return _PLAIN[name]
    if name in _PREFIXABLE:
        return _PREFIXABLE[name]
    for prefix in sorted(PREFIXES, key=len, reverse=True):  # 'da' before 'd'
        if name.startswith(prefix) and name[len(prefix):] in _PREFIXABLE:
            base = _PREFIXABLE[name[len(prefix):]]
            return UnitDefinition(name, base.exponents, PREFIXES[prefix] * base.factor)
    return None


def _split_top(text: str, separators: str) -> list[tuple[str, str]]:
    """Split at separators outside parentheses; returns (separator before, part) pairs."""
    parts, depth, current, before = [], 0, "", ""
    for ch in text:
        if ch == "(":
            depth += 1
        elif ch == ")":
            depth -= 1
        if depth == 0 and ch in separators:
            parts.append((before, current))
            before, current = ch, ""
        else:
            current += ch
    parts.append((before, current))
    return parts


def parse_unit(text: str, definitions: Mapping[str, UnitDefinition] | None = None) -> UnitDefinition:
    """What the unit string ``text`` means.

    ``definitions`` (an FMU's own unit definitions) win over the built-in names.
    Raises UnknownUnit naming the part that is not understood.
    """
    definitions = definitions or {}
    text = text.strip()
    if text in definitions:
        return definitions[text]
    if text == "":
        return _PLAIN["1"]
    single = _parse_expression(text, definitions, text)
    # An offset (degC, degF) means something only for the unit alone, not inside a product.
    alone = _FACTOR_RE.match(text)
    if alone and not alone.group("exp"):
        named = definitions.get(alone.group("name")) or _named(alone.group("name"))
        if named is not None and named.offset:
            return UnitDefinition(text, named.exponents, named.factor, named.offset)
    return UnitDefinition(text, single.exponents, single.factor)


def _parse_expression(text: str, definitions: Mapping[str, UnitDefinition], whole: str) -> UnitDefinition:
    result = _PLAIN["1"]
    for separator, part in _split_top(text, "./*"):
        part = part.strip()
        if not part:
            raise UnknownUnit(f"'{whole}' is not a unit: an empty factor around '{separator or '.'}'")
        if part.startswith("(") and part.endswith(")"):
            factor = _parse_expression(part[1:-1], definitions, whole)
        elif part == "1":
            factor = _PLAIN["1"]
        else:
            m = _FACTOR_RE.match(part)
            named = (definitions.get(m.group("name")) or _named(m.group("name"))) if m else None
            if named is None or m is None:  # no match gives no name either
                raise UnknownUnit(f"'{whole}' is not a unit cosim knows ('{part}' is not understood); write it "
                                  "in the FMI/Modelica unit syntax, e.g. 'rad/s', 'N.m', 'm/s2', 'kg.m2', 'degC'")
            power = int(m.group("exp")) if m.group("exp") else 1
            factor = _PLAIN["1"].times(named, power)
        result = result.times(factor, -1 if separator == "/" else 1)
    return result


def conversion(from_unit: str | UnitDefinition, to_unit: str | UnitDefinition,
               from_definitions: Mapping[str, UnitDefinition] | None = None,
               to_definitions: Mapping[str, UnitDefinition] | None = None) -> tuple[float, float]:
    """``(factor, offset)`` with ``value_in_to = factor * value_in_from + offset``.

    Units are strings (read with :func:`parse_unit` and the given FMU
    definitions) or :class:`UnitDefinition`.  Equal strings convert with
    (1, 0) without being parsed.  Raises UnknownUnit when a unit is not
    understood and IncompatibleUnits when the two measure different quantities.
    """
    if isinstance(from_unit, str) and isinstance(to_unit, str) and from_unit.strip() == to_unit.strip():
        return 1.0, 0.0
    source = from_unit if isinstance(from_unit, UnitDefinition) else parse_unit(from_unit, from_definitions)
    target = to_unit if isinstance(to_unit, UnitDefinition) else parse_unit(to_unit, to_definitions)
    if source.exponents != target.exponents:
        raise IncompatibleUnits(f"'{source.name}' ({source.dimension()}) and '{target.name}' "
                                f"({target.dimension()}) measure different quantities")
    if source.factor == target.factor and source.offset == target.offset:
        return 1.0, 0.0
    factor = source.factor / target.factor
    offset = (source.offset - target.offset) / target.factor
    return factor, offset


def fmi_unit_definitions(model_description: Any) -> dict[str, UnitDefinition]:
    """The ``<UnitDefinitions>`` of an FMU (fmpy's model description), by unit name.

    A unit declared without ``<BaseUnit>`` is left out, so its name is read
    with the unit syntax instead.
    """
    out: dict[str, UnitDefinition] = {}
    for unit in getattr(model_description, "unitDefinitions", None) or ():
        base = getattr(unit, "baseUnit", None)
        if unit.name and base is not None:
            out[unit.name] = UnitDefinition(unit.name, tuple(int(getattr(base, b, 0) or 0) for b in BASE_UNITS),
                                            float(base.factor if base.factor is not None else 1.0),
                                            float(base.offset if base.offset is not None else 0.0))
    return out
