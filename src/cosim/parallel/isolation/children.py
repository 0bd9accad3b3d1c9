"""The point children of this process, all of them: stopped at exit, killed at once by a stop, spares started early.

Every :class:`~cosim.parallel.isolation.runner.IsolatedRunner` with a live child is in :data:`LIVE`; children
started ahead of their payload wait in :data:`SPARES` (:func:`cosim.parallel.isolation.runner.start_spare_children`).
:func:`kill_point_children_now` (a stop signal) kills them all and sets :data:`STOPPING`, so no runner starts
another until :func:`allow_point_children`.
"""

from __future__ import annotations

import atexit
import threading
from typing import Any

LIVE: set[Any] = set()  # the IsolatedRunners of this process with a child


_kill_children_registered = False


def register_exit_hook() -> None:
    """Stop every child at exit; called at the first child process, not at import: importing cosim leaves no
    exit hook."""
    global _kill_children_registered
    if _kill_children_registered:
        return
    atexit.register(_kill_children)
    _kill_children_registered = True


def _kill_children() -> None:
    stop_spare_children()  # no need to wait for a child that never had work
    runners = list(LIVE)
    for runner in runners:  # all asked first, so they finish (terminate their units) at the same time
        runner.ask_to_finish()
    for runner in runners:
        runner.close()


STOPPING = threading.Event()  # set by a stop signal: runners start no new child and run no further point


def allow_point_children() -> None:
    """Undo :func:`kill_point_children_now`'s stop for this process (a program that goes on after a study)."""
    STOPPING.clear()


def kill_point_children_now() -> None:
    """Kill every point child of this process at once, without waiting (the study is being stopped).

    Called from the client's stop-signal handler: a point may take minutes, and waiting for it
    kept a stopped sweep alive long past a job scheduler's grace period.  The points these
    children were running are not finished, so no row of theirs is lost; the worker threads
    waiting on them see the child gone and return at once.
    """
    STOPPING.set()  # first: a batch's next point must not start a fresh child
    for runner in list(LIVE) + list(SPARES):
        proc = runner._proc
        if proc is not None and proc.poll() is None:
            try:
                proc.kill()
            except OSError:
                pass


SPARES: list[Any] = []  # children started ahead of their payload (start_spare_children)
SPARES_LOCK = threading.Lock()


def preload_spare_children(payload: dict[str, Any]) -> None:
    """Send ``payload`` to the spare children that have none yet: they load it (the units' imports, the unit
    files written out) while this process goes on, and the runners of this payload that take them only wait
    for them to be ready."""
    with SPARES_LOCK:
        for spare in SPARES:
            if spare._loading is None and spare._limits == payload.get("limits", {}):
                try:
                    spare._outbox.send(("load", payload))
                except OSError:
                    continue  # gone: the runner that takes it finds it dead and starts its own
                spare._loading = payload["key"]


def stop_spare_children() -> None:
    """Stop the spare children no runner took (the sweep runs elsewhere after all)."""
    with SPARES_LOCK:
        spares = list(SPARES)
        SPARES.clear()
    for spare in spares:
        spare.close(force=True)
