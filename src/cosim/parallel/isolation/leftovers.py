"""The ``cosim_worker_*`` folders a killed cosim left in TMPDIR, removed at the next start: only ours.

Each worker process makes a ``cosim_worker_*`` folder per point child (:mod:`.isolation`) and removes it when
the child ends; a ``kill -9`` of the whole process group leaves them behind (issue 38.8).  Each folder gets a
marker naming its owner (process id and start time); the first child a process starts removes the folders
whose marker names an owner that is gone.  A folder is never removed when it

- has no marker, or one that does not read as ours (another program's folder of the same name);
- belongs to another user, or is a symbolic link (nothing is followed);
- names an owner that still runs (the same process id with the same start time: a reused id is not it).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

PREFIX = "cosim_worker_"
MARKER = ".cosim-worker-owner"


def start_time(pid: int) -> str:
    """The start time of process ``pid`` (clock ticks since boot, from /proc), '' where unknown."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return ""
    fields = stat[stat.rfind(")") + 2:].split()  # after the command name, which may hold spaces
    return fields[19] if len(fields) > 19 else ""


def mark(folder: str | Path) -> None:
    """Write the marker naming this process as ``folder``'s owner."""
    pid = os.getpid()
    (Path(folder) / MARKER).write_text(f"cosim worker folder of {pid} {start_time(pid)}\n")


def _owner(folder: Path) -> tuple[int, str] | None:
    """(pid, start time) of ``folder``'s marker; None when it has none that reads as ours."""
    try:
        with open(folder / MARKER, "rb") as f:
            words = f.read(200).decode("ascii").split()
    except (OSError, UnicodeDecodeError):
        return None
    if len(words) not in (5, 6) or words[:4] != ["cosim", "worker", "folder", "of"] or not words[4].isdigit():
        return None
    return int(words[4]), words[5] if len(words) == 6 else ""


def _running(pid: int, started: str) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process holds the id: not our owner any more, but leave it be
        return True
    return not started or start_time(pid) in ("", started)


def remove_leftovers(where: str | Path | None = None) -> list[Path]:
    """Remove the ``cosim_worker_*`` folders in ``where`` (default: the temporary folder) whose owner is gone
    (module docstring); returns those removed."""
    removed = []
    uid = os.getuid()
    for folder in Path(where or tempfile.gettempdir()).glob(PREFIX + "*"):
        try:
            st = folder.lstat()
        except OSError:
            continue
        if folder.is_symlink() or not folder.is_dir() or st.st_uid != uid:
            continue
        owner = _owner(folder)
        if owner is None or owner[0] == os.getpid() or _running(*owner):
            continue
        shutil.rmtree(folder, ignore_errors=True)
        removed.append(folder)
    return removed
