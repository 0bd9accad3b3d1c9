"""Design points in, one row per point out, on Dask: the pieces every study shares.

``cosim sweep``, ``cosim optimize`` and ``cosim sensitivity`` differ only in
*which* points they ask for and when; they share the cluster set-up, the
payload (system + unit files, scattered once), the task function
(:func:`cosim.parallel.tasks.run_batch`), the per-worker child processes of
:mod:`cosim.parallel.isolation` with their timeouts, the re-runs of lost tasks,
the rule that a fault is a row, never an exception, and one evaluate loop,
:class:`cosim.parallel.point_stream.PointStream`, which hands each point's row
back as soon as that point finishes.  This module holds:

- :func:`dask_client` starts the cluster of a cluster file, connects to a
  running scheduler (given, or from Dask's configuration) or starts a local
  cluster whose workers run in this process (one thread each, 127.0.0.1; each
  runs its points in a child process), and closes what it started (see
  :mod:`cosim.parallel.cluster`).
- :class:`ScatteredPayload`: the payload on the workers, scattered anew when
  the workers holding it all died.
- A task lost with its worker process is run again by the scheduler on
  another worker; the points of a task lost again then run in small groups,
  each alone on the cluster, and the points of a group lost alone one at a
  time, so only a point that kills its workers while alone gets ``crashed``
  (:class:`Reruns`, :func:`lost_rows`) and every other point its true row.
"""

from __future__ import annotations

import collections
import math
import time
from contextlib import contextmanager, nullcontext
from typing import Any, Iterator, Sequence

from cosim.errors import ClusterError, UserError
from cosim.execution.point_row import PointRow


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
    """Whether bokeh is installed (distributed serves its dashboard only with it); found, not imported."""
    import importlib.util

    return importlib.util.find_spec("bokeh") is not None


def _thread_count(client: Any) -> int:
    return sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values())


# Dask keeps the last `distributed.admin.low-level-log-length` messages of every connection, and as many
# transitions and events, for debugging (1000 by default).  A sweep's task messages carry its points, so the
# client, the scheduler cosim runs in its process and the workers would hold the points of the last 1000 tasks
# of every connection: hundreds of MB for a sweep of a million cheap points (2048 a task).  The clients and
# clusters cosim starts keep LOG_LENGTH; the transitions of the last LOG_LENGTH tasks remain for a post-mortem.
LOG_LENGTH = 50


def local_cluster(workers: int) -> Any:
    """The cluster cosim starts when given none: a LocalCluster whose scheduler and ``workers`` workers (one
    thread each) run in this process, its dashboard on a free port of 127.0.0.1, loaded when first opened
    (:mod:`cosim.parallel.dashboard_on_demand`).  The caller closes it.

    Why no worker processes: a point never runs in a Dask worker, it runs in
    the worker's child process (:mod:`cosim.parallel.isolation`), which is what
    isolates a crashing or hanging unit, enforces timeouts and memory limits.
    On this machine a worker only hands points to its child and rows back, so
    a worker process would be a relay that costs a process start, the imports
    of Dask and a serialisation of every task both ways (together about 0.4 s
    of the README's main job of 2 s).  Clusters on other machines (a cluster
    file, a scheduler address) keep their worker processes.
    """
    import dask
    from distributed import LocalCluster, Worker

    from cosim.parallel.cluster import ALLOWED_FAILURES
    from cosim.parallel.dashboard_on_demand import serve_dashboard_on_demand

    with dask.config.set({"distributed.scheduler.allowed-failures": ALLOWED_FAILURES,
                          "distributed.admin.low-level-log-length": LOG_LENGTH}):
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=False,
                               dashboard_address="127.0.0.1:0", worker_dashboard_address="127.0.0.1:0",
                               worker_class=_worker_without_pages(Worker), silence_logs=40,
                               scheduler_kwargs={"dashboard": False})  # loaded when first opened, below
    try:
        if _dashboard_available():
            serve_dashboard_on_demand(cluster)
    except BaseException:
        cluster.close()
        raise
    return cluster


