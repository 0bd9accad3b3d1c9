"""Python's cyclic garbage collector paused while a large, acyclic structure is built.

Checking a spec with 10^5 connections makes millions of small objects (signals, element references,
problems) that form no reference cycles.  CPython's collector still walks the whole heap every time the
objects made since its last full pass reach a quarter of those that survived it: about a dozen full passes
over millions of objects, a quarter of the check's time (10^5 connections: 5.5 s of CPU with the collector,
3.9 s without; benchmarks/hostile_bounds.md).  Reference counting frees everything as usual meanwhile;
only cycles wait until the collector runs again.
"""

from __future__ import annotations

import gc
from contextlib import contextmanager
from typing import Iterator


@contextmanager
def collector_paused() -> Iterator[None]:
    """Pause the cyclic collector in the ``with`` block (nested blocks too); it runs again as before after it,
    also when the block raises.  A collector already off stays off."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()
