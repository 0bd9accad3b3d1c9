"""How long a study will take, from a few sample runs: a mean per point and the range it may lie in.

The cost of a design point can differ by orders of magnitude across a space (a planner that gives up at once
against one that plans and executes a whole task), and a few samples may all miss the dear region. So the
estimate is the *mean* of the samples (the median ignores the few dear points that make most of the total)
with a bootstrap interval of that mean: the samples resampled with replacement, the mean of each resample,
and the central ``confidence`` share of those means. The interval says how much the samples disagree; it
cannot see a dear region no sample reached, which is why the samples are stratified over the space
(:meth:`cosim.spec.design.DesignSpace.stratified`).

Pure: no runs, no I/O. ``benchmarks/dry_run_estimate.py`` measures the estimate against recorded studies.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

BOOTSTRAP_RESAMPLES = 2000


@dataclass(frozen=True)
class TimeEstimate:
    """Seconds per point: ``mean`` of the samples, and ``low``..``high``, the interval of that mean."""

    mean: float
    low: float
    high: float
    samples: int
    confidence: float

    def total(self, points: int, workers: int = 1) -> tuple[float, float, float]:
        """Wall seconds (mean, low, high) for ``points`` points shared by ``workers`` busy workers."""
        share = points / max(workers, 1)
        return self.mean * share, self.low * share, self.high * share


def estimate_time(times: Sequence[float], confidence: float = 0.9, seed: int = 0) -> TimeEstimate:
    """The mean of ``times`` (seconds per sample point) and its bootstrap interval at ``confidence``.

    Deterministic for a given ``seed``. Raises ValueError for no times, a negative time or a confidence
    outside (0, 1).
    """
    values = np.asarray(times, dtype=float)
    if values.size == 0:
        raise ValueError("no sample times to estimate from")
    if (values < 0).any() or not np.isfinite(values).all():
        raise ValueError(f"sample times must be finite and >= 0, got {list(times)}")
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence}")
    mean = float(values.mean())
    if values.size == 1:
        return TimeEstimate(mean, mean, mean, 1, confidence)
    draws = np.random.default_rng(seed).integers(0, values.size, size=(BOOTSTRAP_RESAMPLES, values.size))
    means = values[draws].mean(axis=1)
    tail = (1 - confidence) / 2
    low, high = np.quantile(means, [tail, 1 - tail])
    return TimeEstimate(mean, float(min(low, mean)), float(max(high, mean)), int(values.size), confidence)
