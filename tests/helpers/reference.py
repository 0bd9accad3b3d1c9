"""Reference implementations the tests compare cosim's fast code with (slow on purpose, obviously right)."""

from __future__ import annotations

import numpy as np


def pareto_naive(values: np.ndarray, senses=None) -> np.ndarray:
    """The Pareto mask by comparing every pair (O(n^2)): the reference pareto_mask is checked against."""
    values = np.asarray(values, dtype=float)
    n, k = values.shape
    signs = np.array([1.0 if s.lower().startswith("min") else -1.0 for s in (senses or ["min"] * k)])
    v = values * signs
    out = np.zeros(n, dtype=bool)
    for i in range(n):
        if np.isnan(v[i]).any():
            continue
        out[i] = not any(j != i and not np.isnan(v[j]).any() and np.all(v[j] <= v[i]) and np.any(v[j] < v[i])
                         for j in range(n))
    return out
