"""Set-up of the worker processes of the local Dask cluster cosim starts: how they start, and a Dask *preload*.

:func:`start_method`: the worker processes are forked by a multiprocessing
*fork server* that has already imported Dask and cosim's worker modules,
instead of each starting a fresh Python that imports them (``spawn``, Dask's
default): the imports are paid once, not once per worker (about 0.3 s of CPU
of a 2-worker sweep of the README's main job, 2-core box).  The fork server
is started (by multiprocessing, with this process's ``sys.path``) when the
first cluster starts and serves every later one of this process; a worker
gets this process's environment as it is when its cluster starts (the Nanny's
``env``), not the fork server's.

:func:`dask_setup` runs in each worker process as it starts
(``LocalCluster(preload=[WORKER_SETUP])``, see
:func:`orchestrator.evaluator.local_cluster`).  It makes the process's exit
cheap: a worker process ends with the interpreter's full shutdown, whose
final garbage collections over Dask's objects took 1.3-1.6 s of the 1.5-1.7 s
a local cluster took to close (2 workers, loaded machine; 0.15-0.35 s with
this set-up).  ``gc.freeze`` at exit exempts the objects alive then; exit
handlers (those that stop the worker's child processes) still run first.
"""

from __future__ import annotations

import atexit
import gc
from typing import Any

WORKER_SETUP = __name__  # the module name given to Dask's ``preload``
# imported once by the fork server, so a forked worker has them: Dask's worker, the task function (run_batch)
# with what it uses, and the two preloads
FORK_SERVER_PRELOAD = ("distributed", "orchestrator.sweep", "orchestrator.dashboard_points", "orchestrator.interrupts",
                       WORKER_SETUP)


def start_method() -> str:
    """How the local cluster's worker processes start (Dask's ``distributed.worker.multiprocessing-method``):
    ``forkserver`` with FORK_SERVER_PRELOAD where the platform has it, else ``spawn``."""
    import multiprocessing

    import dask

    if "forkserver" not in multiprocessing.get_all_start_methods():
        return "spawn"  # Windows
    from distributed.utils import get_mp_context

    with dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"}):
        # Dask's own preload list (its required and optional packages, pandas among them) is replaced by ours;
        # it only takes effect when the fork server starts, i.e. before the first cluster of this process
        get_mp_context().set_forkserver_preload(list(FORK_SERVER_PRELOAD))
    return "forkserver"


def dask_setup(worker: Any) -> None:
    """Dask preload hook, run in the worker process at start-up."""
    atexit.register(gc.freeze)  # registered first, so it runs after the other exit handlers
