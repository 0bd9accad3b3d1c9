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
- :func:`lost_rows` are the rows of points whose task was lost with its
  worker (``crashed``).
"""

from __future__ import annotations

import math
from contextlib import contextmanager
from typing import Any, Iterator, Sequence

from .errors import UserError


class ClusterError(UserError):
    """No Dask workers can be had (scheduler unreachable or without workers)."""


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
                                   dashboard_address="127.0.0.1:0", silence_logs=40)
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


def lost_rows(point_ids: Sequence[str], exc: BaseException) -> list[dict[str, Any]]:
    """Rows for points whose task died with its worker process (KilledWorker) or broke on the way."""
    return [{"point_id": pid, "status": "crashed", "message": f"lost with its worker: {type(exc).__name__}: {exc}",
             "run_time": float("nan"), "worker": "", "objectives": {}} for pid in point_ids]


class Evaluator:
    """Evaluates batches of points on ``client`` (see the module docstring).

    ``payload`` is :func:`orchestrator.isolation.make_payload` of the system;
    it is scattered to the workers once.  ``timeout`` is the seconds one point
    may run before its child process is killed (row status ``timeout``).
    """

    def __init__(self, client: Any, payload: dict[str, Any], n_workers: int, timeout: float | None = None):
        self.client, self.n_workers, self.timeout = client, max(1, n_workers), timeout
        self._payload = client.scatter(payload, broadcast=True, hash=False)

    def evaluate(self, points: Sequence[tuple[str, dict[str, Any]]]) -> list[dict[str, Any]]:
        """One row per ``(point_id, values)``, in the order given; never raises for a failing point.

        The points are split into one task per worker, so a batch of K runs
        K / workers points per process.  A row has point_id, status, message,
        run_time, worker and objectives (a flat dict).
        """
        from distributed import wait

        from .sweep import run_batch

        if not points:
            return []
        size = math.ceil(len(points) / self.n_workers)
        chunks = [list(points[i:i + size]) for i in range(0, len(points), size)]
        futures = [self.client.submit(run_batch, self._payload, chunk, self.timeout, pure=False, retries=0)
                   for chunk in chunks]
        wait(futures)
        rows: list[dict[str, Any]] = []
        for chunk, future in zip(chunks, futures):
            try:
                rows.extend(future.result())
            except Exception as exc:  # the worker process itself died, or the task could not run
                rows.extend(lost_rows([pid for pid, _ in chunk], exc))
            future.release()
        return rows
