"""A run driven by the native kernel in one call: every step taken in C, the probed rows handed to the
observers at once (``Observer.load``) and the objectives reduced in C (:mod:`cosim.master.native.reducers`),
so a run costs a few Python calls, not a few per step.

The observers see what the Python drive loop (:meth:`cosim.execution.run.Execution._drive`) shows them: the
same rows, the same end time and step count, ``stop_when`` at the same step, a unit ending the run with one
more row where it ended, and a unit's failure raised as its UnitError.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from cosim.master.native.algorithm import NativeFixedStep
from cosim.master.native.reducers import reduce_rows
from cosim.master.observers import ObjectiveReducer, Observer, StopCondition, StopWhen, TraceRecorder


def takes_bulk(observers: Sequence[Observer]) -> bool:
    """True when every observer takes a whole run's rows at once: trace recorders without exact columns
    (read live from the units) and ``stop_when``, which the kernel evaluates; any other observer watches
    step by step, so the run steps one communication step per call."""
    for observer in observers:
        if isinstance(observer, StopWhen):
            continue
        if not isinstance(observer, TraceRecorder) or observer._exact is not None:
            return False
    return True


def drive_native(algorithm: NativeFixedStep, context: Any, observers: Sequence[Observer], progress: Any,
                 t_end: float) -> None:
    """Start ``algorithm``, run it to ``t_end`` in one kernel call and feed ``observers`` its rows; updates
    ``progress`` (time, steps, why it stopped) as the step-by-step drive does; raises a unit's UnitError."""
    probe = context.probe
    stop_column = -1
    for observer in observers:
        if isinstance(observer, StopWhen):
            stop_column = list(probe.columns).index(observer.column)
    algorithm.start(progress.t)
    run = algorithm.run(progress.t, t_end, probe.layout, len(probe.columns), stop_column)
    progress.t, progress.steps = run.t, run.steps
    if run.error is not None:
        raise run.error
    times, values = run.times, run.values
    if run.ended is not None:  # as the drive loop does: one more row where the unit ended the run
        progress.t, progress.steps = run.ended.time, run.steps + 1
        progress.stopped, progress.by_unit = str(run.ended), True
        times = np.append(times, run.ended.time)
        values = np.vstack([values, probe.read()])
    for observer in observers:
        if isinstance(observer, ObjectiveReducer) and type(observer).results is ObjectiveReducer.results:
            observer.load_reduced(reduce_rows(times, values, observer.objectives, observer.kept, observer.slices))
            continue
        if not observer.load(times, values):  # stop_when: it sees each row, as in the step-by-step drive
            observer.initialized(times[0], values[0])
            for t, row in zip(times[1:], values[1:]):
                observer.step(t, row)
    if progress.stopped is None:
        for stop in (o for o in observers if isinstance(o, StopCondition)):
            if stop.reason is not None:
                progress.stopped, progress.status = stop.reason, stop.status
                return
