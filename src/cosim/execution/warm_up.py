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
    if execution.saved is not None:
        _check_size(system, execution.saved)
    return execution.saved, result


def _check_size(system: System, state: WarmState) -> None:
    """Raise UserError when ``state`` is larger than one message a child process may send (``child_message_mb``).

    A study makes its warm state in a child process and receives it as one message; over the limit it was
    refused as "something other than a result on its channel".  ``cosim run`` (no child) checks the same
    limit, so that it and a study agree on a spec.
    """
    import pickle

    from cosim.util import limits

    most = limits.limit("child_message_mb")
    size = len(pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)) / (1 << 20)
    if size <= most:
        return
    largest, data = max(state.states, key=lambda named: len(named[1]), default=("?", b""))
    needed = int(size) + 1
    raise UserError([Problem(system.spec.path, WARM_PATH, f"the warm state at t={state.time:g} is {size:.1f} MB "
                             f"(unit '{largest}' saved {len(data) / (1 << 20):.1f} MB of it), more than the limit "
                             f"of {most:g} MB for one message from a child process, which carries it to the "
                             "study's points",
                             f"raise the limit: COSIM_CHILD_MESSAGE_MB={needed} (megabytes), or warm-start units "
                             "with a smaller state; the same limit holds for cosim run and a study")])


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
