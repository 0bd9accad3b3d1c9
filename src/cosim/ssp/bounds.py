"""The size bound of the files an SSP's reading loads whole: ``COSIM_SSP_FILE_MB`` (default 64).

The XML files (.ssd, .ssv, .ssm) become lxml trees of about 13 times their size; a table component's CSV
becomes a pandas table of several times its size, read again by every process that runs it.  A file whose
stated size is over the bound is refused unread; one whose stated size lies (``/proc``) is refused after at
most one byte beyond the bound.  The problem names the file, its size, the limit and how to raise it.
"""

from __future__ import annotations

from pathlib import Path

from cosim.errors import Problem
from cosim.util.limits import limit, raise_hint

_WHAT = "one SSP file (.ssd, .ssv, .ssm, .csv table)"
_CHUNK = 1 << 20


def read_bounded(path: Path, label: str) -> tuple[bytes | None, list[Problem]]:
    """The bytes of an SSP XML file, or None and a problem when it cannot be read or is larger than
    ``COSIM_SSP_FILE_MB``; at most one byte beyond the limit is read (a file's stated size may lie: /proc)."""
    most = _most()
    try:
        size = path.stat().st_size
        data = b""
        if size <= most:  # a bigger file is refused unread; one whose stated size lies, after most + 1 bytes
            with open(path, "rb") as stream:
                data = stream.read(most + 1)
            size = max(size, len(data))
    except OSError as exc:
        return None, [Problem(label, "/", f"cannot read the file: {exc}", "check that the file exists")]
    if size > most:
        return None, [_too_large(label, size, "split the parameter values into several files")]
    return data, []


def table_size_problem(path: Path, label: str) -> Problem | None:
    """A problem when the table file at ``path`` (a table component's CSV) is larger than ``COSIM_SSP_FILE_MB``,
    else None: checked before anything parses it.  Its bytes are counted (not kept) up to one beyond the limit,
    so a file whose stated size lies is bounded too."""
    most = _most()
    try:
        size = path.stat().st_size
        if size <= most:
            counted = 0
            with open(path, "rb") as stream:
                while counted <= most and (chunk := stream.read(min(_CHUNK, most + 1 - counted))):
                    counted += len(chunk)
            size = max(size, counted)
    except OSError as exc:
        return Problem(label, "/", f"cannot read the file: {exc}", "check that the file exists")
    if size > most:
        return _too_large(label, size, "shorten the table (resample it to fewer rows, or split its columns "
                                       "among several table components)")
    return None


def _most() -> int:
    return int(limit("ssp_file_mb") * 1024 * 1024)


def _too_large(label: str, size: int, fix: str) -> Problem:
    return Problem(label, "/", f"the file holds {size / 1024 / 1024:,.1f} MB ({size:,} bytes), above the limit of "
                   f"{limit('ssp_file_mb'):g} MB for {_WHAT}", f"{fix}, or {raise_hint('ssp_file_mb')}")
