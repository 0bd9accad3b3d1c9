"""One evaluator for every driver: design points in, one row per point out, on Dask.

``cosim sweep``, ``cosim optimize`` and ``cosim sensitivity`` differ only in
*which* points they ask for and when; all of them evaluate points here, so
they share the cluster set-up, the payload (system + unit files, scattered
once), the per-worker child processes of :mod:`orchestrator.isolation` with
their timeouts, and the rule that a fault is a row, never an exception:

- :func:`dask_client` starts the cluster of a cluster file, connects to a
  running scheduler (given, or from Dask's configuration) or starts a local
  cluster of worker processes (one thread each, 127.0.0.1), and closes what
  it started (see :mod:`orchestrator.cluster`).
- :class:`Evaluator` runs a list of points on that client in parallel and
  returns one row per point in the order given (``evaluate``).
- A task lost with its worker process is run again by the scheduler on
  another worker; a batch lost twice is split and its points run one per task,
  so only a point that kills its workers gets ``crashed`` (:func:`lost_rows`)
  and every other point its true row.
"""

from __future__ import annotations

import math
from contextlib import contextmanager
from typing import Any, Iterator, Sequence

from .errors import UserError


class ClusterError(UserError):
    """No Dask workers can be had (scheduler unreachable or without workers)."""


def check_timeout(timeout: float | None, error: type[UserError] = UserError) -> None:
    """Refuse a per-point timeout that is not a positive, finite number of seconds (None: the default timeout).

    Every driver (sweep, optimize, sensitivity) checks its ``timeout`` here
    before any work.  Raises ``error`` (a UserError, so exit code 2): NaN,
    infinity, zero or a negative number would make every point ``crashed`` or
    never stop a hanging one.
    """
    if timeout is not None and not (isinstance(timeout, (int, float)) and math.isfinite(timeout) and timeout > 0):
        raise error(f"the timeout must be a positive number of seconds, got {timeout}")


def _dashboard_available() -> bool:
    try:
        import bokeh  # noqa: F401  (distributed serves its dashboard only with bokeh)
    except ImportError:
        return False
    return True


def _thread_count(client: Any) -> int:
    return sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values())


@contextmanager
def dask_client(workers: int, scheduler: str | None = None,
                cluster_file: str | None = None) -> Iterator[tuple[Any, int, str]]:
    """Yields ``(client, worker threads, dashboard link)``; closes the client and any cluster it started.

    ``cluster_file`` (a path, see :mod:`orchestrator.cluster`) comes first,
    then ``scheduler``, then Dask's configured scheduler address; without any
    a ``LocalCluster`` of ``workers`` processes is started.  Raises
    ClusterError when the scheduler cannot be reached or has no workers within
    60 s (a cluster file's jobs: 10 min), ClusterFileError for a bad cluster file.
    """
    import dask
    from distributed import Client, LocalCluster

    from .cluster import ALLOWED_FAILURES, configured_scheduler, read_cluster_file, start_cluster
    from .interrupts import WORKER_PRELOAD

    cluster = None
    wait, hint, origin = 60, "start some with: dask worker ADDRESS --nthreads 1", ""
    if scheduler is None and cluster_file is None and (scheduler := configured_scheduler()) is not None:
        origin = "DASK_SCHEDULER_ADDRESS (or Dask's scheduler-address setting)"
        hint = f"start workers, or unset {origin} to use a local cluster"
        origin = f" (from {origin})"
    if cluster_file is not None:
        config = read_cluster_file(cluster_file)  # checked before anything starts
        cluster = start_cluster(config)
        try:
            client = Client(cluster)
        except BaseException:
            cluster.close()
            raise
        link = cluster.dashboard_link if _dashboard_available() else "unavailable (install bokeh to get it)"
        scheduler = f"{cluster.scheduler_address} ({config.type} of {cluster_file})"
        wait, hint = 600, f"check that the jobs of {config.type} start (its scale/adapt and job system)"
    elif scheduler is None:
        dashboard = _dashboard_available()
        with dask.config.set({"distributed.scheduler.allowed-failures": ALLOWED_FAILURES}):
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                                   dashboard_address="127.0.0.1:0", silence_logs=40,
                                   preload=[WORKER_PRELOAD])  # the workers ignore a terminal's Ctrl-C
        client = Client(cluster)
        link = cluster.dashboard_link if dashboard else "unavailable (install bokeh to get it)"
    else:
        try:
            client = Client(scheduler, timeout=10)
        except OSError as exc:
            raise ClusterError(f"cannot reach the Dask scheduler at {scheduler}{origin}: {exc}") from None
        link = client.dashboard_link
    try:
        n_workers = _thread_count(client)
        if n_workers == 0:
            try:
                client.wait_for_workers(1, timeout=wait)
            except TimeoutError:
                raise ClusterError(f"the scheduler at {scheduler} has no workers (waited {wait} s); {hint}") from None
            n_workers = _thread_count(client)
        yield client, n_workers, link
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


MAX_RERUNS = 3  # times the points of one failed task are submitted again before they get ``crashed`` rows


