"""What each unit of a system *is*, as a checksum of its content, so a resume cannot mix two models.

A sweep stores these checksums in ``metadata.json``; ``--resume`` compares
them with the units as they are now (:func:`changed_units`).  The same spec
text can name different models: an FMU file re-exported in place, an edited
``file.py`` unit, a replaced player table.

Covered: an FMU's bytes; a Python unit's source file (``file.py`` or the
file of ``package.module``; modules it imports in turn are not covered); a
player's table; and every data file (or data folder) a Python unit declares it
reads (:mod:`cosim.units.python.data_files`), stored apart as
``data_file_checksums`` (:func:`data_file_checksums`).  Every driver that
resumes (a sweep, an optimisation) asks :func:`changed_files` what differs.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any, Mapping

from cosim.util.digest import file_digest, path_digest


def unit_file(unit_type: Any) -> Path | None:
    """The file whose content defines a unit, or None when there is none to hash."""
    from cosim.units.fmu.description import FmuUnitType
    from cosim.units.player import PlayerUnitType
    from cosim.units.python.unit import PythonUnitType

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
    from cosim.units.fmu.description import FmuUnitType

    sums = {}
    for name, system_unit in system.units.items():
        if isinstance(system_unit.unit_type, FmuUnitType):
            sums[name] = system_unit.unit_type.digest  # hashed once, shared with the payload
            continue
        path = unit_file(system_unit.unit_type)
        if path is not None and path.is_file():
            sums[name] = file_digest(path)
    return sums


def changed_units(stored: Mapping[str, str], current: Mapping[str, str]) -> list[str]:
    """Lines naming each unit whose checksum differs (units in only one of the two count as changed)."""
    lines = []
    for name in sorted(set(stored) | set(current)):
        before, now = stored.get(name), current.get(name)
        if before != now:
            lines.append(f"unit '{name}': {(before or 'none')[:12]}… then, {(now or 'none')[:12]}… now")
    return lines


def data_file_checksums(system: Any) -> dict[str, dict[str, str]]:
    """Unit name -> {data-file parameter value as the spec writes it -> SHA-256 of the file or folder it names}.

    Only units that declare data files and whose values name existing files
    or folders appear (the unit type's ``data_paths``, filled when the system
    was built).
    """
    sums: dict[str, dict[str, str]] = {}
    for name, system_unit in system.units.items():
        paths = getattr(system_unit.unit_type, "data_paths", None) or {}
        if paths:
            sums[name] = {value: path_digest(path) for value, path in sorted(paths.items())}
    return sums


def changed_data_files(stored: Mapping[str, Mapping[str, str]], current: Mapping[str, Mapping[str, str]],
                       folder: str | Path) -> list[str]:
    """Lines naming each data file whose checksum differs (named in only one of the two: changed too).

    ``folder`` is the spec's folder, against which a relative value is shown
    as the file it names.
    """
    lines = []
    for unit in sorted(set(stored) | set(current)):
        before_unit, now_unit = stored.get(unit, {}), current.get(unit, {})
        for value in sorted(set(before_unit) | set(now_unit)):
            before, now = before_unit.get(value), now_unit.get(value)
            if before != now:
                path = Path(value).expanduser()
                shown = path if path.is_absolute() else Path(folder) / path
                lines.append(f"data file {shown} (unit '{unit}'): {(before or 'none')[:12]}… then, "
                             f"{(now or 'missing')[:12]}… now")
    return lines


def changed_files(previous: Mapping[str, Any], units: Mapping[str, str],
                  data_files: Mapping[str, Mapping[str, str]], folder: str | Path) -> list[str]:
    """What differs between a results folder's metadata (``previous``) and the units and data files now.

    ``units`` and ``data_files`` are :func:`unit_checksums` and
    :func:`data_file_checksums` of the system now.  Folders written before
    these checksums existed are compared on what they recorded: only the
    FMUs (``fmu_checksums``), no data files.
    """
    stored = previous.get("unit_checksums")
    if stored is None:  # folders written before unit checksums: FMUs only
        stored = previous.get("fmu_checksums", {})
        units = {k: v for k, v in units.items() if k in stored}
    lines = changed_units(stored, units)
    stored_data = previous.get("data_file_checksums")
    if stored_data is not None:
        lines += changed_data_files(stored_data, data_files, folder)
    return lines
