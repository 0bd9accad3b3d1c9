"""What one run of one design point produced: :class:`RunResult`, data whatever happened in the run."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

OK, FAILED = "ok", "failed"
# Why a run failed, for RunResult.failure: a unit (or a non-finite objective),
# a user's file found unusable only while running, or a bug in cosim.
UNIT_FAILURE, USER_FAILURE, INTERNAL_FAILURE = "unit", "user", "internal"


@dataclass
class RunResult:
    """What one run produced.

    ``objectives`` is flat (array objectives as ``name[i]``); ``traces`` is a
    pandas DataFrame when recording was asked for, else None.  ``failure``
    says why a failed run failed: ``"unit"`` (a unit, or a non-finite
    objective), ``"user"`` (a user's file found unusable only while running,
    e.g. an FMU archive that escapes its folder) or ``"internal"`` (a bug).
    ``steps`` counts the communication steps taken (the accepted ones under
    the adaptive algorithm, whose ``step_stats`` say what else it did; under
    ``experiment.warm_start`` those after the warm start).
    """

    status: str
    message: str = ""
    objectives: dict[str, float] = field(default_factory=dict)
    traces: Any = None
    elapsed: float = 0.0
    steps: int = 0
    end_time: float = math.nan
    failure: str = ""
    # the adaptive algorithm's statistics (accepted, rejected, exceeded, smallest, largest, ...); None for a fixed step
    step_stats: dict[str, Any] | None = None

    @property
    def ok(self) -> bool:
        """Whether the run reached its stop time without a failure (status "ok")."""
        return self.status == OK
