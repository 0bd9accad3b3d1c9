"""The objective reducers computed in C (kernel.c's ``cosim_reduce``) from the rows the kernel recorded.

:func:`reduce_rows` gives what :meth:`cosim.master.observers.ObjectiveReducer.results` gives for the same
samples, bit for bit (kernel.c mirrors numpy's summation order, NaN rules and tie breaks), without copying the
objective columns out of the rows or running a numpy call per reduction.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from cosim.master.native import library as lib

# kernel.c's R_* codes; the keys are REDUCERS' names (a test keeps both lists equal)
CODES = {"final": 0, "initial": 1, "min": 2, "max": 3, "mean": 4, "integral": 5, "integral_abs": 6, "rms": 7,
         "time_of_max": 8, "time_of_min": 9}


def reduce_rows(times: np.ndarray, rows: np.ndarray, objectives: Sequence[tuple[str, str]],
                columns: Sequence[int], slices: Sequence[slice]) -> dict[str, Any]:
    """Objective name -> value (float, or an array for an array signal) of ``objectives`` ((name, reduction)
    each) over ``rows`` (n, all columns, C-ordered float64) sampled at ``times`` (n,): objective k reduces the
    row columns ``columns[slices[k]]``, and each reduction sees all of ``columns`` as numpy's sees all of the
    reducer's kept columns (the summation order depends on how many there are).  Raises KeyError for a
    reduction the kernel lacks."""
    n, stride = rows.shape
    if not rows.flags.c_contiguous or rows.dtype != np.float64 or times.dtype != np.float64:
        raise ValueError("the reducers read C-ordered float64 rows")
    times = np.ascontiguousarray(times)
    cols = np.asarray(columns, dtype=np.intc)
    wanted = list(dict.fromkeys(reduction for _, reduction in objectives))  # each reduction once, all columns
    codes = np.array([CODES[r] for r in wanted], dtype=np.intc)
    reduced = np.empty((len(wanted), len(cols)))
    scratch = np.empty(max(n, 1))
    if lib.reduce_function()(len(codes), codes.ctypes.data, times.ctypes.data, rows.ctypes.data, n, stride,
                             len(cols), cols.ctypes.data, reduced.ctypes.data, scratch.ctypes.data):
        raise KeyError(f"the native kernel lacks one of the reductions {wanted}")
    out: dict[str, Any] = {}
    for (name, reduction), part in zip(objectives, slices):
        chosen = reduced[wanted.index(reduction)][part]
        out[name] = float(chosen[0]) if len(chosen) == 1 else chosen.copy()
    return out
