"""The dry run's time estimate (cosim.studies.estimate): the mean of the samples and its bootstrap range."""

from __future__ import annotations

import numpy as np
import pytest

from cosim.studies.estimate import estimate_time


def test_the_estimate_is_the_mean_and_its_range_widens_with_disagreeing_samples():
    even = estimate_time([1.0, 1.0, 1.0, 1.0])
    assert (even.mean, even.low, even.high, even.samples) == (1.0, 1.0, 1.0, 4)
    uneven = estimate_time([0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 5.0, 5.0])
    assert uneven.mean == pytest.approx(1.325)
    assert 0.1 <= uneven.low < uneven.mean < uneven.high <= 5.0
    # the 90 % bootstrap range of the mean of 8 samples from {0.1 x6, 5 x2}: against a direct simulation
    rng = np.random.default_rng(7)
    means = rng.choice([0.1] * 6 + [5.0] * 2, size=(20000, 8)).mean(axis=1)
    assert uneven.low == pytest.approx(np.quantile(means, 0.05), abs=0.62)  # 0.61 is one dear sample in 8
    assert uneven.high == pytest.approx(np.quantile(means, 0.95), abs=0.62)
    assert estimate_time([0.1] * 6 + [5.0] * 2) == uneven  # deterministic


def test_the_total_scales_with_points_and_workers():
    e = estimate_time([2.0, 4.0])
    assert e.total(10, 2) == (e.mean * 5, e.low * 5, e.high * 5) and e.mean == 3.0
    assert estimate_time([0.5]).total(4) == (2.0, 2.0, 2.0)


@pytest.mark.parametrize("times, confidence, message", [
    ([], 0.9, "no sample times"), ([1.0, -1.0], 0.9, ">= 0"), ([float("nan")], 0.9, "finite"),
    ([1.0], 1.0, r"confidence must lie in \(0, 1\)")])
def test_bad_input_is_refused(times, confidence, message):
    with pytest.raises(ValueError, match=message):
        estimate_time(times, confidence)
