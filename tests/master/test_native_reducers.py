"""The objective reducers in C (cosim.master.native.reducers, kernel.c's cosim_reduce) against the Python
reducers (cosim.master.observers.REDUCERS via ObjectiveReducer), bit for bit, on random samples chosen to hit
numpy's summation paths (one column: pairwise sums, blocks of 8 and 128; several: a running sum), ties,
signed zeros, NaN and infinities, and zero durations."""

from __future__ import annotations

import numpy as np
import pytest

from cosim.master.native.reducers import CODES, reduce_rows
from cosim.master.observers import REDUCERS, ObjectiveReducer

LENGTHS = [1, 2, 3, 7, 8, 9, 15, 16, 17, 100, 128, 129, 136, 300, 1001, 5000]


def _samples(rng, n, ncol, kind):
    rows = rng.standard_normal((n, ncol)) * 10.0 ** rng.uniform(-3, 3, (n, ncol))
    if kind == "ties":
        rows = np.round(rows)
    elif kind == "zeros":
        rows[rng.random((n, ncol)) < 0.4] = 0.0
        rows[rng.random((n, ncol)) < 0.4] = -0.0
    elif kind == "nan":
        rows[rng.random((n, ncol)) < 0.05] = np.nan
    elif kind == "inf":
        rows[rng.random((n, ncol)) < 0.05] = np.inf * rng.choice([-1.0, 1.0])
    return rows


def test_the_kernel_has_every_reduction_the_spec_names():
    assert set(CODES) == set(REDUCERS)


@pytest.mark.parametrize("kind", ["plain", "ties", "zeros", "nan", "inf"])
def test_c_reducers_equal_the_python_reducers_bit_for_bit(kind):
    rng = np.random.default_rng(35)
    compared = 0
    for trial in range(150):
        n, ncol = int(rng.choice(LENGTHS)), int(rng.integers(1, 6))
        rows = _samples(rng, n, ncol, kind)
        times = np.cumsum(rng.uniform(0.001, 0.1, n)) if trial % 7 else np.zeros(n)  # some of zero duration
        columns = [f"c{i}" for i in range(ncol)]
        objectives = []
        for k in range(int(rng.integers(1, 5))):
            chosen = sorted(rng.choice(ncol, int(rng.integers(1, ncol + 1)), replace=False).tolist())
            objectives.append((f"o{k}", str(rng.choice(sorted(REDUCERS))), [columns[i] for i in chosen]))
        python = ObjectiveReducer(columns, objectives)
        python.load(times, rows)
        want = python.results()
        got = reduce_rows(times, rows, python.objectives, python.kept, python.slices)
        assert list(got) == list(want)
        for name, value in want.items():
            assert np.asarray(got[name]).tobytes() == np.asarray(value).tobytes(), (n, ncol, objectives, name)
            compared += 1
    assert compared > 300


def test_a_reducer_given_the_c_results_hands_them_out():
    python = ObjectiveReducer(["a", "b"], [("m", "max", ["a", "b"])])
    python.load_reduced({"m": np.array([1.0, 2.0])})
    first = python.results()
    first["m"][0] = 9.0  # a copy: the caller cannot change what the reducer holds
    assert python.results()["m"].tolist() == [1.0, 2.0]


def test_rows_not_c_ordered_are_refused():
    rows = np.zeros((4, 3))[:, :2]
    with pytest.raises(ValueError, match="C-ordered"):
        reduce_rows(np.arange(4.0), rows, [("a", "final")], [0], [slice(0, 1)])
