"""What each unit of a system *is*, as a checksum of its content, so a resume cannot mix two models.

A sweep stores these checksums in ``metadata.json``; ``--resume`` compares
them with the units as they are now (:func:`changed_units`).  The same spec
text can name different models: an FMU file re-exported in place, an edited
``file.py`` unit, a replaced player table.

Covered: an FMU's bytes; a Python unit's source file (``file.py`` or the
file of ``package.module``; modules it imports in turn are not covered); a
player's table.
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path
from typing import Any, Mapping


def _file_digest(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def unit_file(unit_type: Any) -> Path | None:
    """The file whose content defines a unit, or None when there is none to hash."""
    from .units.fmu import FmuUnitType
    from .units.player import PlayerUnitType
    from .units.python import PythonUnitType

    if isinstance(unit_type, FmuUnitType):
        return Path(unit_type.path)
    if isinstance(unit_type, PythonUnitType):
        module = sys.modules.get(unit_type.load_class().__module__)
        origin = getattr(module, "__file__", None)
        return Path(origin) if origin else None
    if isinstance(unit_type, PlayerUnitType):
        path = getattr(unit_type, "path", None)
        return Path(path) if path else None
    return None


def unit_checksums(system: Any) -> dict[str, str]:
    """Unit name -> SHA-256 of the file that defines it (units without such a file are left out)."""
    from .units.fmu import FmuUnitType

    sums = {}
    for name, system_unit in system.units.items():
        if isinstance(system_unit.unit_type, FmuUnitType):
            sums[name] = system_unit.unit_type.digest  # hashed once, shared with the payload
            continue
        path = unit_file(system_unit.unit_type)
        if path is not None and path.is_file():
            sums[name] = _file_digest(path)
    return sums


def changed_units(stored: Mapping[str, str], current: Mapping[str, str]) -> list[str]:
    """Lines naming each unit whose checksum differs (units in only one of the two count as changed)."""
    lines = []
    for name in sorted(set(stored) | set(current)):
        before, now = stored.get(name), current.get(name)
        if before != now:
            lines.append(f"unit '{name}': {(before or 'none')[:12]}… then, {(now or 'none')[:12]}… now")
    return lines
