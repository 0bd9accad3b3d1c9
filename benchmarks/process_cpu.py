"""CPU time of the commands a benchmark starts, with every process they start (Linux; elsewhere as before).

``getrusage(RUSAGE_CHILDREN)`` counts a child once it has been waited for, and its own children through it.
A process that outlives its parent is counted by whoever reaps it: a process the command leaves behind (in
session 3 the multiprocessing fork server that forked the local cluster's worker processes; the local
cluster's workers now run inside the command) would be missed with all its children. So the benchmark
becomes a *subreaper* (``prctl(PR_SET_CHILD_SUBREAPER)``): such orphans become its children, and
:func:`reap_orphans` waits for them before the CPU time is read.
"""

from __future__ import annotations

import ctypes
import os
import sys
import time

PR_SET_CHILD_SUBREAPER = 36


def become_subreaper() -> bool:
    """Make this process the reaper of its orphaned descendants; False where that is not possible."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        return ctypes.CDLL(None, use_errno=True).prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def reap_orphans(wait: float = 5.0) -> None:
    """Wait (up to ``wait`` seconds) for the orphans handed to this process; returns when none is left."""
    end = time.monotonic() + wait
    while time.monotonic() < end:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return  # no child left
        if pid == 0:
            time.sleep(0.02)
