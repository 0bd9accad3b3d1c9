"""The cluster cosim starts when given none, and the Dask settings of every cluster cosim starts.

:func:`local_cluster`: a LocalCluster whose scheduler and workers run in this process, one thread each, on
127.0.0.1, its dashboard loaded when first opened.  :data:`ALLOWED_FAILURES` and :data:`LOG_LENGTH` hold on
every cluster cosim starts (also those of a cluster file, :mod:`cosim.parallel.cluster.cluster_file`).
"""

from __future__ import annotations

from typing import Any

ALLOWED_FAILURES = 1  # a task whose worker died is run once more elsewhere; a second death is the point's fault

# Dask keeps the last `distributed.admin.low-level-log-length` messages of every connection, and as many
# transitions and events, for debugging (1000 by default).  A sweep's task messages carry its points, so the
# client, the scheduler cosim runs in its process and the workers would hold the points of the last 1000 tasks
# of every connection: hundreds of MB for a sweep of a million cheap points (2048 a task).  The clients and
# clusters cosim starts keep LOG_LENGTH; the transitions of the last LOG_LENGTH tasks remain for a post-mortem.
LOG_LENGTH = 50


def local_cluster(workers: int) -> Any:
    """The cluster cosim starts when given none: a LocalCluster whose scheduler and ``workers`` workers (one
    thread each) run in this process, its dashboard on a free port of 127.0.0.1, loaded when first opened
    (:mod:`cosim.parallel.dashboard.on_demand`).  The caller closes it.

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

    from cosim.parallel.dashboard.on_demand import dashboard_available, serve_dashboard_on_demand

    with dask.config.set({"distributed.scheduler.allowed-failures": ALLOWED_FAILURES,
                          "distributed.admin.low-level-log-length": LOG_LENGTH}):
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=False,
                               dashboard_address="127.0.0.1:0", worker_dashboard_address="127.0.0.1:0",
                               worker_class=_worker_without_pages(Worker), silence_logs=40,
                               scheduler_kwargs={"dashboard": False})  # loaded when first opened, below
    try:
        if dashboard_available():
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
