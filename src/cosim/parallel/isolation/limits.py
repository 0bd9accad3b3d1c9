"""What a point child may hold: a cap on its data memory, and when it ends itself for a fresh one.

A child caps its own data memory (``COSIM_CHILD_MEMORY_MB``: an allocation beyond it fails the point, not the
machine) and ends itself after ``COSIM_CHILD_POINTS`` points or once it holds more than ``COSIM_CHILD_RSS_MB``
resident (a leaking unit); the parent then starts a fresh one for the rest of the batch.
"""

from __future__ import annotations

import os

from cosim.util.limits import limit


def limit_memory(size: int) -> None:
    """Cap this process's data memory (RLIMIT_DATA: heap and private mappings) at ``size`` bytes.

    A unit that allocates beyond it gets MemoryError (Python) or a failed
    malloc (native code) in this child instead of starving the machine.
    """
    try:
        import resource

        soft, hard = resource.getrlimit(resource.RLIMIT_DATA)
        if hard == resource.RLIM_INFINITY or size < hard:
            resource.setrlimit(resource.RLIMIT_DATA, (size, hard))
    except (ImportError, ValueError, OSError):
        pass  # not on this platform: the recycling below still bounds a leak


def resident_bytes() -> int:
    """This process's resident memory now (Linux /proc; 0 where unavailable)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


def recycle_reason(served: int) -> str | None:
    """Why this child should be replaced after ``served`` points, or None."""
    if served >= limit("child_points"):
        return f"ran {served} points (COSIM_CHILD_POINTS)"
    resident = resident_bytes()
    if resident > int(limit("child_rss_mb")) << 20:
        return f"holds {resident >> 20} MB (COSIM_CHILD_RSS_MB)"
    return None
