"""Which K designs to simulate next: batch Bayesian optimisation on the surrogates (``--sampler surrogate``).

One Gaussian process per objective (and one for the constraints' worst violation), fitted by
:func:`cosim.analysis.surrogate.fit.fit_gp` on the designs evaluated so far, in the unit box of the design space.
An objective whose values are all positive is modelled as its logarithm (energies and times: the spread near
the minimum is what matters, and a log keeps the predictions positive).

**Acquisition: expected hypervolume improvement (EHVI), estimated by Monte Carlo over the posterior**, on a
candidate set (uniform designs, designs near the current front, then designs near the best of those); the
batch is chosen greedily with the **kriging believer**: after each pick, its posterior mean is taken as if it had
been simulated (it joins the front, and the posterior variance near it shrinks; the mean does not move), and
the next pick maximises EHVI over that.  Why this and not q-ParEGO (random Chebyshev weights, one EI each):
EHVI scores a design by the quantity the run is judged by, the hypervolume, while a random weight points a
pick at a part of the front that may be dense already; in two objectives a sample's exact hypervolume
improvement costs O(front size), so thousands of candidates cost milliseconds.  The believer makes the K picks
of a batch spread out (a second pick next to the first is predicted to add nothing) without simulating.

The constraints enter the same samples: a sample counts only where its sampled violation is <= 0 (the
probability of feasibility, joint with the improvement); designs where runs fail enter through the failure
classifier (:mod:`.failures`): EHVI times the probability that a run succeeds.  Before any feasible design is
known the acquisition is the probability of feasibility.

Everything is a function of the data and the seed given: the same history gives the same batch.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from cosim.analysis.hypervolume import HV_REFERENCE, hypervolume
from cosim.analysis.pareto import pareto_mask
from cosim.analysis.surrogate.fit import fit_gp
from cosim.analysis.surrogate.models import GaussianProcess

SHAPE = "matern52"
SHORTEST = 0.05  # length scales below 5 % of a range cannot be told from a few hundred designs (and are slow)
COLD_ITERATIONS, WARM_ITERATIONS = 60, 15  # L-BFGS iterations of the first fit, and of each later warm start
SAMPLES = 32  # Monte Carlo samples of the posterior per candidate
SCREENED = 64  # candidates scored by Monte Carlo at each pick: those of the highest optimistic improvement
REFIT_GROWTH = 1.25  # hyper-parameters are refitted once the designs grew by this factor since the last fit
GLOBAL, LOCAL, REFINE = 700, 700, 400  # candidates: uniform, near the front, near the best of those


@dataclass
class Output:
    """One modelled output: its Gaussian process (fixed hyper-parameters) and how its values were transformed."""

    gp: GaussianProcess
    log: bool  # modelled as log(value)

    def transform(self, y: np.ndarray) -> np.ndarray:
        return np.log(y) if self.log else y

    def back(self, t: np.ndarray) -> np.ndarray:
        return np.exp(t) if self.log else t


def fit_output(u: np.ndarray, y: np.ndarray, positive_log: bool, start: Output | None, seed: int,
               refit: bool = True) -> Output:
    """A Gaussian process of ``y`` over the unit-box designs ``u``, warm-started at ``start``'s hyper-parameters
    (``refit`` false: ``start``'s hyper-parameters kept, only conditioned on the designs)."""
    from threadpoolctl import threadpool_limits

    log = positive_log and bool(np.all(y > 0))
    target = np.log(y) if log else y
    begin = start.gp if start is not None and start.log == log else None
    iterations = COLD_ITERATIONS if begin is None else WARM_ITERATIONS if refit else 0
    with threadpool_limits(limits=1, user_api="blas"):  # small matrices: a second BLAS thread only spins
        gp = fit_gp(u, target, SHAPE, seed, restarts=0, start=begin, iterations=iterations, shortest=SHORTEST)
    return Output(gp, log)


class Believer:
    """An output's posterior at a fixed candidate set, updated as picks are believed (kriging believer).

    The mean never changes (believing the mean leaves it where it is); the variance at every candidate shrinks
    by the Schur complement of each pick: ``cov(c, s)^2 / var(s)``.
    """

    def __init__(self, output: Output, u_candidates: np.ndarray):
        from scipy.linalg import solve_triangular

        gp = output.gp
        self.gp, self.output = gp, output
        self.z = gp.scaling.inputs(u_candidates)
        k = _kernel(gp, self.z, gp.x_train)  # (C, n)
        self.v = solve_triangular(gp.cholesky, k.T, lower=True, check_finite=False)  # (n, C)
        self.mean = (k @ gp.alpha) * gp.scaling.y_scale + gp.scaling.y_mean  # transformed units
        self.var = np.maximum(gp.constant - np.sum(self.v * self.v, axis=0), 1e-12)  # standardised, latent
        self.columns: list[np.ndarray] = []  # cov(candidates, pick j) after picks < j, per pick

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(self.var) * self.gp.scaling.y_scale

    def believe(self, pick: int) -> None:
        """Take candidate ``pick`` as simulated at its mean."""
        cov = _kernel(self.gp, self.z, self.z[pick:pick + 1])[:, 0] - self.v.T @ self.v[:, pick]
        for column in self.columns:
            cov = cov - column * column[pick]
        column = cov / np.sqrt(max(cov[pick] + self.gp.noise, 1e-12))
        self.columns.append(column)
        self.var = np.maximum(self.var - column * column, 1e-12)


def _mean(gp: GaussianProcess, u: np.ndarray) -> np.ndarray:
    """The posterior mean (transformed units) at unit-box designs ``u``."""
    return (_kernel(gp, gp.scaling.inputs(u), gp.x_train) @ gp.alpha) * gp.scaling.y_scale + gp.scaling.y_mean


def _kernel(gp: GaussianProcess, za: np.ndarray, zb: np.ndarray) -> np.ndarray:
    """``c * matern52(|(a - b) / length_scales|)`` between scaled designs (no noise term)."""
    squared = np.zeros((len(za), len(zb)))
    for j in range(za.shape[1]):
        step = (za[:, j, None] - zb[None, :, j]) / gp.length_scales[j]
        squared += step * step
    s = np.sqrt(5.0 * squared)
    return gp.constant * (1.0 + s + s * s / 3.0) * np.exp(-s)


def improvement(front: np.ndarray, points: np.ndarray, reference: float = HV_REFERENCE) -> np.ndarray:
    """Hypervolume improvement of each of ``points`` (..., m) over ``front`` (k, m), both scaled losses, with the
    reference point ``reference`` in every objective: exact, vectorised for m <= 2, by WFG for m > 2."""
    points = np.minimum(points, reference)
    m = points.shape[-1]
    own = np.prod(reference - points, axis=-1)
    if len(front) == 0:
        return own
    front = np.minimum(front, reference)
    if m == 1:
        return np.maximum(front.min() - points[..., 0], 0.0)
    if m == 2:
        front = front[np.argsort(front[:, 0], kind="stable")]
        # the front clipped into the point's box is a staircase in the same order: its area term by term
        q1 = np.maximum(points[..., None, 0], front[:, 0])
        q2 = np.maximum(points[..., None, 1], front[:, 1])
        q2 = np.minimum.accumulate(q2, axis=-1)
        previous = np.concatenate([np.full(q2.shape[:-1] + (1,), reference), q2[..., :-1]], axis=-1)
        covered = np.sum((reference - q1) * (previous - q2), axis=-1)
        return np.maximum(own - covered, 0.0)
    flat = points.reshape(-1, m)
    base = hypervolume(front, reference)
    gains = [hypervolume(np.vstack([front, p]), reference) - base for p in flat]
    return np.maximum(np.asarray(gains), 0.0).reshape(points.shape[:-1])


@dataclass
class History:
    """The evaluated designs as the acquisition sees them (unit box, objectives as losses: minimised)."""

    u: np.ndarray  # (n, d) designs with values
    losses: np.ndarray  # (n, m) objective values, minimised
    violation: np.ndarray | None  # (n,) worst constraint violation (<= 0: feasible), None without constraints
    pending: np.ndarray  # (p, d) designs asked but not yet told: believed at their mean
    failed: np.ndarray  # (f, d) designs whose runs failed
    positive: np.ndarray  # (m,) bool: the objective may be modelled as its log (its sense is minimise)

    def feasible(self) -> np.ndarray:
        return np.ones(len(self.u), bool) if self.violation is None else self.violation <= 0


class BatchProposer:
    """Proposes batches of designs from a :class:`History`; keeps the last fit to warm-start the next."""

    def __init__(self, dimension: int, objectives: int):
        self.d, self.m = dimension, objectives
        self.outputs: list[Output] = []
        self.constraint: Output | None = None
        self.fitted_at = 0  # how many designs the hyper-parameters were last fitted on

    def fit(self, history: History, seed: int) -> None:
        """Fit every output on ``history``: hyper-parameters by maximum likelihood from the previous fit's when the
        designs grew by REFIT_GROWTH since that fit, else the previous ones conditioned on the new designs (the
        likelihood moves little between two batches, and its optimisation is most of a batch's cost)."""
        n = len(history.u)
        refit = not self.outputs or n >= REFIT_GROWTH * self.fitted_at
        self.fitted_at = n if refit else self.fitted_at
        previous: Sequence[Output | None] = self.outputs or [None] * self.m
        self.outputs = [fit_output(history.u, history.losses[:, i], bool(history.positive[i]), previous[i], seed,
                                   refit) for i in range(self.m)]
        self.constraint = None if history.violation is None else \
            fit_output(history.u, history.violation, False, self.constraint, seed, refit)

    def propose(self, history: History, k: int, rng: np.random.Generator) -> np.ndarray:
        """``k`` designs (rows in the unit box) by greedy EHVI with the kriging believer (module docstring)."""
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):  # small matrices: a second thread only spins
            return self._propose(history, k, rng)

    def _propose(self, history: History, k: int, rng: np.random.Generator) -> np.ndarray:
        from cosim.analysis.surrogate.failures import fit_failures

        feasible = history.feasible()
        front = history.losses[feasible]
        front = front[pareto_mask(front)] if len(front) else front
        lo, span = _scale(history.losses[feasible] if feasible.any() else history.losses, front)
        candidates = self._candidates(history, front, feasible, rng)
        fails = None
        if len(history.failed) >= 5:
            both = np.vstack([history.u, history.failed])
            flags = np.r_[np.zeros(len(history.u), bool), np.ones(len(history.failed), bool)]
            fails = fit_failures(both, flags)
        eps = rng.standard_normal((SAMPLES, self.m + 1))  # common random numbers: candidates ranked fairly
        believed = np.zeros((0, self.m))
        # the designs asked but not yet told come first, believed as picks already made
        pending = list(range(len(history.pending)))
        candidates = np.vstack([history.pending, candidates]) if pending else candidates
        believers, success = self._believers(candidates, fails)
        scaled_front = (front - lo) / span
        picks: list[int] = []
        for j in range(len(pending) + k):
            if j < len(pending):
                pick = pending[j]
            else:
                score = self._score(believers, scaled_front, believed, lo, span, eps) * success
                score[pending + picks] = -np.inf
                if not np.isfinite(score).any() or np.nanmax(score) <= 0:  # nothing to gain: explore
                    score = np.prod([b.std / max(float(np.std(b.mean)), 1e-12) for b in believers[:self.m]],
                                    axis=0) * success
                    score[pending + picks] = -np.inf
                pick = int(np.nanargmax(score))
                picks.append(pick)
            mean = np.array([b.output.back(b.mean[pick]) for b in believers[:self.m]])
            if self.constraint is None or believers[-1].mean[pick] <= 0:
                believed = np.vstack([believed, (mean - lo) / span])
            for b in believers:
                b.believe(pick)
        return candidates[picks]

    def _believers(self, candidates: np.ndarray, fails) -> tuple[list[Believer], np.ndarray]:
        outputs = self.outputs + ([self.constraint] if self.constraint is not None else [])
        believers = [Believer(o, candidates) for o in outputs]
        success = np.ones(len(candidates)) if fails is None else 1.0 - fails.probability(candidates)
        return believers, success

    def _score(self, believers: list[Believer], front: np.ndarray, believed: np.ndarray, lo: np.ndarray,
               span: np.ndarray, eps: np.ndarray) -> np.ndarray:
        """EHVI (Monte Carlo over SAMPLES posterior draws, feasibility in the same draws) at the SCREENED
        candidates of the highest optimistic improvement (at mean - 2 standard deviations: the improvement is
        monotone, so a candidate low there is low in most draws); 0 at the others."""
        current = np.vstack([front, believed]) if len(believed) else front
        current = current[pareto_mask(current)] if len(current) else current
        objectives = believers[:self.m]
        optimistic = np.stack([b.output.back(b.mean - 2.0 * b.std) for b in objectives], axis=-1)
        rough = improvement(current, (optimistic - lo) / span)
        if self.constraint is not None:
            b = believers[-1]
            rough = rough * (b.mean - 2.0 * b.std <= 0)
        chosen = np.argsort(-rough, kind="stable")[:SCREENED]
        draws = np.stack([b.output.back(b.mean[None, chosen] + b.std[None, chosen] * eps[:, i, None])
                          for i, b in enumerate(objectives)], axis=-1)  # (S, chosen, m)
        gain = improvement(current, (draws - lo) / span)  # (S, chosen)
        if self.constraint is not None:
            b = believers[-1]
            ok = (b.mean[None, :] + b.std[None, :] * eps[:, -1, None]) <= 0
            if not len(front):  # no feasible design yet: find one
                return ok.mean(axis=0)
            gain = gain * ok[:, chosen]
        score = np.zeros(len(rough))
        score[chosen] = gain.mean(axis=0)
        return score

    def _candidates(self, history: History, front: np.ndarray, feasible: np.ndarray,
                    rng: np.random.Generator) -> np.ndarray:
        """Uniform designs, and designs near the front's: some coordinates moved by a normal step."""
        out = [rng.random((GLOBAL, self.d))]
        if feasible.any():
            losses = history.losses[feasible]
            centres = history.u[feasible][pareto_mask(losses)]
        else:
            centres = history.u[np.argsort(history.violation)[:5]] if history.violation is not None else history.u
        out.append(_perturb(centres, LOCAL, rng, self.d))
        candidates = np.vstack(out)
        if len(self.outputs):  # near the best by the mean alone: a cheap first look, then closer steps there
            lo, span = _scale(history.losses[feasible] if feasible.any() else history.losses, front)
            means = np.stack([o.back(_mean(o.gp, candidates)) for o in self.outputs], axis=-1)
            gain = improvement((front - lo) / span if len(front) else front, (means - lo) / span)
            best = candidates[np.argsort(-gain, kind="stable")[:20]]
            candidates = np.vstack([candidates, _perturb(best, REFINE, rng, self.d, scale=0.3)])
        return candidates


def _perturb(centres: np.ndarray, count: int, rng: np.random.Generator, d: int, scale: float = 1.0) -> np.ndarray:
    """``count`` designs near ``centres``: each moves a random subset of its coordinates (about min(d, 3) of them,
    as trust-region methods do in many dimensions) by a normal step of 1-20 % of the range, clipped to the box
    (so the box's faces, where optima often lie, are reached)."""
    base = centres[rng.integers(0, len(centres), count)]
    sigma = scale * np.exp(rng.uniform(np.log(0.01), np.log(0.2), (count, 1)))
    moved = rng.random((count, d)) < min(1.0, 3.0 / d)
    moved[np.arange(count), rng.integers(0, d, count)] = True
    return np.clip(base + moved * rng.standard_normal((count, d)) * sigma, 0.0, 1.0)


def _scale(losses: np.ndarray, front: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Objectives scaled so that the front spans [0, 1] (the reference point then sits just beyond its worst)."""
    lo = losses.min(axis=0)
    hi = front.max(axis=0) if len(front) else losses.max(axis=0)
    span = hi - lo
    fallback = losses.max(axis=0) - lo
    span = np.where(span > 0, span, np.where(fallback > 0, fallback, 1.0))
    return lo, span
