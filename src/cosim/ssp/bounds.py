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
    try:
        size, data = _measured(path, keep=True)
    except OSError as exc:
        return None, [_unreadable(label, exc)]
    if size > _most():
        return None, [_too_large(label, size, "split the parameter values into several files")]
    return data, []


def table_size_problem(path: Path, label: str) -> Problem | None:
    """A problem when the table file at ``path`` (a table component's CSV) is larger than ``COSIM_SSP_FILE_MB``,
    else None: checked before anything parses it.  Its bytes are counted (not kept) up to one beyond the limit,
    so a file whose stated size lies is bounded too."""
    try:
        size, _ = _measured(path, keep=False)
    except OSError as exc:
        return _unreadable(label, exc)
    if size > _most():
        return _too_large(label, size, "shorten the table (resample it to fewer rows, or split its columns "
                                       "among several table components)")
    return None


def _measured(path: Path, keep: bool) -> tuple[int, bytes]:
    """The size of the file at ``path`` and, when ``keep``, its bytes: a file whose stated size is over the limit
    is not opened; otherwise it is read (counted in chunks when not kept) up to one byte beyond the limit, since
    its stated size may lie, so the size is the larger of the stated and the counted one.  Raises OSError when
    it cannot be read."""
    most = _most()
    size = path.stat().st_size
    data = b""
    if size <= most:
        with open(path, "rb") as stream:
            if keep:  # one read: the bytes are held once, never as chunks and their join
                data = stream.read(most + 1)
                counted = len(data)
            else:
                counted = 0
                while counted <= most and (chunk := stream.read(min(_CHUNK, most + 1 - counted))):
                    counted += len(chunk)
        size = max(size, counted)
    return size, data


def _unreadable(label: str, exc: OSError) -> Problem:
    return Problem(label, "/", f"cannot read the file: {exc}", "check that the file exists")


def _most() -> int:
    return int(limit("ssp_file_mb") * 1024 * 1024)


def _too_large(label: str, size: int, fix: str) -> Problem:
    return Problem(label, "/", f"the file holds {size / 1024 / 1024:,.1f} MB ({size:,} bytes), above the limit of "
                   f"{limit('ssp_file_mb'):g} MB for {_WHAT}", f"{fix}, or {raise_hint('ssp_file_mb')}")
