"""Files a Python unit reads, found from its parameters so they travel with the unit.

A :class:`~cosim.units.python.unit.PythonUnit` declares in ``data_files``
the String parameters whose values are paths of files it reads (a plant
description, a URDF, a table)::

    class Planner(PythonUnit):
        variables = (Variable("plant_file", "parameter", type="String", start=""), ...)
        data_files = ("plant_file",)

:func:`attach` (run when a :class:`~cosim.system.builder.System` is built)
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

A value may also name a **folder** (a URDF with its meshes): it travels as a
whole, as one zip whose name is the digest of the folder's content
(:func:`pack`, :func:`cosim.util.digest.path_digest`), unpacked on the
worker into a folder of the same name (:func:`unpack`), so relative paths
inside it keep working.  A data file or folder may hold at most the
``data_mb`` limit (``COSIM_DATA_MB``): it is sent with every sweep's payload;
a bigger one is a SpecError naming it and the fix.
"""

from __future__ import annotations

import os
import tempfile
import zipfile
from pathlib import Path
from typing import Any, Iterator

from cosim.util.digest import folder_files, path_digest


def attach(system: Any) -> None:
    """Fill ``data_paths`` (and ``data_folders``) of every Python unit type of ``system`` declaring ``data_files``.

    Raises SpecError naming each data file or folder above the ``data_mb`` limit.
    """
    from cosim.errors import SpecError

    problems = []
    for name, system_unit in system.units.items():
        unit_type = system_unit.unit_type
        if not hasattr(unit_type, "data_paths"):  # a Python unit's type (PythonUnitType) has them; no other
            continue
        declared = set(unit_type.load_class().data_files)
        if not declared:
            continue
        paths = {}
        for value in sorted(set(_values(system, name, declared))):
            found = _resolve(value, system.spec.folder)
            if found is not None:
                paths[value] = found
                problems += _size_problems(system.spec.path, name, value, Path(found))
        unit_type.data_paths = paths
        unit_type.data_folders = {value for value, path in paths.items() if Path(path).is_dir()}
    if problems:
        raise SpecError(problems)


def _size_problems(spec_path: str, unit: str, value: str, path: Path) -> list[Any]:
    """A Problem when the file or folder ``path`` holds more than the ``data_mb`` limit (none otherwise)."""
    from cosim.errors import Problem
    from cosim.util.limits import limit, raise_hint

    files = list(folder_files(path)) if path.is_dir() else [path]
    size = sum(f.stat().st_size for f in files)
    most = limit("data_mb")
    if size <= most * 1e6:
        return []
    what = f"the folder {path} ({len(files)} files)" if path.is_dir() else f"the file {path}"
    return [Problem(spec_path, f"$.units.{unit}", f"data file value '{value}' names {what} of {size / 1e6:.1f} MB, "
                    f"more than the {most:g} MB a data file or folder may hold (it travels with every sweep)",
                    f"name a smaller file or folder (only what the unit reads), or {raise_hint('data_mb')}")]


def _values(system: Any, unit: str, declared: set[str]) -> Iterator[str]:
    """Every string the declared parameters of ``unit`` may hold in this study."""
    from cosim.errors import SpecError

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
    """The absolute path of the file or folder ``value`` names (relative: in ``folder``), or None when none."""
    if not value:
        return None
    path = Path(value).expanduser()
    if not path.is_absolute():
        path = Path(folder) / path
    return str(path.resolve()) if path.is_file() or path.is_dir() else None


def pack(folder: str | Path) -> Path:
    """A zip of ``folder``'s files, named after the digest of its content; made once per content.

    The same content gives the same bytes (sorted members, fixed dates), so
    a sweep's payload key and resume stay stable.
    """
    folder = Path(folder)
    target = Path(tempfile.gettempdir()) / "cosim_data" / f"{folder.name}_{path_digest(folder)[:16]}.zip"
    if not target.is_file():
        target.parent.mkdir(parents=True, exist_ok=True)
        partial = target.with_suffix(f".{os.getpid()}.part")
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as archive:
            for file in folder_files(folder):
                info = zipfile.ZipInfo(file.relative_to(folder).as_posix(), date_time=(1980, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                with open(file, "rb") as source, archive.open(info, "w") as member:
                    while chunk := source.read(1 << 20):
                        member.write(chunk)
        partial.replace(target)
    return target


def unpack(archive: str | Path, name: str) -> Path:
    """Unpack a zip made by :func:`pack` into the folder ``name`` beside it (on a worker); returns that folder."""
    target = Path(archive).parent / name
    with zipfile.ZipFile(archive) as zipped:
        zipped.extractall(target)  # our own archive, made by pack() on the client
    return target
