"""Whether a Dask scheduler cosim did not start itself can run cosim's tasks.

Dask's scheduler unpickles every task it is given, so it must be able to
import the modules a task names (``cosim.parallel.tasks``: ``run_batch``); a
scheduler in an environment without cosim fails every task with "Error
during deserialization of the task graph".  :func:`scheduler_import_problem`
asks the scheduler once, before any work, so the user gets one clear message
instead of a table of crashed points.  The question is sent *by value*
(cloudpickle), so asking needs nothing of cosim on the scheduler.
"""

from __future__ import annotations

import sys
from typing import Any

TASK_MODULE = "cosim.parallel.tasks"  # where run_batch, the function of every cosim task, lives


def _import_problem(module: str) -> str:
    """Runs on the scheduler: '' when ``module`` imports there, else the error's type and message."""
    import importlib

    try:
        importlib.import_module(module)
    except Exception as exc:
        return f"{type(exc).__name__}: {exc}"
    return ""


def scheduler_import_problem(client: Any) -> str:
    """'' when ``client``'s scheduler can import cosim's task module, else why not (never raises)."""
    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # asking must not need cosim there
    try:
        return client.run_on_scheduler(_import_problem, TASK_MODULE)
    except Exception:  # a scheduler that cannot even answer: the tasks themselves will tell
        return ""
