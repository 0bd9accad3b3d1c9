"""Ctrl-C and ``kill`` stop cosim quietly: one line on stderr, exit 130, no tracebacks from any process.

A terminal's Ctrl-C sends SIGINT to the whole process group: the ``cosim``
client (with the workers of its local cluster, which run inside it), the
point children, and the worker processes a cluster file starts on this
machine.  Only the client decides what happens (it stops the sweep, keeps
the rows written so far and says ``cosim: interrupted``):

- :func:`stop_cleanly_on_signals` (called by ``cosim``'s ``main``) turns
  SIGINT, SIGTERM and SIGHUP into KeyboardInterrupt in the client and, once a stop has
  begun, hushes what Dask logs while its half-stopped workers go down.
- :func:`dask_setup` is a Dask *preload*: every scheduler, nanny and worker
  process a cluster file starts here runs it at start-up and ignores SIGINT
  from then on, so it neither prints a traceback nor closes itself (a
  SubprocessCluster's ``dask spec`` processes install their own SIGINT
  handler, which closed them, their scheduler first, so that rows still on
  their way to the client were lost) before the client closes it.  Each
  process ignores it itself; nothing it does not own (the client's own handler
  while workers are restarted after a loss) is changed.
- :func:`processes_started_here_ignore_ctrl_c` does the same for the
  processes a cluster file's class starts on this machine, and
  :func:`processes_started_here_get_the_preload` for those its scale/adapt
  starts later, as long as the cluster lives.
- Point children (:mod:`cosim.parallel.isolation.runner`) ignore SIGINT themselves.
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

WORKER_PRELOAD = __name__  # the module name given to Dask's ``preload`` for the processes cosim starts
# Dask's preload settings, as the environment variables through which processes started here read them: a
# `dask spec` process (SubprocessCluster) reads its configuration from its environment, not from this process
# The signals of the stops begun in this command (stop_cleanly_on_signals).  The handler raises KeyboardInterrupt
# wherever the main thread is, also inside a finaliser (a __del__, a weakref callback, which Python runs during
# any allocation): Python prints and swallows an exception raised there (and a stop hushes that print), so the
# command went on and could end with exit 0 and a study marked complete (issue 38.4: 4 of ~45 early
# SIGTERM/SIGHUP at load 6-10).  What is recorded here is checked where a stop must not be missed.
_STOPS: list[int] = []

PRELOAD_VARIABLES = {"distributed.scheduler.preload": "DASK_DISTRIBUTED__SCHEDULER__PRELOAD",
                     "distributed.nanny.preload": "DASK_DISTRIBUTED__NANNY__PRELOAD",
                     "distributed.worker.preload": "DASK_DISTRIBUTED__WORKER__PRELOAD"}


def stop_cleanly_on_signals() -> dict[int, Any]:
    """Make SIGINT, SIGTERM and SIGHUP raise KeyboardInterrupt in the main thread, and quiet Dask after a stop.

    SIGHUP (the terminal or ssh session closed, a job scheduler's hang-up) stops a study like SIGTERM:
    unhandled, it killed the client at once, before it could say where the rows are.

    Returns the handlers it replaced, for :func:`restore_signals`.  Does
    nothing outside the main thread (signal handlers can only be set there).
    """
    def stop(signum: int, frame: Any) -> None:
        _STOPS.append(signum)  # first: the KeyboardInterrupt below may be swallowed (see _STOPS)
        # Nothing is imported here: the stop may come while a module is half imported (cosim's main() sets this
        # handler before its imports), and importing a module that needs it raised ImportError ("partially
        # initialized module") instead of the stop.  What is not imported yet has nothing to quiet or kill.
        logging = sys.modules.get("logging")
        if logging is not None and hasattr(logging, "getLogger"):
            for name in ("distributed", "asyncio"):  # asyncio reports tasks of workers that never started
                logging.getLogger(name).setLevel(logging.CRITICAL + 1)
        sys.unraisablehook = lambda unraisable: None
        children = sys.modules.get("cosim.parallel.isolation.children")
        if children is not None and hasattr(children, "kill_point_children_now"):
            children.kill_point_children_now()  # their points are unfinished: waiting for them could take minutes
        raise KeyboardInterrupt

    if threading.current_thread() is not threading.main_thread():
        return {}
    _STOPS.clear()  # a new command (main called again in one process: tests, notebooks)
    stopping = [signal.SIGTERM, signal.SIGINT] + ([signal.SIGHUP] if hasattr(signal, "SIGHUP") else [])
    return {signum: signal.signal(signum, stop) for signum in stopping}


def stop_requested() -> int | None:
    """The signal of the first stop begun in this command (SIGINT, SIGTERM or SIGHUP), None when there was none."""
    return _STOPS[0] if _STOPS else None


def raise_if_stopped() -> None:
    """Raise KeyboardInterrupt when a stop has begun, even one whose own KeyboardInterrupt was swallowed.

    Called where going on would misreport a stop: the point stream's loop (no new points after a stop), before
    a study is marked complete, and when a command returns (its exit code)."""
    if _STOPS:
        raise KeyboardInterrupt


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
    _STOPS.clear()  # the command is over: a study run later from Python is not stopped by its signal
    if previous:
        from cosim.parallel.isolation.children import allow_point_children

        allow_point_children()


@contextmanager
def processes_started_here_ignore_ctrl_c() -> Iterator[None]:
    """Processes started within the block (a cluster class's scheduler, nannies, workers) ignore SIGINT.

    A terminal's Ctrl-C reaches cosim's whole process group, also the
    processes a cluster file's class starts on this machine (a LocalCluster's
    workers, a SubprocessCluster's scheduler): they must not print tracebacks
    or die before the client closes them.  SIGINT is ignored in this process
    while the block runs, so processes started meanwhile inherit that (an
    ignored signal stays ignored across exec, and Python then keeps it so);
    processes that set their own SIGINT handler (``dask spec``) ignore it again
    through :func:`processes_started_here_get_the_preload`, which holds while
    the block runs.  A Ctrl-C while the block runs is lost (cluster classes
    start quickly; their jobs start later).  Outside the main thread only the
    preload is set.
    """
    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
    try:
        with processes_started_here_get_the_preload():
            yield
    finally:
        if main:
            signal.signal(signal.SIGINT, previous)


@contextmanager
def processes_started_here_get_the_preload() -> Iterator[None]:
    """Every Dask scheduler, nanny and worker process started here while the block runs runs :func:`dask_setup`.

    For the whole life of a cluster a cluster file starts (cosim.parallel.cluster.client): the workers its
    scale/adapt starts later, after the cluster's class returned, ignore Ctrl-C as the first ones do.
    Processes a nanny of this process starts get it through Dask's ``distributed.worker.preload`` setting
    (a nanny hands its configuration to its worker); processes started as commands (a SubprocessCluster's
    ``dask spec``) through their environment (:data:`PRELOAD_VARIABLES`).  Preloads set before are kept;
    both are put back as they were when the block ends.
    """
    import os

    import dask

    preloads = [*_preloads("distributed.worker.preload"), WORKER_PRELOAD]
    environment = {variable: os.environ.get(variable) for variable in PRELOAD_VARIABLES.values()}
    try:
        for key, variable in PRELOAD_VARIABLES.items():
            os.environ[variable] = repr([*_preloads(key), WORKER_PRELOAD])  # Dask reads it as a Python literal
        with dask.config.set({"distributed.worker.preload": preloads}):
            yield
    finally:
        for variable, value in environment.items():
            if value is None:
                os.environ.pop(variable, None)
            else:
                os.environ[variable] = value


def _preloads(key: str) -> list[str]:
    """The preload modules Dask's setting ``key`` names (a name or a list), cosim's own left out."""
    import dask

    value = dask.config.get(key, None) or []
    return [name for name in ([value] if isinstance(value, str) else list(value)) if name != WORKER_PRELOAD]


def dask_setup(server: Any) -> None:
    """Dask preload hook, run in each scheduler, nanny and worker process cosim starts here, at start-up:
    ignore Ctrl-C (the client handles it).

    Such a process runs its event loop, and so this hook, in its main
    thread, where a signal handler may be set; elsewhere it does nothing.
    It runs after ``dask spec`` installed its own handler, and replaces it.
    """
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
