"""Making a study's warm start: the warm-up run to ``experiment.warm_start`` and the system that carries its
saved state (what the saved state is and how a point starts from it: :mod:`cosim.execution.warm_start`)."""

from __future__ import annotations

from dataclasses import replace

from cosim.errors import Problem, UserError
from cosim.execution.result import RunResult
from cosim.execution.run import Execution
from cosim.execution.warm_start import WARM_PATH, WarmState
from cosim.system.builder import System


def warm_up(system: System) -> tuple[WarmState | None, RunResult]:
    """Run ``system`` with the spec's own values to its ``experiment.warm_start`` and save it there.

    Returns (the warm state, the warm-up's result), or (None, the failed result) when a unit failed on the
    way.  Raises UserError when a unit cannot save its state or the run ends before the warm-start time.
    """
    execution = Execution(system, save_warm=True)
    result = execution.run()
    return execution.saved, result


def warmed(system: System) -> System:
    """``system`` carrying its warm state (``system.warm_start``) when its spec asks for a warm start and it has
    none yet; the same system otherwise.  Raises UserError when the warm-up cannot be made (see :func:`warm_up`),
    naming the failing unit."""
    if system.spec.experiment.warm_start is None or system.warm_start is not None:
        return system
    state, result = warm_up(system)
    if state is None:
        raise UserError([Problem(system.spec.path, WARM_PATH, f"the warm-up run to t="
                                 f"{system.spec.experiment.warm_start:g} failed: {result.message}",
                                 "fix what makes the run with the spec's own values fail, or remove warm_start")])
    return replace(system, warm_start=state)