def _worker_without_pages(worker: type) -> type:
    """Dask's Worker, its web server (health, metrics) on the address given but without its own bokeh pages.

    The workers cosim starts run in the client's process (local_cluster):
    their pages would import bokeh there at every start (0.25 s); the
    scheduler's dashboard shows the workers anyway.  (LocalCluster turns the
    pages on whenever it is given the address the server should listen on.)
    """
    class LocalWorker(worker):
        def __init__(self, *args: Any, **kwargs: Any):
            super().__init__(*args, **{**kwargs, "dashboard": False})

    return LocalWorker


@contextmanager
def dask_client(workers: int, scheduler: str | None = None, cluster_file: str | None = None,
                early: Any = None) -> Iterator[tuple[Any, int, str]]:
    """Yields ``(client, worker threads, dashboard link)``; closes the client and any cluster it started.

    ``cluster_file`` (a path, see :mod:`cosim.parallel.cluster`) comes first,
    then ``scheduler``, then Dask's configured scheduler address; without any
    a ``LocalCluster`` of ``workers`` processes is started, or taken from
    ``early`` (an :class:`~cosim.parallel.early_cluster.EarlyCluster` started
    before, which the caller closes if it is not used here).  Raises
    ClusterError when the scheduler cannot be reached or has no workers within
    60 s (a cluster file's jobs: 10 min), ClusterFileError for a bad cluster file.
    Meanwhile the dashboard's web server logs its errors without tracebacks
    (:mod:`cosim.parallel.dashboard`), and Dask keeps LOG_LENGTH recent
    messages of each connection (see LOG_LENGTH).
    """
    import dask

    from cosim.parallel.dashboard import web_server_tracebacks_as_lines
    from cosim.parallel.interrupts import processes_started_here_get_the_preload

    # the workers a cluster file's scale/adapt starts at any time of the study ignore Ctrl-C as the first ones
    preload = processes_started_here_get_the_preload() if cluster_file is not None else nullcontext()
    # LOG_LENGTH for the client's connections, and for the scheduler and workers of a cluster started here
    with dask.config.set({"distributed.admin.low-level-log-length": LOG_LENGTH}), web_server_tracebacks_as_lines(), \
            preload:
        yield from _client(workers, scheduler, cluster_file, early)


def _client(workers: int, scheduler: str | None, cluster_file: str | None,
            early: Any) -> Iterator[tuple[Any, int, str]]:
    from distributed import Client

    from cosim.parallel.cluster import configured_scheduler, read_cluster_file, start_cluster

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
        cluster = early.take() if early is not None else local_cluster(workers)
        client = Client(cluster)
        # not cluster.dashboard_link: that names the machine's address, the server listens on 127.0.0.1 only
        link = (f"http://127.0.0.1:{cluster.scheduler.http_server.port}/status" if dashboard
                else "unavailable (install bokeh to get it)")
        if dashboard:
            # Imported before the link is printed: the page's callbacks (bokeh, in Dask's IO-loop thread) import
            # pandas once a tab is open, and racing this thread's own first import of it (when the first rows
            # come) handed them a partially initialised module (an AttributeError traceback on the terminal).
            import pandas  # noqa: F401
    else:
        try:
            client = Client(scheduler, timeout=10)
        except OSError as exc:
            raise ClusterError(f"cannot reach the Dask scheduler at {scheduler}{origin}: {exc}") from None
        except (MemoryError, ValueError, TypeError, KeyError, IndexError) as exc:
            # a server that is no Dask scheduler (ssh, smtp, http speak first): its first bytes, read as the
            # length of a Dask frame, asked for exabytes ("Unable to allocate 3.01 EiB"), or would not decode
            raise ClusterError(f"the server at {scheduler}{origin} is not a Dask scheduler: it did not answer in "
                               f"Dask's protocol ({type(exc).__name__}: {str(exc)[:100]}); check the address and "
                               "port (a scheduler listens on 8786 unless told otherwise)") from None
        link = client.dashboard_link
    stopped = False  # by Ctrl-C or a stop signal (KeyboardInterrupt, see cosim.parallel.interrupts)
    try:
        if cluster_file is not None or scheduler is not None:  # a scheduler of another environment
            _check_scheduler_imports_cosim(client, f"{scheduler}{origin}")
        n_workers = _thread_count(client)
        if n_workers == 0:
            try:
                client.wait_for_workers(1, timeout=wait)
            except TimeoutError:
                raise ClusterError(f"the scheduler at {scheduler} has no workers (waited {wait} s); {hint}") from None
            n_workers = _thread_count(client)
        yield client, n_workers, link
    except KeyboardInterrupt:
        stopped = True
        raise
    finally:
        _close(client, cluster, stopped)


