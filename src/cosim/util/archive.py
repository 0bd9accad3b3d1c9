"""Unpacking zip archives from others (FMUs, SSP files) without trusting them.

An archive can be made to hurt the machine that unpacks it: members whose
names leave the target folder (``../x``, ``/etc/x``), symbolic links and
device or pipe entries, millions of members, or a "zip bomb" whose few
kilobytes expand to gigabytes.  :func:`check_archive` inspects the archive's
table of contents without unpacking anything and :func:`safe_extract`
unpacks it, counting the bytes it actually writes (a table of contents can
lie about sizes).  Both raise :class:`ArchiveError` naming the archive, the
member and the limit, with the way to raise it.

The limits (:class:`ArchiveLimits`) default to the settings of
:mod:`cosim.util.limits` (``COSIM_FMU_UNPACKED_MB``, ``COSIM_FMU_MEMBERS``,
``COSIM_FMU_RATIO``)::

    from cosim.util.archive import ArchiveError, safe_extract
    safe_extract("model.fmu", folder)          # raises ArchiveError
"""

from __future__ import annotations

import atexit
import shutil
import stat
import tempfile
import threading
import zipfile
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Callable

from cosim.errors import ArchiveError, Problem
from cosim.util import limits

RATIO_MIN_BYTES = 1 << 20  # small members may compress extremely well (a file of spaces); only big ones count
_CHUNK = 1 << 20


@dataclass(frozen=True)
class ArchiveLimits:
    """How big an archive may unpack: total bytes, number of members, compression ratio of big members."""

    max_bytes: int
    max_members: int
    max_ratio: float

    @classmethod
    def from_settings(cls) -> "ArchiveLimits":
        """The limits set for FMUs (environment variables, else defaults; see cosim.util.limits)."""
        return cls(max_bytes=int(limits.limit("fmu_unpacked_mb")) * (1 << 20),
                   max_members=int(limits.limit("fmu_members")), max_ratio=float(limits.limit("fmu_ratio")))


def _limit_fix(name: str) -> str:
    return f"use an archive from a source you trust; if you trust this one, {limits.raise_hint(name)}"


def _member_problem(archive: str, info: zipfile.ZipInfo, kind: str) -> Problem | None:
    """Why one member may not be unpacked, or None."""
    name = info.filename
    path = PurePosixPath(name.replace("\\", "/"))
    fix = f"re-export the {kind} with relative member paths inside the archive, regular files only"
    if path.is_absolute() or ".." in path.parts or (len(name) > 1 and name[1] == ":") or "\0" in name:
        return Problem(archive, name, "archive member escapes the extraction folder (absolute path or '..'); "
                       f"refusing to unpack this {kind}", fix)
    mode = info.external_attr >> 16
    if info.create_system == 3 and stat.S_IFMT(mode):  # unix file type present (many writers leave it 0)
        if stat.S_ISLNK(mode):
            return Problem(archive, name, f"archive member is a symbolic link; refusing to unpack this {kind}", fix)
        if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
            return Problem(archive, name, "archive member is a special file (device, pipe or socket); refusing "
                           f"to unpack this {kind}", fix)
    if info.flag_bits & 0x1:
        return Problem(archive, name, f"archive member is encrypted; refusing to unpack this {kind}", fix)
    return None


def check_archive(path: str | Path, limits_: ArchiveLimits | None = None, kind: str = "FMU") -> None:
    """Refuse an archive whose table of contents breaks a rule or a limit (nothing is unpacked).

    ``kind`` names the archive in messages ("FMU", "SSP").  Raises
    ArchiveError listing every problem found, and zipfile.BadZipFile when
    ``path`` is not a zip archive.
    """
    limits_ = limits_ or ArchiveLimits.from_settings()
    archive = str(path)
    problems: list[Problem] = []
    with zipfile.ZipFile(path) as zf:
        members = zf.infolist()
    if len(members) > limits_.max_members:
        problems.append(Problem(archive, "", f"the {kind} has {len(members)} members, more than the limit of "
                                f"{limits_.max_members}", _limit_fix("fmu_members")))
        members = members[: limits_.max_members]
    total = 0
    for info in members:
        problem = _member_problem(archive, info, kind)
        if problem:
            problems.append(problem)
        total += info.file_size
        ratio = info.file_size / max(info.compress_size, 1)
        if info.file_size >= RATIO_MIN_BYTES and ratio > limits_.max_ratio:
            problems.append(Problem(archive, info.filename, f"archive member expands {ratio:.0f} times, more than "
                                    f"the limit of {limits_.max_ratio:g} (a zip bomb?)", _limit_fix("fmu_ratio")))
    if total > limits_.max_bytes:
        problems.append(Problem(archive, "", f"the {kind} unpacks to {_mb(total)}, more than the limit of "
                                f"{_mb(limits_.max_bytes)}", _limit_fix("fmu_unpacked_mb")))
    if problems:
        raise ArchiveError(archive, problems)


