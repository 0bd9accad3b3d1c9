"""Ctrl-C and ``kill`` stop cosim quietly: one line on stderr, exit 130, no tracebacks from any process.

A terminal's Ctrl-C sends SIGINT to the whole process group: the ``cosim``
client, the local Dask worker processes and their point children.  Only the
client decides what happens (it stops the sweep, keeps the rows written so
far and says ``cosim: interrupted``):

- :func:`stop_cleanly_on_signals` (called by ``cosim``'s ``main``) turns
  SIGINT and SIGTERM into KeyboardInterrupt in the client and, once a stop has
  begun, hushes what Dask logs while its half-stopped workers go down.
- :func:`dask_setup` is a Dask *preload*: every local worker process cosim
  starts runs it at start-up and ignores SIGINT from then on, so it neither
  prints a traceback nor dies before the client closes it.  The worker
  process ignores it itself; nothing it does not own (the nanny, the client's
  own handler while workers are restarted after a loss) is changed.
- Point children (:mod:`orchestrator.isolation`) ignore SIGINT themselves.
"""

from __future__ import annotations

import signal
import sys
import threading
from typing import Any

WORKER_PRELOAD = __name__  # the module name given to Dask's ``preload`` for the workers cosim starts


def stop_cleanly_on_signals() -> None:
    """Make SIGINT and SIGTERM raise KeyboardInterrupt in the main thread, and quiet Dask after a stop.

    Does nothing outside the main thread (signal handlers can only be set there).
    """
    def stop(signum: int, frame: Any) -> None:
        import logging

        for name in ("distributed", "asyncio"):  # asyncio reports tasks of workers that never started
            logging.getLogger(name).setLevel(logging.CRITICAL + 1)
        sys.unraisablehook = lambda unraisable: None
        raise KeyboardInterrupt

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, stop)
        signal.signal(signal.SIGINT, stop)


def dask_setup(worker: Any) -> None:
    """Dask preload hook, run in each worker process at start-up: ignore Ctrl-C (the client handles it).

    A worker process runs its event loop, and so this hook, in its main
    thread, where a signal handler may be set; elsewhere it does nothing.
    """
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