def worker_died(exc: BaseException) -> bool:
    """Whether a task failed because every worker process that ran it died (Dask's KilledWorker).

    The scheduler has then already run it again elsewhere (``allowed-failures``
    times, 1 on the clusters cosim starts).
    """
    from distributed import KilledWorker

    return isinstance(exc, KilledWorker)


def rerun(points: Sequence[Any], exc: BaseException, attempt: int) -> list[list[Any]] | None:
    """The point lists to submit again after a task of ``points`` failed with ``exc``, or None: give up.

    - Its worker processes died (KilledWorker) and the task held several
      points: each point runs again on its own, so only a point that kills its
      workers itself ends ``crashed``, never the innocent points of its batch.
    - It was cancelled because the scattered payload died with the last
      worker holding it: the same points run again (with the payload scattered
      anew, see :class:`ScatteredPayload`).

    ``attempt`` counts the reruns so far; after MAX_RERUNS, None.
    """
    from concurrent.futures import CancelledError

    if attempt >= MAX_RERUNS:
        return None
    if worker_died(exc) and len(points) > 1:
        return [[point] for point in points]
    if isinstance(exc, CancelledError):
        return [list(points)]
    return None


class ScatteredPayload:
    """The payload scattered to every worker; scattered anew when the workers holding it are all gone.

    Scattered data lives only on workers: when every worker that held it
    dies (a cluster of two both killed, a lost node), its tasks are cancelled.
    """

    def __init__(self, client: Any, payload: dict[str, Any]):
        self.client, self.payload, self._future = client, payload, None

    def future(self, stale: Any = None) -> Any:
        """The payload's future; scattered anew if it is lost or is ``stale`` (a task using it was cancelled)."""
        if self._future is None or self._future is stale or not _alive(self._future):
            self._future = self.client.scatter(self.payload, broadcast=True, hash=False)
        return self._future


def _alive(scattered: Any) -> bool:
    """Whether every future of a scattered object (a dict is scattered value by value) still holds its data."""
    futures = scattered.values() if isinstance(scattered, dict) else [scattered]
    return all(f.status == "finished" for f in futures)


def lost_rows(point_ids: Sequence[str], exc: BaseException) -> list[dict[str, Any]]:
    """Rows for points whose task died with its worker process (KilledWorker) or broke on the way."""
    from concurrent.futures import CancelledError

    if worker_died(exc) or isinstance(exc, CancelledError):
        # A cancelled task here means the workers holding its scattered data all died (see rerun): when a
        # point kills every worker that runs it, Dask may report the last try as cancelled, not KilledWorker.
        cause = (f"Dask: {exc}" if worker_died(exc) else
                 f"its workers died and took the task's data with them; Dask: {type(exc).__name__}: {exc}")
        message = ("every Dask worker process that ran this point died (most likely the point kills it, e.g. "
                   f"by using up the memory); {cause}")
    else:
        message = f"lost with its worker: {type(exc).__name__}: {exc}"
    return [{"point_id": pid, "status": "crashed", "message": message,
             "run_time": float("nan"), "worker": "", "objectives": {}} for pid in point_ids]


class Evaluator:
    """Evaluates batches of points on ``client`` (see the module docstring).

    ``payload`` is :func:`orchestrator.isolation.make_payload` of the system;
    it is scattered to the workers once.  ``timeout`` is the seconds one point
    may run before its child process is killed (row status ``timeout``).
    """

    def __init__(self, client: Any, payload: dict[str, Any], n_workers: int, timeout: float | None = None):
        self.client, self.n_workers, self.timeout = client, max(1, n_workers), timeout
        self._payload = ScatteredPayload(client, payload)

    def evaluate(self, points: Sequence[tuple[str, dict[str, Any]]]) -> list[dict[str, Any]]:
        """One row per ``(point_id, values)``, in the order given; never raises for a failing point.

        The points are split into one task per worker, so a batch of K runs
        K / workers points per process.  A row has point_id, status, message,
        run_time, worker and objectives (a flat dict).
        """
        from distributed import wait

        if not points:
            return []
        size = math.ceil(len(points) / self.n_workers)
        chunks = [list(points[i:i + size]) for i in range(0, len(points), size)]
        tasks = [self._submit(chunk) for chunk in chunks]
        wait([future for future, _ in tasks])
        rows: list[dict[str, Any]] = []
        for chunk, task in zip(chunks, tasks):
            rows.extend(self._rows(chunk, task))
        return rows

    def _submit(self, chunk: list[tuple[str, dict[str, Any]]], stale: Any = None) -> tuple[Any, Any]:
        """(task future, payload future it uses)."""
        from .sweep import run_batch

        payload = self._payload.future(stale)
        return self.client.submit(run_batch, payload, chunk, self.timeout, pure=False, retries=0), payload

    def _rows(self, chunk: list[tuple[str, dict[str, Any]]], submitted: tuple[Any, Any],
              attempt: int = 0) -> list[dict[str, Any]]:
        future, payload = submitted
        try:
            return future.result()
        except Exception as exc:  # the worker process itself died, or the task could not run
            again = rerun(chunk, exc, attempt)
            if again is None:
                return lost_rows([pid for pid, _ in chunk], exc)
            tasks = [self._submit(points, stale=payload) for points in again]
            return [row for points, task in zip(again, tasks) for row in self._rows(points, task, attempt + 1)]
        finally:
            future.release()