def safe_extract(path: str | Path, target: str | Path, limits_: ArchiveLimits | None = None,
                 kind: str = "FMU") -> None:
    """Unpack the archive at ``path`` into the folder ``target`` within the limits.

    Checks the table of contents first (:func:`check_archive`), then unpacks
    regular files and folders only, stopping as soon as the bytes written
    exceed the limit.  On ArchiveError, what was unpacked stays in ``target``
    for the caller to remove.
    """
    limits_ = limits_ or ArchiveLimits.from_settings()
    check_archive(path, limits_, kind)
    target = Path(target).resolve()
    written = 0
    with zipfile.ZipFile(path) as zf:
        for info in zf.infolist():
            destination = (target / info.filename).resolve()
            if destination != target and target not in destination.parents:  # also checked by check_archive
                raise ArchiveError(path, [Problem(str(path), info.filename, "archive member escapes the extraction "
                                                  "folder", f"re-export the {kind} with relative member paths")])
            if info.is_dir():
                destination.mkdir(parents=True, exist_ok=True)
                continue
            destination.parent.mkdir(parents=True, exist_ok=True)
            with zf.open(info) as source, open(destination, "wb") as sink:
                while chunk := source.read(_CHUNK):
                    written += len(chunk)
                    if written > limits_.max_bytes:
                        raise ArchiveError(path, [Problem(str(path), info.filename, f"the {kind} unpacks to more "
                                                          f"than the limit of {_mb(limits_.max_bytes)}",
                                                          _limit_fix("fmu_unpacked_mb"))])
                    sink.write(chunk)


def extract_to_new_folder(path: str | Path, folder: str | Path, limits_: ArchiveLimits | None = None,
                          kind: str = "FMU") -> None:
    """:func:`safe_extract` into ``folder``, removing the folder again when the archive is refused."""
    try:
        safe_extract(path, folder, limits_, kind)
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise


class ExtractionCache:
    """One unpacked copy of each archive per process, removed when the process exits.

    ``extract(path, folder)`` unpacks into a new folder and removes it when
    the archive is refused (default: :func:`extract_to_new_folder`); temporary
    folders are named ``cosim_<prefix>_*``.  The exit hook is registered at
    the first extraction, not at import, so importing cosim leaves no hook.
    """

    def __init__(self, prefix: str, extract: Callable[[str | Path, str], None] = extract_to_new_folder):
        self.prefix, self._extract = prefix, extract
        self._folders: dict[str, str] = {}
        self._lock = threading.Lock()
        self._registered = False

    def folder(self, path: str | Path, key: str) -> str:
        """The folder holding the archive at ``path`` unpacked, for the version ``key`` of it (e.g. a digest).

        Raises what ``extract`` raises (leaving no folder behind) when the archive is refused.
        """
        with self._lock:
            if not self._registered:
                atexit.register(self.clear)
                self._registered = True
            if key not in self._folders:
                folder = tempfile.mkdtemp(prefix=f"cosim_{self.prefix}_")
                self._extract(path, folder)
                self._folders[key] = folder
            return self._folders[key]

    def clear(self) -> None:
        """Remove every folder unpacked so far."""
        with self._lock:
            for folder in self._folders.values():
                shutil.rmtree(folder, ignore_errors=True)
            self._folders.clear()


def _mb(n: int) -> str:
    return f"{n / (1 << 20):.1f} MB"


# Files inside an SSP archive are named "archive.ssp!/resources/model.fmu" wherever a path is expected (a spec
# merged from an SSP names its FMUs so); any layer may resolve such a name, so it lives here.
MEMBER_SEPARATOR = "!/"

# unpacking refuses escaping members, links, special files, zip bombs (safe_extract)
_SSP_EXTRACTIONS = ExtractionCache("ssp", lambda archive, folder: extract_to_new_folder(archive, folder, kind="SSP"))


def extracted_ssp(archive: Path) -> Path:
    """The folder holding the SSP at ``archive`` unpacked (once per process and version of the file)."""
    stat = archive.stat()
    return Path(_SSP_EXTRACTIONS.folder(archive, f"{archive.resolve()}:{stat.st_mtime}:{stat.st_size}"))


def member_file(reference: str) -> Path:
    """The extracted file ``archive.ssp!/member`` refers to (extracting the archive once per process).

    Raises FileNotFoundError when the archive or the member is missing.
    """
    archive, _, member = reference.partition(MEMBER_SEPARATOR)
    archive_path = Path(archive)
    if not archive_path.is_file():
        raise FileNotFoundError(f"SSP archive not found: {archive}")
    folder = extracted_ssp(archive_path)
    path = (folder / member).resolve()
    if folder.resolve() not in path.parents or not path.is_file():
        raise FileNotFoundError(f"'{member}' is not a file of the SSP archive {archive}")
    return path
