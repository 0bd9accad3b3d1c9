"""Ctrl-C and ``kill`` stop cosim quietly: one line on stderr, exit 130, no tracebacks from any process.

A terminal's Ctrl-C sends SIGINT to the whole process group: the ``cosim``
client (with the workers of its local cluster, which run inside it), the
point children, and the worker processes a cluster file starts on this
machine.  Only the client decides what happens (it stops the sweep, keeps
the rows written so far and says ``cosim: interrupted``):

- :func:`stop_cleanly_on_signals` (called by ``cosim``'s ``main``) turns
  SIGINT, SIGTERM and SIGHUP into KeyboardInterrupt in the client and, once a stop has
  begun, hushes what Dask logs while its half-stopped workers go down.
- :func:`dask_setup` is a Dask *preload*: every worker process a cluster
  file starts here runs it at start-up and ignores SIGINT from then on, so it neither
  prints a traceback nor dies before the client closes it.  The worker
  process ignores it itself; nothing it does not own (the nanny, the client's
  own handler while workers are restarted after a loss) is changed.
- :func:`processes_started_here_ignore_ctrl_c` does the same for the
  processes a cluster file's class starts on this machine.
- Point children (:mod:`cosim.parallel.isolation`) ignore SIGINT themselves.
- :func:`scheduler_gone` tells the client, after a stop, that the signal ended
  the scheduler too (a cluster file's ``dask spec`` processes close themselves on
  SIGINT), so that it neither sends to it nor waits for it.
"""

from __future__ import annotations

import signal
import sys
import threading
from contextlib import contextmanager
from typing import Any, Iterator

WORKER_PRELOAD = __name__  # the module name given to Dask's ``preload`` for the workers cosim starts


def stop_cleanly_on_signals() -> dict[int, Any]:
    """Make SIGINT, SIGTERM and SIGHUP raise KeyboardInterrupt in the main thread, and quiet Dask after a stop.

    SIGHUP (the terminal or ssh session closed, a job scheduler's hang-up) stops a study like SIGTERM:
    unhandled, it killed the client at once, before it could say where the rows are.

    Returns the handlers it replaced, for :func:`restore_signals`.  Does
    nothing outside the main thread (signal handlers can only be set there).
    """
    def stop(signum: int, frame: Any) -> None:
        import logging

        for name in ("distributed", "asyncio"):  # asyncio reports tasks of workers that never started
            logging.getLogger(name).setLevel(logging.CRITICAL + 1)
        sys.unraisablehook = lambda unraisable: None
        from cosim.parallel.isolation import kill_point_children_now

        kill_point_children_now()  # their points are unfinished: waiting for them could take minutes
        raise KeyboardInterrupt

    if threading.current_thread() is not threading.main_thread():
        return {}
    stopping = [signal.SIGTERM, signal.SIGINT] + ([signal.SIGHUP] if hasattr(signal, "SIGHUP") else [])
    return {signum: signal.signal(signum, stop) for signum in stopping}


def scheduler_gone(client: Any) -> bool:
    """True when ``client`` has lost its scheduler: nothing sent to it would arrive, nothing would answer.

    A SubprocessCluster's ``dask spec`` scheduler installs its own SIGINT
    handler and closes itself on the terminal's Ctrl-C, whatever cosim set
    before starting it; its client then reconnects (status ``connecting``)
    in vain.  Waiting for it (the points page's end message, an orderly
    close of the cluster through it) cost seconds after the user's Ctrl-C.
    """
    return getattr(client, "status", "running") != "running"


def restore_signals(previous: dict[int, Any]) -> None:
    """Put back the handlers :func:`stop_cleanly_on_signals` replaced (and let point children start again)."""
    for signum, handler in previous.items():
        signal.signal(signum, handler)
    if previous:
        from cosim.parallel.isolation import allow_point_children

        allow_point_children()


@contextmanager
def processes_started_here_ignore_ctrl_c() -> Iterator[None]:
    """Processes started within the block (a cluster class's scheduler, nannies, workers) ignore SIGINT.

    A terminal's Ctrl-C reaches cosim's whole process group, also the
    processes a cluster file's class starts on this machine (a LocalCluster's
    workers, a SubprocessCluster's scheduler): they must not print tracebacks
    or die before the client closes them.  SIGINT is ignored in this process
    while the block runs, so processes started meanwhile inherit that (an
    ignored signal stays ignored across exec, and Python then keeps it so),
    and workers a nanny starts later get the :func:`dask_setup` preload
    through Dask's ``distributed.worker.preload`` setting.  A Ctrl-C while the
    block runs is lost (cluster classes start quickly; their jobs start
    later).  Outside the main thread only the preload is set.
    """
    import dask

    preloads = [*dask.config.get("distributed.worker.preload", []), WORKER_PRELOAD]
    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
    try:
        with dask.config.set({"distributed.worker.preload": preloads}):
            yield
    finally:
        if main:
            signal.signal(signal.SIGINT, previous)


def dask_setup(worker: Any) -> None:
    """Dask preload hook, run in each worker process at start-up: ignore Ctrl-C (the client handles it).

    A worker process runs its event loop, and so this hook, in its main
    thread, where a signal handler may be set; elsewhere it does nothing.
    """
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
