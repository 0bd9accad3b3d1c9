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


def fixed_scale(values: np.ndarray, senses: Sequence[str], usable: np.ndarray,
                batches: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(ideal, nadir) of the usable rows of the first batch that has any: the scale every later hypervolume of
    the optimisation is measured in, fixed once that batch is told, so the measure never decreases as rows come
    (a scale from the current front moved with it: constant on a converged grid, dropping between batches)."""
    first = np.asarray(batches)[usable].min()
    rows = np.asarray(values, dtype=float)[usable & (np.asarray(batches) == first)]
    signs = np.array([1.0 if s.startswith("min") else -1.0 for s in senses])
    ideal = np.where(signs > 0, rows.min(axis=0), rows.max(axis=0))
    nadir = np.where(signs > 0, rows.max(axis=0), rows.min(axis=0))
    return ideal, nadir


def progress_hypervolume(values: np.ndarray, senses: Sequence[str], usable: np.ndarray,
                         batches: np.ndarray) -> float:
    """The hypervolume of the usable rows' front in the optimisation's :func:`fixed_scale`, reference point
    HV_REFERENCE: the one figure the progress line, the report and the decision room show (0 before any row)."""
    history = hypervolume_history(values, senses, usable, batches)
    return float(history[-1]) if len(history) else 0.0


def hypervolume_history(values: np.ndarray, senses: Sequence[str], usable: np.ndarray,
                        batches: np.ndarray | None = None) -> np.ndarray:
    """Hypervolume of the front after each row (rows in evaluation order) of the ``usable`` rows (ok and
    feasible), objectives scaled to [0, 1] between the ideal and nadir of the first batch's usable rows
    (:func:`fixed_scale`; without ``batches``, of all usable rows), reference point HV_REFERENCE in
    every scaled objective: it never decreases, and its last value is the progress line's."""
    values = np.asarray(values, dtype=float)
    usable = np.asarray(usable, dtype=bool)
    out = np.zeros(len(values))
    if not usable.any():
        return out
    if batches is None:  # a table without batch numbers (not written by cosim optimize): one batch, all rows
        batches = np.zeros(len(values), dtype=int)
    ideal, nadir = fixed_scale(values, senses, usable, batches)
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
