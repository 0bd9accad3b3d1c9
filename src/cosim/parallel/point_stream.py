"""The one evaluate loop of every study: points in, each point's row back as soon as that point finishes.

``cosim sweep`` (and ``cosim sensitivity``, a sweep of its sample) and ``cosim optimize`` differ in which
points they ask for and when; they all evaluate them through :class:`PointStream`:

- It puts the points into Dask tasks of :func:`cosim.parallel.tasks.run_batch` (a batch each, sized by a
  :class:`BatchSizer` or split evenly over the workers by :class:`EvenBatches`), keeps a bounded number
  in flight, and sends the payload to the workers once (:class:`~cosim.parallel.scattered.ScatteredPayload`).
- A task sends the rows of its finished points to the client while it runs (a Dask event on a topic of
  this stream, at most every ``tasks.ROWS_EVERY`` seconds), so a row reaches the caller within a fraction
  of a second of its point's end, however long the rest of the batch takes; the task's result then
  brings every row of the batch again, and is what counts: a row streamed is only an early copy, each
  point is handed to the caller once.
- A task lost with its workers: the points that already sent their rows keep them; the others are run
  again (:class:`~cosim.parallel.reruns.Reruns`), only a point that kills its workers while it runs
  alone gets ``crashed`` (:func:`~cosim.parallel.reruns.lost_rows`).
- A stop (Ctrl-C, SIGTERM, SIGHUP: KeyboardInterrupt in the main thread, see
  :mod:`cosim.parallel.cluster.interrupts`): the rows still on their way are collected for up to ``GRACE``
  seconds (at once, when the cluster runs in this process: its point children were killed and its
  tasks end at once) and handed to the caller, then the KeyboardInterrupt goes on.  So every point
  that finished before the signal is kept.
- However the loop ends (done, an error, a stop) the futures it holds are released before it returns,
  so none outlives the client (a future collected at interpreter exit prints tracebacks with
  distributed 2024.1).
"""

from __future__ import annotations

import collections
import itertools
import math
import pickle
import queue
import statistics
import time
import uuid
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Iterator, Sequence

from cosim.execution.point_row import PointRow
from cosim.parallel.cluster.interrupts import raise_if_stopped
from cosim.parallel.dashboard.task_keys import payload_key
from cosim.parallel.reruns import Reruns, lost_rows
from cosim.parallel.scattered import ScatteredPayload, release_futures
from cosim.spec.design import Point
from cosim.util import limits

GRACE = 1.0  # seconds a stopped loop waits for the rows of points that finished before the stop
QUIET = 0.1  # ... and for further rows once every task in flight has ended

TIMEOUT_FACTOR = 50  # a point may take this many times the median measured point time (default timeout)


def default_timeout(point_times: Sequence[float]) -> float:
    """The per-point timeout when none is given, from the run times of points measured so far.

    ``TIMEOUT_FACTOR`` times their median, but at least the
    ``timeout_floor_seconds`` limit and at most ``timeout_first_seconds``,
    which is also the timeout until three points have been measured.  So a
    hanging point never hangs a sweep, and a slow model is not cut short.
    """
    first = float(limits.limit("timeout_first_seconds"))
    if len(point_times) < 3:
        return first
    floor = float(limits.limit("timeout_floor_seconds"))
    return min(first, max(floor, TIMEOUT_FACTOR * statistics.median(point_times)))


class BatchSizer:
    """How many points go into the next Dask task (a sweep's sizing).

    The first tasks are small, so the first points spread over every worker
    at once.  Once point times are known, a task gets enough points to last
    about TASK_SECONDS (at most MAX_BATCH): each task costs the scheduler,
    the worker and the client a few milliseconds whatever it holds, so tasks
    of trivial points must hold many.  Near the end tasks shrink again, so
    the workers finish together.  A fixed ``size`` (``--batch-size``) is kept.
    """

    TASK_SECONDS = 0.5
    MAX_BATCH = 2048

    def __init__(self, todo: int, n_workers: int, size: int | None = None):
        self.fixed = size
        self.n_workers = n_workers
        # a quarter of each worker's share at most: the first tasks still spread over every worker, and a task
        # of cheap points stays big enough for the lock-step groups of its child (cosim.execution.lockstep)
        self.first = size or max(1, min(64, math.ceil(todo / (n_workers * 4))))
        self.remaining = todo  # points not yet handed to a task
        self._seconds, self._count = 0.0, 0  # run time of the ok points so far, and how many

    @property
    def point_seconds(self) -> float | None:
        """The mean run time of an ok point so far (None before the first)."""
        return max(self._seconds / self._count, 1e-5) if self._count else None

    def observe(self, rows: Sequence[PointRow]) -> None:
        """Learn the time a point takes from finished rows."""
        for row in rows:
            if row.ok and row.run_time > 0:
                self._seconds += row.run_time
                self._count += 1

    def next(self) -> int:
        """The size of the next task."""
        if self.fixed is not None or self.point_seconds is None:
            size = self.first
        else:
            size = min(self.MAX_BATCH, max(self.first, round(self.TASK_SECONDS / self.point_seconds)))
            size = min(size, max(self.first, math.ceil(self.remaining / (4 * self.n_workers))))
        return max(1, size)

    def take(self, points: Iterator[Point]) -> list[Point]:
        """The next task's points from ``points`` (an empty list at the end)."""
        batch = list(itertools.islice(points, self.next()))
        self.remaining -= len(batch)
        return batch


