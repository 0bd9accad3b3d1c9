"""The hypervolume of a Pareto front: how much of the objective space it dominates, the measure of an
optimisation's progress.

Objectives are scaled to [0, 1] between an ideal and a nadir point and read as losses (a maximised objective
turned around), so the measure does not depend on their units; the reference point is HV_REFERENCE in every
scaled objective.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from cosim.analysis.pareto import pareto_mask

HV_REFERENCE = 1.1  # hypervolume reference point in objectives scaled to [0, 1]


def normalised_losses(values: np.ndarray, senses: Sequence[str], ideal: np.ndarray | None = None,
                      nadir: np.ndarray | None = None) -> np.ndarray:
    """Objective values as losses scaled to [0, 1] between ``ideal`` and ``nadir`` (default: of ``values``)."""
    signs = np.array([1.0 if s.startswith("min") else -1.0 for s in senses])
    losses = np.asarray(values, dtype=float) * signs
    if ideal is None or nadir is None:
        ideal, nadir = losses.min(axis=0), losses.max(axis=0)
    else:
        ideal, nadir = np.asarray(ideal) * signs, np.asarray(nadir) * signs
        ideal, nadir = np.minimum(ideal, nadir), np.maximum(ideal, nadir)
    span = np.where(nadir > ideal, nadir - ideal, 1.0)
    return (losses - ideal) / span


def hypervolume(losses: np.ndarray, reference: float = HV_REFERENCE) -> float:
    """Hypervolume dominated by ``losses`` (rows of scaled losses) up to the point ``reference`` in every
    objective; rows beyond the reference in any objective add nothing.  Optuna's exact WFG algorithm."""
    from optuna._hypervolume import compute_hypervolume  # exact, any dimension; the module is Optuna's own

    losses = np.asarray(losses, dtype=float)
    if losses.ndim != 2 or len(losses) == 0:
        return 0.0
    losses = losses[np.all(np.isfinite(losses), axis=1) & np.all(losses < reference, axis=1)]
    if len(losses) == 0:
        return 0.0
    return float(compute_hypervolume(losses, np.full(losses.shape[1], reference)))


def hypervolume_history(values: np.ndarray, senses: Sequence[str], usable: np.ndarray) -> np.ndarray:
    """Hypervolume of the front after each row (rows in evaluation order) of the ``usable`` rows (ok and
    feasible), objectives scaled to [0, 1] between the ideal and nadir points of the final front, reference
    point HV_REFERENCE: it rises to the final front's value as the search converges."""
    out = np.zeros(len(values))
    if not usable.any():
        return out
    signs = np.array([1.0 if s.startswith("min") else -1.0 for s in senses])
    final = values[usable][pareto_mask(values[usable] * signs)]
    ideal = np.where(signs > 0, final.min(axis=0), final.max(axis=0))
    nadir = np.where(signs > 0, final.max(axis=0), final.min(axis=0))
    losses = normalised_losses(values[usable], senses, ideal, nadir)
    front: np.ndarray = np.zeros((0, losses.shape[1]))
    index = np.flatnonzero(usable)
    current, k = 0.0, 0
    for i in range(len(values)):
        if k < len(index) and index[k] == i:
            front = np.vstack([front, losses[k]])
            front = front[pareto_mask(front)]
            current = hypervolume(front)
            k += 1
        out[i] = current
    return out