# How long closing a cluster after a stop may wait for each of its processes to answer.  A terminal's Ctrl-C
# also reaches the processes a cluster file's class started here, and some close themselves on it (a
# SubprocessCluster's `dask spec` scheduler installs its own SIGINT handler): closing then waited Dask's connect
# timeout (30 s) per attempt to reach a process that was gone, 30-40 s after the user's Ctrl-C.
CLOSE_AFTER_STOP_CONNECT = "1s"


def _close(client: Any, cluster: Any, stopped: bool) -> None:
    """Close ``client`` and ``cluster`` (None: a scheduler cosim did not start); after a stop, without waiting
    long for processes that the signal already ended."""
    import dask

    from cosim.parallel.interrupts import scheduler_gone

    settings = {"distributed.comm.timeouts.connect": CLOSE_AFTER_STOP_CONNECT} if stopped else {}
    with dask.config.set(settings):
        at_once = stopped and cluster is not None and (scheduler_gone(client) or _scheduler_in_own_process(cluster))
        client.close()
        if at_once and _end_processes(cluster):
            # Dask's exit hook would try the orderly close, through the scheduler that is gone, for 10 s
            cluster.shutdown_on_close = False
        elif cluster is not None:
            try:
                cluster.close()
            except OSError:  # its processes are already gone (a kill reached them): nothing left to close
                # (TimeoutError is an OSError.)  Dask's exit hook would try closing it again, for another 10 s
                cluster.shutdown_on_close = False
        if stopped and cluster is not None:
            _end_resource_tracker()


def _end_resource_tracker(timeout: float = 2.0) -> None:
    """End multiprocessing's resource tracker of this process, waiting up to ``timeout`` s for it to exit.

    The worker processes of a cluster started here (a LocalCluster's nannies spawn them) started it; it ends
    when the last process holding its pipe is gone, i.e. just after cosim itself, so after a stop it was the
    one process of cosim's that outlived it (still running when the shell's prompt came back; seen on a loaded
    machine).  Closing our end of the pipe, as multiprocessing's own ``_stop`` does, ends it now.  Uses the
    tracker's private fields (CPython 3.11-3.13); does nothing where they differ.
    """
    import os
    from multiprocessing import resource_tracker

    tracker = getattr(resource_tracker, "_resource_tracker", None)
    fd, pid = getattr(tracker, "_fd", None), getattr(tracker, "_pid", None)
    if not isinstance(fd, int) or not isinstance(pid, int):
        return  # never started here, or not the layout known
    try:
        os.close(fd)
    except OSError:
        return
    tracker._fd = None  # a later process started through multiprocessing starts a new tracker
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            ended, _ = os.waitpid(pid, os.WNOHANG)
        except ChildProcessError:
            ended = pid  # already reaped
        if ended:
            tracker._pid = None
            return
        time.sleep(0.01)


def _scheduler_in_own_process(cluster: Any) -> bool:
    """Whether ``cluster`` is a SpecCluster whose scheduler runs in a process of its own (a SubprocessCluster's
    ``dask spec``), not in this one (LocalCluster, dask-jobqueue's clusters)."""
    from distributed import Scheduler, SpecCluster

    return isinstance(cluster, SpecCluster) and not isinstance(getattr(cluster, "scheduler", None), Scheduler)