class EvenBatches:
    """``todo`` points split into one task per worker (an optimiser's batch: all of it runs at once)."""

    def __init__(self, todo: int, n_workers: int):
        self.size = max(1, math.ceil(todo / max(1, n_workers)))

    def observe(self, rows: Sequence[PointRow]) -> None:
        """(Point times do not change the split.)"""

    def take(self, points: Iterator[Point]) -> list[Point]:
        return list(itertools.islice(points, self.size))


@dataclass
class _Task:
    """One task in flight: its points, whether it runs alone on the cluster (see Reruns), the rows it handed over."""

    future: Any
    points: list[Point]
    alone: bool
    handed: dict[str, PointRow] = field(default_factory=dict)  # rows of its points given to the caller, by id


OnRows = Callable[[list[tuple[Point, PointRow]]], None]


class PointStream:
    """Evaluates points on ``client`` and hands each row to the caller as its point finishes (module docstring).

    ``payload`` is :func:`cosim.parallel.isolation.payload.make_payload` of the system, scattered to the workers
    once.  ``timeout``: seconds a point may run before its child is killed (row status ``timeout``); None:
    :func:`default_timeout` of the points measured so far when ``adaptive_timeout``, else the
    ``timeout_first_seconds`` limit.  ``kind`` and ``name`` name the tasks on the dashboard
    (:func:`cosim.parallel.dashboard.task_keys.task_key`); ``board`` (:func:`cosim.parallel.dashboard.points.open_board`)
    counts their points on its page.  Use it as a context manager, or call :meth:`close`: it releases the
    payload and unsubscribes from the rows' topic.
    """

    def __init__(self, client: Any, payload: dict[str, Any], n_workers: int, kind: str, name: str = "",
                 timeout: float | None = None, adaptive_timeout: bool = False, board: Any = None,
                 prune: Any = None):
        """``prune``: None, or a callable giving the :class:`~cosim.execution.prune.PruneOrder` (the current
        front) each batch carries when it is submitted (:mod:`cosim.studies.pruning`)."""
        self.prune = prune
        self.client, self.n_workers = client, max(1, n_workers)
        self.kind, self.name, self.board = kind, name, board
        self.timeout, self.adaptive_timeout = timeout, adaptive_timeout
        self.payload = ScatteredPayload(client, payload, payload_key(kind, name))
        self._times: collections.deque[float] = collections.deque(maxlen=1000)  # recent ok point times
        self._inbox: queue.Queue = queue.Queue()  # ("rows", event message) from the topic, ("done", future)
        self.topic = f"cosim-rows-{uuid.uuid4().hex}"
        client.subscribe_topic(self.topic, lambda event: self._inbox.put(("rows", event[1])))
        self._subscribed = True
        self._in_flight: dict[str, _Task] = {}

    def __enter__(self) -> "PointStream":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        """Release every future this stream holds (tasks and payload) and stop listening for rows."""
        release_futures(task.future for task in self._in_flight.values())
        self._in_flight.clear()
        self.payload.release()
        while True:  # the inbox holds finished futures (released): no reference to them outlives the stream
            try:
                self._inbox.get_nowait()
            except queue.Empty:
                break
        if self._subscribed:
            self._subscribed = False
            try:
                self.client.unsubscribe_topic(self.topic)
            except Exception:  # a client already closing: nothing is sent on that topic any more
                pass

    # -- the loop ----------------------------------------------------------------------------
    def run(self, points: Iterable[Point], sizer: Any, on_rows: OnRows, total: int | None = None) -> None:
        """Evaluate ``points``; ``on_rows`` gets every point once with its row, in the order points finish.

        ``sizer`` (:class:`BatchSizer`, :class:`EvenBatches`) cuts the points into tasks; ``total`` is the
        study's number of points (the dashboard's task names). Never raises for a failing point; raises
        ClusterError when the workers are gone for good, and KeyboardInterrupt on a stop, after handing
        over the rows that were on their way (module docstring).
        """
        self._on_rows = on_rows
        self._handing: list[tuple[Point, PointRow]] = []
        try:
            self._loop(iter(points), sizer, total)
        except KeyboardInterrupt:
            self._rows_in_transit()
            raise
        finally:
            release_futures(task.future for task in self._in_flight.values())  # an error or a stop: none waited for
            self._in_flight.clear()

    def _loop(self, unsubmitted: Iterator[Point], sizer: Any, total: int | None) -> None:
        reruns = Reruns()
        in_flight = self._in_flight

        def submit() -> bool:
            alone = bool(reruns.suspects) or any(t.alone for t in in_flight.values())
            if alone and in_flight:
                return False  # no new work until the suspects have run, each group alone on the cluster
            batch = reruns.suspects.popleft() if alone else sizer.take(unsubmitted)
            if not batch:
                return False
            self._submit(batch, alone, total)
            return True

        def fill() -> None:  # enough to keep every worker busy, few enough to stay small
            while len(in_flight) < 2 * self.n_workers + 1 and submit():
                pass

        fill()
        while in_flight:
            raise_if_stopped()  # a stop whose KeyboardInterrupt a finaliser swallowed (interrupts._STOPS)
            kind, body = self._inbox.get()
            if kind == "rows":
                self._take_streamed(body, sizer)
                continue
            task = in_flight.get(body.key)
            if task is None or task.future is not body:
                continue  # a task released meanwhile
            try:
                rows = body.result()
            except Exception as exc:  # the worker process itself died (KilledWorker) or the task broke
                left = [p for p in task.points if p.id not in task.handed]
                lost = []
                if left and not reruns.after_failure(left, exc, task.alone):  # innocent points are never crashed
                    lost = lost_rows([p.id for p in left], exc, task.alone)
                if self.board is not None and (task.handed or lost):  # the page dropped this task's counts
                    self.board.rows_made_here(body.key, [*task.handed.values(), *lost])
                self._hand(list(zip(left, lost)), sizer, task)
            else:
                self._hand(self._unhanded(task, rows), sizer, task)
            del in_flight[body.key]
            body.release()
            fill()

    def _submit(self, batch: list[Point], alone: bool, total: int | None) -> None:
        from cosim.parallel.dashboard.task_keys import task_key
        from cosim.parallel.tasks import PointBatch, run_batch

        timeout = self.timeout
        if timeout is None and self.adaptive_timeout:
            timeout = default_timeout(self._times)
        key = task_key(self.kind, self.name, [p.index for p in batch], total if total is not None else len(batch),
                       run=self.board.run if self.board is not None else "")  # the dashboard's names
        future = self.client.submit(run_batch, self.payload.future(), PointBatch([(p.id, p.values) for p in batch]),
                                    timeout, self.topic, self.prune() if self.prune is not None else None,
                                    pure=False, retries=0, key=key)
        self._in_flight[future.key] = _Task(future, batch, alone)
        future.add_done_callback(lambda done: self._inbox.put(("done", done)))

    @staticmethod
    def _unhanded(task: _Task, rows: Sequence[PointRow]) -> list[tuple[Point, PointRow]]:
        """The rows among ``rows`` (of ``task``'s points) not yet handed to the caller, with their points."""
        by_id = {p.id: p for p in task.points}
        return [(by_id[r.point_id], r) for r in rows if r.point_id in by_id and r.point_id not in task.handed]

    def _streamed(self, message: Any) -> tuple[_Task | None, list[tuple[Point, PointRow]]]:
        """The task in flight that sent ``message`` (``{"key": task key, "rows": pickled PointRows}``) and its
        rows not yet handed over; (None, []) for a task that has ended (its result brought the rows)."""
        key = message.get("key") if isinstance(message, dict) else None
        task = self._in_flight.get(key) if isinstance(key, str) else None  # task keys are str
        if task is None:
            return None, []
        return task, self._unhanded(task, pickle.loads(message["rows"]))

    def _take_streamed(self, message: Any, sizer: Any) -> None:
        task, fresh = self._streamed(message)
        self._hand(fresh, sizer, task)

    def _hand(self, pairs: list[tuple[Point, PointRow]], sizer: Any, task: _Task | None) -> None:
        """Give rows to the caller; noted as handed once the caller returns (a stop may come meanwhile)."""
        if not pairs:
            return
        self._handing = pairs
        rows = [r for _, r in pairs]
        sizer.observe(rows)
        self._times.extend(r.run_time for r in rows if r.ok)
        self._on_rows(pairs)
        if task is not None:
            task.handed.update((p.id, r) for p, r in pairs)
        self._handing = []

    def _rows_in_transit(self) -> None:
        """After a stop: hand over the rows of points that finished before it and are still on their way.

        The tasks go on where the cluster runs elsewhere: their rows come as events, for up to GRACE
        seconds.  A cluster in this process was stopped with the client (its point children killed, see
        :mod:`cosim.parallel.cluster.interrupts`): its tasks end at once, their results holding the rows of the
        points that finished (only those, see tasks.run_batch), read here; then QUIET seconds more for
        events.  The rows the caller was being given when the stop came are given again (a results store
        keeps a point's latest row; the Evaluator takes each point once).
        """
        pending: dict[str, tuple[Point, PointRow]] = {p.id: (p, r) for p, r in self._handing}
        self._handing = []
        deadline = time.monotonic() + GRACE
        quiet_from = None
        read: set[str] = set()  # tasks whose result was read
        while True:
            now = time.monotonic()
            for key, task in self._in_flight.items():
                if key not in read and task.future.status == "finished":
                    read.add(key)
                    try:
                        rows = task.future.result(timeout=max(0.1, deadline - now))
                    except Exception:  # lost, or not fetched in time: its streamed rows are what there is
                        continue
                    pending.update((p.id, (p, r)) for p, r in self._unhanded(task, rows))
            if quiet_from is None and all(t.future.done() for t in self._in_flight.values()):
                quiet_from = now
            wait = min(deadline, quiet_from + QUIET if quiet_from is not None else deadline) - now
            if wait <= 0:
                break
            try:
                kind, body = self._inbox.get(timeout=min(wait, 0.05))
            except queue.Empty:
                continue
            if kind == "rows":
                pending.update((p.id, (p, r)) for p, r in self._streamed(body)[1])
        if pending:
            self._on_rows(list(pending.values()))


