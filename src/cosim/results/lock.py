"""One sweep at a time per results folder.

Two ``cosim sweep`` processes writing into the same ``--out`` would both
compute every point.  :class:`FolderLock` is an advisory lock on
``DIR/.cosim.lock`` (``fcntl.flock``): the operating system releases it when
its process ends in any way, kill -9 included, so a killed sweep never leaves
a folder locked.  The file names the holder (pid, host, start time) for the
message the second sweep prints.  On network filesystems without ``flock``
support the lock may not hold across machines.

The holder removes the file when it releases the lock, so a finished study leaves no ``.cosim.lock`` in its
folder (a killed one leaves it, unlocked; the next study takes it over).  Removing a locked file invites a
race: another process may have opened the file just before it was removed and lock it after, while a third
creates a new file under the name and locks that.  So a lock counts only when the name still refers to the
very file locked; otherwise :meth:`FolderLock.acquire` tries again with the file now under the name.
"""

from __future__ import annotations

import fcntl
import json
import os
import socket
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from cosim.errors import FolderInUse

LOCK_NAME = ".cosim.lock"


class FolderLock:
    """The lock of results folder ``folder`` (created when missing)."""

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)
        self.path = self.folder / LOCK_NAME
        self._fd: int | None = None

    def acquire(self, what: str = "cosim sweep") -> None:
        """Take the lock, or raise FolderInUse naming the process that holds it."""
        if self._fd is not None:
            return
        self.folder.mkdir(parents=True, exist_ok=True)
        while True:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _describe(_read(fd))
                os.close(fd)
                raise FolderInUse(f"{self.folder} is in use by another {holder}; wait for it to finish, or choose "
                                  "another results folder (a killed sweep releases the folder at once)",
                                  file=str(self.folder)) from None
            except OSError:
                os.close(fd)
                raise
            if _same_file(fd, self.path):
                break
            os.close(fd)  # its holder removed it meanwhile (see the module docstring): lock the file there now
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps({"what": what, "pid": os.getpid(), "host": socket.gethostname(),
                                  "started": datetime.now(timezone.utc).isoformat(timespec="seconds")}).encode(), 0)
        self._fd = fd

    def check_free(self) -> None:
        """Raise FolderInUse when another process holds the lock (without keeping it)."""
        if self._fd is not None or not self.path.exists():
            return
        self.acquire()
        self.release()

    def release(self) -> None:
        """Remove the lock file (while still holding it) and release the lock; nothing when not held."""
        if self._fd is not None:
            fd, self._fd = self._fd, None
            try:
                if _same_file(fd, self.path):
                    self.path.unlink()
            except OSError:  # a read-only or vanished folder: the lock is released all the same
                pass
            try:
                fcntl.flock(fd, fcntl.LOCK_UN)
            finally:
                os.close(fd)

    def __del__(self) -> None:
        self.release()


def _same_file(fd: int, path: Path) -> bool:
    """Whether ``path`` is (still) the file open as ``fd``."""
    try:
        here, there = os.fstat(fd), os.stat(path)
    except FileNotFoundError:
        return False
    return (here.st_dev, here.st_ino) == (there.st_dev, there.st_ino)


def _read(fd: int) -> dict[str, Any]:
    try:
        return json.loads(os.pread(fd, 4096, 0).decode() or "{}")
    except (OSError, ValueError):
        return {}


def _describe(holder: dict[str, Any]) -> str:
    what = holder.get("what", "cosim process")
    if "pid" not in holder:
        return what
    return f"{what} (pid {holder['pid']} on {holder.get('host', '?')}, started {holder.get('started', '?')})"
