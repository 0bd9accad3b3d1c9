"""The one task function every cosim study sends to Dask workers: :func:`run_batch` runs a batch of points.

It runs on a worker (or anywhere): the child process holding a system (:mod:`cosim.parallel.isolation`) is kept
for the next batch of the same payload.  A scheduler must be able to import this module to unpickle cosim's
tasks (:mod:`cosim.parallel.scheduler_check`).
"""

from __future__ import annotations

import os
import pickle
import socket
import threading
from typing import Any, Sequence

from cosim.execution.point_row import PointRow
from cosim.parallel.isolation import IsolatedRunner

_IDLE: dict[str, list[IsolatedRunner]] = {}
_IDLE_LOCK = threading.Lock()
_MAX_PAYLOADS = 2  # idle child processes are kept for at most this many different systems


class PointBatch:
    """The points of one task as one opaque object, pickled as one bytes object.

    Dask walks through the lists, tuples and dicts it is given looking for
    futures; over a list of point tuples that walk costs the client about
    60 µs a point, more than a trivial point's whole run.  Pickled as one
    bytes object, the points stay bytes wherever Dask only passes the task
    on (the scheduler unpickles every task it receives and keeps its recent
    messages, see :data:`cosim.parallel.evaluator.LOG_LENGTH`): 2048 trivial
    points take 72 kB as bytes, 690 kB unpickled, and are one object instead
    of thousands.  They are unpickled when first read, on the worker.
    """

    __slots__ = ("_points", "_pickled")

    def __init__(self, points: Sequence[tuple[str, dict[str, Any]]]):
        self._points: Sequence[tuple[str, dict[str, Any]]] | None = points
        self._pickled: bytes | None = None

    @property
    def points(self) -> Sequence[tuple[str, dict[str, Any]]]:
        if self._points is None:
            self._points, self._pickled = pickle.loads(self._pickled), None
        return self._points

    def __reduce__(self) -> tuple[Any, tuple[bytes]]:
        pickled = self._pickled if self._pickled is not None else pickle.dumps(list(self._points), protocol=5)
        return _point_batch, (pickled,)


def _point_batch(pickled: bytes) -> PointBatch:
    """A PointBatch from its pickled points (unpickled when first read)."""
    batch = PointBatch(())
    batch._points, batch._pickled = None, pickled
    return batch


def run_batch(payload: dict[str, Any], points: PointBatch | Sequence[tuple[str, dict[str, Any]]],
              timeout: float | None) -> list[PointRow]:
    """Run ``points`` on this worker; one row per point (see IsolatedRunner.run), with the worker named.

    Runs on a Dask worker (or anywhere): the child process holding the system
    is kept for the next batch of the same payload.
    """
    from cosim.parallel.dashboard_points import BatchProgress

    if isinstance(points, PointBatch):
        points = points.points
    progress = BatchProgress()  # the points page of the dashboard counts points as they finish
    with _IDLE_LOCK:
        idle = _IDLE.pop(payload["key"], [])
        runner = idle.pop() if idle else IsolatedRunner(payload)
        _IDLE[payload["key"]] = idle  # most recently used last
        while len(_IDLE) > _MAX_PAYLOADS:  # a long-lived worker must not pile up children of old sweeps
            for old in _IDLE.pop(next(iter(_IDLE))):
                old.close()
    try:
        rows = runner.run(points, timeout, on_row=progress.row)
    finally:
        with _IDLE_LOCK:
            _IDLE.setdefault(payload["key"], []).append(runner)
        progress.close()
    name = _worker_name()
    return [row.on_worker(name) for row in rows]


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return f"{socket.gethostname()}:{os.getpid()}"