class Evaluator:
    """A list of points in, one row per point out, in the order given (``cosim optimize``'s way).

    A :class:`PointStream` whose tasks are the batch split evenly over the workers, with the given
    ``timeout`` (None: the ``timeout_first_seconds`` limit).  ``study`` names the tasks on the dashboard,
    ``board`` counts them on its page.  :meth:`close` (or ``with``) releases its futures.
    """

    streams_rows = True  # evaluate() takes on_rows (cosim.studies.optimize stores rows as they come)

    def __init__(self, client: Any, payload: dict[str, Any], n_workers: int, timeout: float | None = None,
                 study: str = "", board: Any = None, prune: Any = None):
        self.n_workers = max(1, n_workers)
        self.stream = PointStream(client, payload, n_workers, "optimize", study, timeout=timeout, board=board,
                                  prune=prune)

    def __enter__(self) -> "Evaluator":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        self.stream.close()

    def evaluate(self, points: Sequence[tuple[str, dict[str, Any]]],
                 on_rows: Callable[[list[PointRow]], None] | None = None) -> list[PointRow]:
        """One row per ``(point_id, values)``, in the order given; never raises for a failing point.

        The points are split into one task per worker, so a batch of K runs K / workers points per process.
        Points of a task lost with its workers are run again (:class:`~cosim.parallel.reruns.Reruns`).
        ``on_rows`` gets rows as their points finish (before this returns), e.g. to store them at once.
        """
        if not points:
            return []
        rows: dict[str, PointRow] = {}

        def take(pairs: list[tuple[Point, PointRow]]) -> None:
            fresh = [r for _, r in pairs if r.point_id not in rows]
            if on_rows is not None and fresh:
                on_rows(fresh)
            rows.update((r.point_id, r) for r in fresh)

        batch = [Point(i, pid, values) for i, (pid, values) in enumerate(points)]
        self.stream.run(batch, EvenBatches(len(batch), self.n_workers), take, total=len(batch))
        return [rows[pid] for pid, _ in points]
