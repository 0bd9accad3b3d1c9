"""The one task function every cosim study sends to Dask workers: :func:`run_batch` runs a batch of points.

It runs on a worker (or anywhere): the child process holding a system (:mod:`cosim.parallel.isolation`) is kept
for the next batch of the same payload.  A scheduler must be able to import this module to unpickle cosim's
tasks (:mod:`cosim.parallel.cluster.scheduler_check`).
"""

from __future__ import annotations

import os
import pickle
import socket
import threading
from typing import TYPE_CHECKING, Any, Sequence

from cosim.execution.point_row import PointRow
from cosim.parallel.isolation.runner import IsolatedRunner

if TYPE_CHECKING:  # types only: distributed is imported on a worker, when a task runs there
    from dask.typing import Key
    from distributed import Worker

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
    messages, see :data:`cosim.parallel.cluster.local.LOG_LENGTH`): 2048 trivial
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
            assert self._pickled is not None  # one of the two is always kept
            self._points, self._pickled = pickle.loads(self._pickled), None
        return self._points

    def __reduce__(self) -> tuple[Any, tuple[bytes]]:
        pickled = self._pickled if self._pickled is not None else pickle.dumps(list(self.points), protocol=5)
        return _point_batch, (pickled,)


def _point_batch(pickled: bytes) -> PointBatch:
    """A PointBatch from its pickled points (unpickled when first read)."""
    batch = PointBatch(())
    batch._points, batch._pickled = None, pickled
    return batch


def run_batch(payload: dict[str, Any], points: PointBatch | Sequence[tuple[str, dict[str, Any]]],
              timeout: float | None, rows_topic: str | None = None, prune: Any = None) -> list[PointRow]:
    """Run ``points`` on this worker; one row per point (see IsolatedRunner.run), with the worker named.

    Runs on a Dask worker (or anywhere): the child process holding the system
    is kept for the next batch of the same payload.  ``rows_topic``: the rows
    of finished points are also sent to the client on that Dask event topic
    while the batch runs (:class:`RowSender`; :mod:`cosim.parallel.point_stream`).
    ``prune``: a :class:`~cosim.execution.prune.PruneOrder` (the study's front) each point compares its bound
    with while it runs (:mod:`cosim.studies.pruning`).
    Once a stop of this process began (:func:`cosim.parallel.isolation.children.kill_point_children_now`)
    the rows of points the stop cut short are left out: the result holds only finished points.
    """
    from cosim.parallel.dashboard.points import BatchProgress

    if isinstance(points, PointBatch):
        points = points.points
    name = _worker_name()
    progress = BatchProgress()  # the points page of the dashboard counts points as they finish
    sender = RowSender(rows_topic, name)

    def finished(row: PointRow) -> None:
        progress.row(row)
        sender.row(row)

    with _IDLE_LOCK:
        idle = _IDLE.pop(payload["key"], [])
        runner = idle.pop() if idle else IsolatedRunner(payload)
        _IDLE[payload["key"]] = idle  # most recently used last
        while len(_IDLE) > _MAX_PAYLOADS:  # a long-lived worker must not pile up children of old sweeps
            for old in _IDLE.pop(next(iter(_IDLE))):
                old.close()
    try:
        rows = runner.run(points, timeout, on_row=finished, prune=prune)
        cut = runner.cut_by_stop  # read before the runner goes back: another task may take it at once
    finally:
        with _IDLE_LOCK:
            _IDLE.setdefault(payload["key"], []).append(runner)
        sender.close()
        progress.close()
    return [row.on_worker(name) for row in rows if row.point_id not in cut]


ROWS_EVERY = 0.25  # seconds a finished point's row may wait on the worker, to go with the rows after it


class RowSender:
    """Sends the rows of a running task's finished points to the client as Dask events (``Worker.log_event``).

    The first row after a quiet spell is sent ROWS_EVERY seconds later, with
    every row finished meanwhile, in one event ``{"key": task key, "rows":
    pickled rows}``: a task of cheap points sends few events, a slow point's
    row is on its way within ROWS_EVERY seconds.  Rows still waiting when the
    task ends are not sent: its result brings every row.  Without a topic, or
    outside a Dask worker, it does nothing.

    A Dask scheduler keeps the recent events of each topic, as many as its
    configuration says (recent distributed: ``low-level-log-length``, which
    is ``cluster.local.LOG_LENGTH`` on the clusters cosim starts), so the rows of a
    study's last events stay in its memory until pushed out.
    A task of cheap points (about half a second, see ``BatchSizer``) sends one
    or two events; one of slow points one per point.
    """

    def __init__(self, topic: str | None, worker_name: str):
        self._worker: Worker | None = None
        self._key: Key | None = None
        if topic:
            try:
                from distributed import get_worker

                self._worker = get_worker()
                self._key = self._worker.get_current_task()
            except (ImportError, ValueError):  # not on a worker
                self._worker = None
        self.topic, self.worker_name = topic, worker_name
        self._pending: list[PointRow] = []
        self._lock = threading.Lock()
        self._closed = False

    def row(self, row: PointRow) -> None:
        """A point finished with ``row`` (called from the task's thread)."""
        if self._worker is None:
            return
        with self._lock:
            if self._closed:
                return
            first = not self._pending
            self._pending.append(row.on_worker(self.worker_name))
        if first:  # from the worker's event loop, which goes on while the task's thread runs the next point
            loop = self._worker.loop
            loop.add_callback(loop.call_later, ROWS_EVERY, self._flush)

    def _flush(self) -> None:
        with self._lock:
            rows, self._pending = self._pending, []
            if self._closed or not rows:
                return
        worker, topic = self._worker, self.topic
        if worker is None or topic is None:  # never: a worker is kept only with a topic, and row() needs one
            return
        try:
            worker.log_event(topic, {"key": self._key, "rows": pickle.dumps(rows, protocol=5)})
        except Exception:  # a closing worker: the task's result, or its rerun, brings the rows
            pass

    def close(self) -> None:
        """The task ends: rows not yet sent stay for its result."""
        with self._lock:
            self._closed = True
            self._pending = []


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return f"{socket.gethostname()}:{os.getpid()}"