def _end_processes(cluster: Any) -> bool:
    """After a stop, end the processes of ``cluster`` at once; False if it is no SpecCluster (nothing done).

    For a cluster whose scheduler the stop signal ended, or whose scheduler
    runs in a process of its own (:func:`_scheduler_in_own_process`).  An
    orderly close (``cluster.close()``) retires the workers through the
    scheduler: with the scheduler gone it waited a connect timeout per attempt,
    and the workers' nannies went on for 2-4 s more and logged their closing
    on the terminal after cosim's last line; with the scheduler there, the
    nannies still log their closing.  A SpecCluster ends each of its processes
    itself (a SubprocessCluster's: SIGKILL to the process and its children).
    Only unfinished points die with them: the rows of the finished ones were
    collected before (PointStream).
    """
    import asyncio

    from distributed import SpecCluster

    if not isinstance(cluster, SpecCluster):
        return False

    async def close_each() -> None:
        processes = [*cluster.workers.values(), cluster.scheduler]
        await asyncio.gather(*(p.close() for p in processes if p is not None), return_exceptions=True)

    try:
        cluster.sync(close_each, callback_timeout=5)
    except Exception:  # what is left ends by itself (it got the signal too)
        pass
    return True


def _check_scheduler_imports_cosim(client: Any, where: str) -> None:
    """Raise ClusterError when the scheduler cannot import cosim (it could run none of the tasks)."""
    from cosim.parallel.scheduler_check import scheduler_import_problem

    problem = scheduler_import_problem(client)
    if problem:
        raise ClusterError(f"the Dask scheduler at {where} cannot import cosim ({problem}); Dask's scheduler "
                           "unpickles every task, so it needs the modules the tasks name: install cosim (the "
                           "version of this client) where the scheduler runs")


SCATTER_TRIES = 5  # sending the payload to the workers, when workers die meanwhile
WORKER_WAIT = 120.0  # seconds to wait for a worker when all died (a loaded machine restarts them slowly)


def worker_died(exc: BaseException) -> bool:
    """Whether a task failed because every worker process that ran it died (Dask's KilledWorker).

    The scheduler has then already run it again elsewhere (``allowed-failures``
    times, 1 on the clusters cosim starts).
    """
    from distributed import KilledWorker

    return isinstance(exc, KilledWorker)


RERUN_GROUP = 64  # points of a lost task rerun together, alone on the cluster, before any is run by itself


class Reruns:
    """Where the points of a task that failed with its workers go next.

    Dask counts a worker's death against *every* task the scheduler had sent
    to that worker (:attr:`TaskState.suspicious`), also tasks only waiting
    there behind the one running, so a KilledWorker says "this task was on
    workers that died", not "this task killed them"; and when the workers
    that died held the last copies of the scattered payload, the tasks using
    it are cancelled instead.  Blame is therefore only given to a point that
    ran *alone*: the points of a task lost either way become ``suspects``,
    one point each (a task of more than RERUN_GROUP points: groups of
    RERUN_GROUP); the driver stops submitting new work, lets the tasks in
    flight finish, then runs the suspects one task at a time, with nothing
    else on the cluster (the scheduler still re-runs such a task
    ``allowed-failures`` times).  A group lost while it runs alone holds a
    point that kills its workers: its points become suspects of one point
    each.  A single point whose task is lost while it runs alone is the
    one that kills its workers: it gets ``crashed`` (:func:`lost_rows`); every
    other suspect gets its true row.

    Why groups: a sweep's task may hold thousands of cheap points
    (:class:`cosim.parallel.point_stream.BatchSizer`); rerun one per task, one task at
    a time, they would cost a scheduler round trip each (a minute or more
    for a lost worker), where a group costs one.  The group holding the
    killer costs one more round of worker deaths.
    """

    def __init__(self, group: int = RERUN_GROUP) -> None:
        self.group = group
        self.suspects: collections.deque[list[Any]] = collections.deque()  # each entry: one task's points

    def after_failure(self, points: Sequence[Any], exc: BaseException, alone: bool) -> bool:
        """True when ``points`` became suspects (run again later, alone); False: they get :func:`lost_rows`."""
        from concurrent.futures import CancelledError

        if not (worker_died(exc) or isinstance(exc, CancelledError)):
            return False  # the task could not run at all (e.g. unpicklable arguments): a row
        if not alone:
            size = self.group if len(points) > self.group else 1  # a task of at most `group` points: one by one
            self.suspects.extend(list(points[i:i + size]) for i in range(0, len(points), size))
            return True
        if len(points) > 1:  # one of them kills its workers: find it, one point at a time
            self.suspects.extend([point] for point in points)
            return True
        return False  # lost while alone: this point kills its workers


