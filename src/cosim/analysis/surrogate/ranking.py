"""The parameters ranked by their influence on a surrogate: Sobol indices of the surrogate's mean (SALib).

The surrogate is cheap, so its indices are estimated from a Saltelli sample of ``n (2 d + 2)`` designs over the
box of the training designs; they describe the surrogate (as good as its Q² says), not the simulation.

**Q² per parameter** (:func:`parameter_q2`) is optiSLang's coefficient of prognosis of a single variable (Most and
Will, "Metamodel of Optimal Prognosis", 2008/2011): ``CoP(x_i) = Q² * ST_i``, the share of the objective's
variance the surrogate predicts (Q², cross-validated) times the share of the surrogate's variance due to the
parameter with all its interactions (ST_i).  For an additive objective it is the drop of Q² when the parameter is
left out (checked in tests/analysis/test_surrogate.py); with interactions the shares add up to more than Q², as total
indices do.  It costs nothing beyond Q² and the indices, where refitting without each parameter would cost d more
cross-validations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cosim.analysis.surrogate.models import Surrogate


@dataclass(frozen=True)
class Influence:
    parameter: str
    first_order: float  # S1: the share of the variance the parameter explains alone
    total: float  # ST: with all its interactions


def sobol_ranking(model: Surrogate, parameters: list[str], n: int = 1024, seed: int = 0) -> list[Influence]:
    """Each parameter's first-order and total Sobol index, most influential (by total index) first."""
    from SALib.analyze import sobol
    from SALib.sample import sobol as sobol_sample

    low = model.scaling.low
    high = low + model.scaling.span
    problem = {"num_vars": len(parameters), "names": list(parameters), "bounds": np.column_stack([low, high]).tolist()}
    sample = sobol_sample.sample(problem, n, calc_second_order=False, seed=seed)
    values = model.predict(sample)[0]
    if np.std(values) == 0:
        return [Influence(p, 0.0, 0.0) for p in parameters]
    result = sobol.analyze(problem, values, calc_second_order=False, seed=seed)
    out = [Influence(p, float(s1), float(st)) for p, s1, st in zip(parameters, result["S1"], result["ST"])]
    return sorted(out, key=lambda i: -i.total)


def parameter_q2(q2: float, influence: Influence) -> float:
    """The coefficient of prognosis of one parameter: ``max(Q², 0) * ST`` (module docstring); NaN without a Q²."""
    if not np.isfinite(q2):
        return float("nan")
    return max(q2, 0.0) * max(influence.total, 0.0)
