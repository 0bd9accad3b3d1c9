"""What the Dask dashboard shows of cosim's tasks: their keys.

:func:`task_key` is the key of a task running a batch of points.  Dask groups tasks by the key's leading words
(its *prefix*, ``dask.utils.key_split``), so every batch of one study falls under one progress bar named after
it (``cosim sweep NAME``), and the rest of the key names the task's points, as the dashboard's task stream,
worker and task pages show it: ``cosim sweep NAME-points 4..6 of 40-<unique>``.  Dask's bars count these
tasks; the points page of :mod:`cosim.parallel.dashboard.points` counts points.  A point's own status is a row
of the results table, never a task error: a failing point leaves no traceback in a worker's log.
"""

from __future__ import annotations

import uuid
from typing import Sequence


def task_key(kind: str, study: str, indices: Sequence[int], total: int, run: str = "") -> str:
    """A unique Dask key for the task running the points at ``indices`` (0-based) of the ``total`` of ``study``.

    ``kind`` is the command (``sweep``, ``optimize``); the prefix
    ``cosim KIND STUDY`` is what the progress bar shows.  ``run`` (letters
    and digits) identifies this run of the study for the points page of
    :mod:`cosim.parallel.dashboard.points`: the key then ends ``-RUN.<unique>``.
    """
    name = study.replace("-", "_") or "study"  # '-' separates a key's prefix from the rest
    first, last = indices[0] + 1, indices[-1] + 1
    if len(indices) == 1:
        which = f"point {first}"
    elif last - first + 1 == len(indices):
        which = f"points {first}..{last}"
    else:  # not consecutive
        which = f"{len(indices)} points from {first}"
    unique = f"{run}.{uuid.uuid4().hex[:16]}" if run else uuid.uuid4().hex
    return f"cosim {kind} {name}-{which} of {total}-{unique}"


def payload_key(kind: str, study: str) -> str:
    """A unique Dask key for a study's payload (its system and unit files), scattered once to every worker.

    The dashboard lists it among the data held in memory and as a progress bar of its own, under the prefix
    ``cosim KIND STUDY system and unit files`` (``cosim system and unit files`` without a study): a name a
    user recognises, beside the study's bar of batches.
    """
    name = study.replace("-", "_")
    words = " ".join(w for w in ("cosim", kind, name, "system and unit files") if w)
    return f"{words}-{uuid.uuid4().hex}"
