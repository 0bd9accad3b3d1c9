"""``cosim optimize --sampler surrogate``: batch Bayesian optimisation on the surrogates, as an Optuna sampler.

It plugs in where Optuna's samplers do (ask and tell, resume, an Optuna storage all work unchanged):

- the first ``initial`` trials (default ``max(batch, 2 (d + 1))``) are a Latin hypercube of the design space
  (scipy's, seeded): space-filling designs to fit on;
- then, at the first ask after new results were told, the Gaussian processes of
  :mod:`cosim.analysis.surrogate.acquisition` are refitted on every finished trial (warm-started from the last
  fit) and a whole batch of ``batch`` designs is chosen by expected hypervolume improvement with the kriging
  believer; the asks of the batch hand them out in order.  Trials asked but not yet told are believed at their
  posterior mean, so a batch asked before the last was told still spreads out;
- the trials' constraint values (``Trial.set_constraint``) are modelled as their worst violation; failed
  trials (a run that failed, or a design outside the design constraint) train the failure classifier.

Dimensions map to the unit box: a float or int range linearly (or in its log), rounded to its step; a
categorical one by its choices' order (its index over [0, 1]: a surrogate sees an order there that the
choices may not have).  Deterministic: the same seed and history give the same proposals, which a resumed
run's replay relies on (see :mod:`cosim.studies.optimize`).
"""

from __future__ import annotations

import math
from typing import Any, Iterable, Mapping

import numpy as np
from optuna.distributions import BaseDistribution, CategoricalDistribution, FloatDistribution, IntDistribution
from optuna.samplers import BaseSampler, RandomSampler
from optuna.study import Study, StudyDirection
from optuna.trial import FrozenTrial, TrialState

from cosim.analysis.surrogate.acquisition import BatchProposer, History

CONSTRAINT_PREFIX = "constraints:"  # where Optuna keeps Trial.set_constraint's values in system_attrs


class SurrogateSampler(BaseSampler):
    """Batch Bayesian optimisation over ``distributions`` (name -> Optuna distribution), ``batch`` designs per
    fit, seeded by ``seed`` (see the module's docstring)."""

    def __init__(self, distributions: Mapping[str, BaseDistribution], seed: int, batch: int,
                 initial: int | None = None):
        from scipy.stats import qmc

        self._dists = dict(distributions)
        self._names = list(self._dists)
        self._d = len(self._names)
        self._seed = int(seed)
        self._batch = max(int(batch), 1)
        self.initial = initial if initial is not None else max(self._batch, 2 * (self._d + 1))
        self._lhs = qmc.LatinHypercube(self._d, seed=self._seed).random(self.initial) if self._d else None
        self._random = RandomSampler(seed=self._seed)
        self._proposer: BatchProposer | None = None
        self._fitted_on: tuple[int, ...] | None = None  # numbers of the finished trials of the last fit
        self._queue: list[np.ndarray] = []
        self.fits = 0  # how many times the surrogates were fitted (one per batch)

    # -- Optuna's interface -------------------------------------------------------------
    def infer_relative_search_space(self, study: Study, trial: FrozenTrial) -> dict[str, BaseDistribution]:
        return dict(self._dists)

    def sample_relative(self, study: Study, trial: FrozenTrial,
                        search_space: dict[str, BaseDistribution]) -> dict[str, Any]:
        if not search_space or self._lhs is None:  # no dimensions (the hypercube is made for d > 0)
            return {}
        if trial.number < self.initial:
            return self._params(self._lhs[trial.number])
        history, finished = self._history(study, trial)
        if len(history.u) < self._d + 2:  # too few results to fit on (failures): go on filling the space
            return self._params(self._rng(trial.number).random(self._d))
        if self._proposer is None:
            self._proposer = BatchProposer(self._d, len(study.directions))
        proposer = self._proposer
        if finished != self._fitted_on:
            proposer.fit(history, self._seed)
            self._fitted_on, self._queue, self.fits = finished, [], self.fits + 1
        if not self._queue:
            self._queue = list(proposer.propose(history, self._batch, self._rng(trial.number)))
        return self._params(self._queue.pop(0))

    def sample_independent(self, study: Study, trial: FrozenTrial, param_name: str,
                           param_distribution: BaseDistribution) -> Any:
        return self._random.sample_independent(study, trial, param_name, param_distribution)

    # -- the data ---------------------------------------------------------------------
    def _rng(self, number: int) -> np.random.Generator:
        return np.random.default_rng([self._seed, number])

    def _history(self, study: Study, current: FrozenTrial) -> tuple[History, tuple[int, ...]]:
        signs = np.array([1.0 if d == StudyDirection.MINIMIZE else -1.0 for d in study.directions])
        u, losses, violations, pending, failed, finished = [], [], [], [], [], []
        constrained = False
        for t in study.get_trials(deepcopy=False):
            if t.number == current.number or any(n not in t.params for n in self._names):
                continue
            row = self.unit(t.params)
            if t.state == TrialState.COMPLETE and t.values is not None and all(map(math.isfinite, t.values)):
                u.append(row)
                losses.append(np.asarray(t.values, float) * signs)
                values = [float(v) for k, v in t.system_attrs.items() if k.startswith(CONSTRAINT_PREFIX)]
                constrained = constrained or bool(values)
                violations.append(max(values) if values else 0.0)
            elif t.state == TrialState.RUNNING:
                pending.append(row)
            elif t.state == TrialState.FAIL:
                failed.append(row)
            if t.state.is_finished():
                finished.append(t.number)
        d, m = self._d, len(signs)
        history = History(np.reshape(u, (-1, d)), np.reshape(losses, (-1, m)),
                          np.asarray(violations, float) if constrained else None, np.reshape(pending, (-1, d)),
                          np.reshape(failed, (-1, d)), np.ones(m, bool))
        return history, tuple(finished)

    # -- the unit box -------------------------------------------------------------------
    def unit(self, params: Mapping[str, Any]) -> np.ndarray:
        """A trial's params as a point of the unit box."""
        return np.array([_to_unit(self._dists[n], params[n]) for n in self._names], float)

    def _params(self, u: Iterable[float]) -> dict[str, Any]:
        return {n: _from_unit(self._dists[n], float(x)) for n, x in zip(self._names, u)}


def _to_unit(dist: BaseDistribution, value: Any) -> float:
    if isinstance(dist, CategoricalDistribution):
        return (dist.choices.index(value) + 0.5) / len(dist.choices)
    assert isinstance(dist, (FloatDistribution, IntDistribution))
    low, high, v = float(dist.low), float(dist.high), float(value)
    if dist.log:
        low, high, v = math.log(low), math.log(high), math.log(v)
    return 0.0 if high == low else (v - low) / (high - low)


def _from_unit(dist: BaseDistribution, x: float) -> Any:
    x = min(max(x, 0.0), 1.0)
    if isinstance(dist, CategoricalDistribution):
        return dist.choices[min(int(x * len(dist.choices)), len(dist.choices) - 1)]
    assert isinstance(dist, (FloatDistribution, IntDistribution))
    low, high = float(dist.low), float(dist.high)
    value = math.exp(math.log(low) + x * (math.log(high) - math.log(low))) if dist.log else low + x * (high - low)
    step = getattr(dist, "step", None)
    if step is not None and not dist.log:
        value = low + round((value - low) / step) * step
    value = min(max(value, low), high)
    return int(round(value)) if isinstance(dist, IntDistribution) else float(value)