class ScatteredPayload:
    """The payload scattered to every worker; scattered anew when the workers holding it are all gone.

    Scattered data lives only on workers: when every worker that held it
    dies (a cluster of two both killed, a lost node), its tasks are cancelled.
    """

    def __init__(self, client: Any, payload: dict[str, Any]):
        self.client, self.payload, self._future = client, payload, None

    def future(self) -> Any:
        """The payload's future; scattered anew if it is lost (the workers holding it all died).

        The payload is lost when every worker holding it died, and then there
        may be no worker for a while (their nannies restart them): it waits up
        to WORKER_WAIT seconds for one, then raises ClusterError.  A worker that dies while the payload
        is being sent to it fails the scatter (CommClosedError, an OSError, or
        a ValueError from the broadcast): it is tried again, at most
        SCATTER_TRIES times.
        """
        if self._future is None or not _alive(self._future):
            for attempt in range(SCATTER_TRIES):
                try:
                    self._wait_for_a_worker()
                    self._future = self.client.scatter(self.payload, broadcast=True, hash=False)
                    break
                # OSError, also TimeoutError: "No valid workers found" when the last one just died; ValueError: "Can
                # not use replicate to delete data" when the workers changed while the payload was sent to them all
                except (OSError, ValueError):
                    if attempt == SCATTER_TRIES - 1:
                        raise
                    time.sleep(1.0)  # the scheduler removes the dead worker meanwhile
        return self._future

    def release(self) -> None:
        """Let go of the scattered payload; call it before the client closes.

        A future still alive when the interpreter exits is released by its
        ``__del__`` after the modules are torn down, which distributed 2024.1
        (the declared floor) reports as "Exception ignored in Future.__del__"
        tracebacks; a released future's ``__del__`` does nothing.
        """
        release_futures(self._future.values() if isinstance(self._future, dict) else [self._future])
        self._future = None

    def _wait_for_a_worker(self) -> None:
        """Raises ClusterError when no worker is there within WORKER_WAIT seconds (all died, none came back)."""
        try:
            self.client.wait_for_workers(1, timeout=WORKER_WAIT)
        except TimeoutError:
            raise ClusterError(f"every Dask worker died and none came back within {WORKER_WAIT:g} s (a Dask nanny "
                               "does not restart a worker killed while it starts); the rows so far are kept: start "
                               "workers, or run again with --resume (or resume=True from Python)") from None


def release_futures(futures: Any) -> None:
    """Release every future of ``futures`` (None entries skipped); see :meth:`ScatteredPayload.release`."""
    for future in futures:
        if future is not None:
            future.release()


def _alive(scattered: Any) -> bool:
    """Whether every future of a scattered object (a dict is scattered value by value) still holds its data."""
    futures = scattered.values() if isinstance(scattered, dict) else [scattered]
    return all(f.status == "finished" for f in futures)


def lost_rows(point_ids: Sequence[str], exc: BaseException, alone: bool = False) -> list[PointRow]:
    """``crashed`` rows for points whose task failed with its workers (``alone``: see :class:`Reruns`)."""
    from concurrent.futures import CancelledError

    if alone and (worker_died(exc) or isinstance(exc, CancelledError)):
        # A cancelled task here means the workers holding its scattered data all died while it ran alone.
        cause = (f"Dask: {exc}" if worker_died(exc) else
                 f"its workers died and took the task's data with them; Dask: {type(exc).__name__}: {exc}")
        message = ("every Dask worker process that ran this point died, also while it ran alone on the cluster "
                   f"(the point kills them, e.g. by using up the memory); {cause}")
    else:
        message = f"the task running this point failed: {type(exc).__name__}: {exc}"
    return [PointRow(pid, "crashed", message) for pid in point_ids]  # run time unknown (NaN), no worker
