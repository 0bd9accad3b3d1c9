"""Where the points of a task lost with its workers go next, and the rows of those lost for good.

A task lost with its worker process is run again by the scheduler on another worker; the points of a task
lost again then run in small groups, each alone on the cluster, and the points of a group lost alone one at a
time, so only a point that kills its workers while alone gets ``crashed`` (:class:`Reruns`,
:func:`lost_rows`) and every other point its true row.
"""

from __future__ import annotations

import collections
from typing import Any, Sequence

from cosim.execution.point_row import PointRow


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
