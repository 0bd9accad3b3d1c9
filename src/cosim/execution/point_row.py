"""A design point's outcome as every study records it: :class:`PointRow`, and the columns it fills.

The child process that runs points (:mod:`cosim.parallel.isolation`), the lock-step runner
(:mod:`cosim.execution.lockstep`), the Dask task (:mod:`cosim.parallel.tasks`) and the studies pass rows of this
one type; a study turns each into its results table's row with :meth:`PointRow.to_dict`.  This module imports
nothing heavy: the Dask scheduler and workers import it to unpickle rows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Mapping

if TYPE_CHECKING:
    from cosim.execution.run import RunResult

# a point's status: it ran; it failed in its run; it hung (killed at its timeout); it killed its process
STATUSES = ("ok", "failed", "timeout", "crashed")  # and "pruned" (cosim.execution.prune), counted only when it occurs
TAIL_COLUMNS = ("status", "message", "run_time", "worker")  # a results table's last columns, in this order


@dataclass(frozen=True, slots=True)
class PointRow:
    """The outcome of one design point as a study records it: what crosses from a point's process to the study.

    ``status`` is one of :data:`STATUSES` (``timeout`` and ``crashed`` are given by the parent of the process
    that ran the point, :mod:`cosim.parallel.isolation`); ``message`` says why a point is not ``ok``;
    ``run_time`` is in seconds (NaN when unknown: a point lost with its worker); ``objectives`` is flat
    (array objectives as ``name[i]``), empty unless the run got that far; ``worker`` names the Dask worker
    (empty until :func:`cosim.parallel.tasks.run_batch` says it).

    Rows cross process boundaries once per point, so they pickle as a plain tuple of their fields.
    """

    point_id: str
    status: str
    message: str = ""
    run_time: float = math.nan
    objectives: Mapping[str, float] = field(default_factory=dict)
    worker: str = ""

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @classmethod
    def of(cls, point_id: str, result: "RunResult", run_time: float) -> "PointRow":
        """The row of a finished run (its status, message and objectives) taking ``run_time`` seconds."""
        return cls(point_id, result.status, result.message, run_time, result.objectives)

    def on_worker(self, worker: str) -> "PointRow":
        """This row, run on ``worker``."""
        return PointRow(self.point_id, self.status, self.message, self.run_time, self.objectives, worker)

    def tail(self) -> dict[str, Any]:
        """The results table's :data:`TAIL_COLUMNS` of this row."""
        return {"status": self.status, "message": self.message, "run_time": self.run_time, "worker": self.worker}

    def to_dict(self, columns: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """This row as a results table's row: ``point_id``, then ``columns`` (the point's parameters, and whatever
        else the study records of it), the objectives, and the :data:`TAIL_COLUMNS`."""
        return {"point_id": self.point_id, **(columns or {}), **self.objectives, **self.tail()}

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        return PointRow, (self.point_id, self.status, self.message, self.run_time, self.objectives, self.worker)
