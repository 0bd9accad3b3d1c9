"""SHA-256 of a file's bytes or of a folder's content: the one hashing helper behind every checksum cosim keeps.

Used for an FMU's digest (:mod:`cosim.units.fmu.description`), the unit and data
file checksums a resume compares (:mod:`cosim.results.checksums`) and the
content address of a data folder that travels to the workers
(:mod:`cosim.units.python.data_files`).  Files are read in chunks, so a large FMU or
mesh never sits in memory whole.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Iterator

CHUNK = 1 << 20


def file_digest(path: str | Path) -> str:
    """SHA-256 of a file's bytes (hex).  Raises OSError when it cannot be read."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(CHUNK), b""):
            h.update(chunk)
    return h.hexdigest()


def folder_files(folder: str | Path) -> Iterator[Path]:
    """The regular files under ``folder`` (recursively, symbolic links followed), in a fixed (sorted) order."""
    root = Path(folder)
    for path in sorted(root.rglob("*")):
        if path.is_file():
            yield path


def path_digest(path: str | Path) -> str:
    """SHA-256 (hex) of a file's bytes, or of a folder's content: each file's path inside it and its digest.

    Two folders with the same files at the same relative paths have the same
    digest wherever they are; renaming, adding, removing or editing a file
    inside changes it.  Empty sub-folders do not count.  Raises OSError when a
    file cannot be read.
    """
    path = Path(path)
    if not path.is_dir():
        return file_digest(path)
    h = hashlib.sha256(b"folder\0")
    for file in folder_files(path):
        h.update(file.relative_to(path).as_posix().encode() + b"\0" + file_digest(file).encode() + b"\0")
    return h.hexdigest()
