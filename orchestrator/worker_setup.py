"""Set-up of the worker processes of the local Dask cluster cosim starts (a Dask *preload*).

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


def dask_setup(worker: Any) -> None:
    """Dask preload hook, run in the worker process at start-up."""
    atexit.register(gc.freeze)  # registered first, so it runs after the other exit handlers
