"""A Dask client on the cluster a study chose (:mod:`cosim.parallel.cluster.choice`), closed with it.

:func:`dask_client` starts the cluster of a cluster file, connects to a running scheduler (given, or from
Dask's configuration) or starts a local cluster whose workers run in this process (one thread each,
127.0.0.1; each runs its points in a child process), and closes what it started
(:mod:`cosim.parallel.cluster.closing`).
"""

from __future__ import annotations

from contextlib import contextmanager, nullcontext
from typing import Any, Iterator

from cosim.errors import ClusterError
from cosim.parallel.cluster.choice import CONFIGURED, ClusterChoice
from cosim.parallel.cluster.local import LOG_LENGTH


def _thread_count(client: Any) -> int:
    return sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values())


@contextmanager
def dask_client(choice: ClusterChoice, early: Any = None) -> Iterator[tuple[Any, int, str]]:
    """Yields ``(client, worker threads, dashboard link)`` on the cluster ``choice`` names; closes the client
    and any cluster it started.

    A local cluster is started, or taken from ``early`` (an :class:`~cosim.parallel.cluster.early.EarlyCluster`
    started before, which the caller closes if it is not used here).  Raises ClusterError when the scheduler
    cannot be reached or has no workers within 60 s (a cluster file's jobs: 10 min), ClusterFileError when the
    cluster of a cluster file cannot be started.  Meanwhile the dashboard's web server logs its errors without
    tracebacks (:mod:`cosim.parallel.dashboard.web_server`), and Dask keeps LOG_LENGTH recent messages of each
    connection (see :data:`cosim.parallel.cluster.local.LOG_LENGTH`).
    """
    import dask

    from cosim.parallel.cluster.interrupts import processes_started_here_get_the_preload
    from cosim.parallel.dashboard.web_server import web_server_tracebacks_as_lines

    # the workers a cluster file's scale/adapt starts at any time of the study ignore Ctrl-C as the first ones
    preload = processes_started_here_get_the_preload() if choice.kind == "file" else nullcontext()
    # LOG_LENGTH for the client's connections, and for the scheduler and workers of a cluster started here
    with dask.config.set({"distributed.admin.low-level-log-length": LOG_LENGTH}), web_server_tracebacks_as_lines(), \
            preload:
        yield from _client(choice, early)


NO_DASHBOARD = "unavailable (install bokeh to get it)"


def _connect(choice: ClusterChoice, early: Any) -> tuple[Any, Any, str]:
    """(client, the cluster started here or None, dashboard link) for ``choice``."""
    from distributed import Client

    from cosim.parallel.cluster.cluster_file import start_cluster
    from cosim.parallel.cluster.local import local_cluster
    from cosim.parallel.dashboard.on_demand import dashboard_available

    if choice.kind == "file":
        assert choice.file is not None
        cluster = start_cluster(choice.file)
        try:
            client = Client(cluster)
        except BaseException:
            cluster.close()
            raise
        return client, cluster, cluster.dashboard_link if dashboard_available() else NO_DASHBOARD
    if choice.kind == "local":
        dashboard = dashboard_available()
        cluster = early.take() if early is not None else local_cluster(choice.workers)
        client = Client(cluster)
        if dashboard:
            # Imported before the link is printed: the page's callbacks (bokeh, in Dask's IO-loop thread) import
            # pandas once a tab is open, and racing this thread's own first import of it (when the first rows
            # come) handed them a partially initialised module (an AttributeError traceback on the terminal).
            import pandas  # noqa: F401
        # not cluster.dashboard_link: that names the machine's address, the server listens on 127.0.0.1 only
        return client, cluster, (f"http://127.0.0.1:{cluster.scheduler.http_server.port}/status" if dashboard
                                 else NO_DASHBOARD)
    where = choice.describe()
    try:
        client = Client(choice.address, timeout=10)
    except OSError as exc:
        raise ClusterError(f"cannot reach the Dask scheduler at {where}: {exc}") from None
    except (MemoryError, ValueError, TypeError, KeyError, IndexError) as exc:
        # a server that is no Dask scheduler (ssh, smtp, http speak first): its first bytes, read as the
        # length of a Dask frame, asked for exabytes ("Unable to allocate 3.01 EiB"), or would not decode
        raise ClusterError(f"the server at {where} is not a Dask scheduler: it did not answer in "
                           f"Dask's protocol ({type(exc).__name__}: {str(exc)[:100]}); check the address and "
                           "port (a scheduler listens on 8786 unless told otherwise)") from None
    return client, None, client.dashboard_link


def _client(choice: ClusterChoice, early: Any) -> Iterator[tuple[Any, int, str]]:
    from cosim.parallel.cluster.closing import close_client_and_cluster

    client, cluster, link = _connect(choice, early)
    if choice.kind == "file":
        assert choice.file is not None
        where = f"{cluster.scheduler_address} ({choice.file.type} of {choice.file.path})"
        wait, hint = 600, f"check that the jobs of {choice.file.type} start (its scale/adapt and job system)"
    elif choice.kind == "address":
        where, wait = choice.describe(), 60
        hint = (f"start workers, or unset {CONFIGURED} to use a local cluster" if choice.configured
                else "start some with: dask worker ADDRESS --nthreads 1")
    else:
        where, wait, hint = str(client.scheduler.address), 60, "start some with: dask worker ADDRESS --nthreads 1"
    bare = choice.address if choice.kind == "address" else where  # the no-workers message names the address alone
    stopped = False  # by Ctrl-C or a stop signal (KeyboardInterrupt, see cosim.parallel.cluster.interrupts)
    try:
        if not choice.local:  # a scheduler of another environment
            _check_scheduler_imports_cosim(client, where)
        n_workers = _thread_count(client)
        if n_workers == 0:
            try:
                client.wait_for_workers(1, timeout=wait)
            except TimeoutError:
                raise ClusterError(f"the scheduler at {bare} has no workers (waited {wait} s); {hint}") from None
            n_workers = _thread_count(client)
        yield client, n_workers, link
    except KeyboardInterrupt:
        stopped = True
        raise
    finally:
        close_client_and_cluster(client, cluster, stopped)


def _check_scheduler_imports_cosim(client: Any, where: str) -> None:
    """Raise ClusterError when the scheduler cannot import cosim (it could run none of the tasks)."""
    from cosim.parallel.cluster.scheduler_check import scheduler_import_problem

    problem = scheduler_import_problem(client)
    if problem:
        raise ClusterError(f"the Dask scheduler at {where} cannot import cosim ({problem}); Dask's scheduler "
                           "unpickles every task, so it needs the modules the tasks name: install cosim (the "
                           "version of this client) where the scheduler runs")
