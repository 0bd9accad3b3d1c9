"""Where in the design space do designs fail?  A classifier of ok against not-ok rows.

A logistic regression over the monomials of degree <= 2 of the designs in the unit box (balanced classes, so a
rare failure still counts), its quality as the k-fold balanced accuracy (0.5: no better than guessing, 1:
perfect).  Its numbers are stored like the surrogates' (``p_fail(x) = 1 / (1 + exp(-(b + w . m(x))))``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from cosim.analysis.surrogate.models import Scaling, monomials


@dataclass
class FailureModel:
    scaling: Scaling  # the design part only (y_mean 0, y_scale 1)
    powers: np.ndarray
    coefficients: np.ndarray
    intercept: float
    balanced_accuracy: float  # k-fold
    failed: int  # rows not ok when fitted
    total: int

    def probability(self, x: np.ndarray) -> np.ndarray:
        """The probability that each design (row of ``x``) fails."""
        z = self.scaling.inputs(np.atleast_2d(x))
        return 1.0 / (1.0 + np.exp(-(self.intercept + monomials(z, self.powers) @ self.coefficients)))

    def to_json(self) -> dict[str, Any]:
        return {"kind": "logistic", "scaling": self.scaling.to_json(), "powers": self.powers.tolist(),
                "coefficients": self.coefficients.tolist(), "intercept": self.intercept,
                "balanced_accuracy": self.balanced_accuracy, "failed": self.failed, "total": self.total}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> FailureModel:
        return cls(Scaling.from_json(data["scaling"]), np.asarray(data["powers"], int),
                   np.asarray(data["coefficients"], float), float(data["intercept"]),
                   float(data["balanced_accuracy"]), int(data["failed"]), int(data["total"]))


def fit_failures(x: np.ndarray, failed: np.ndarray, folds: int = 5, seed: int = 0) -> FailureModel | None:
    """The classifier of ``failed`` (bool per row of ``x``); None when every row or none failed, or when a
    class has fewer rows than ``folds``."""
    from sklearn.linear_model import LogisticRegression
    from sklearn.metrics import balanced_accuracy_score
    from sklearn.model_selection import StratifiedKFold
    from sklearn.preprocessing import PolynomialFeatures

    n_failed = int(failed.sum())
    if min(n_failed, len(failed) - n_failed) < folds:
        return None
    low, high = x.min(axis=0), x.max(axis=0)
    scaling = Scaling(low, np.where(high > low, high - low, 1.0), 0.0, 1.0)
    z = scaling.inputs(x)
    powers = np.asarray(PolynomialFeatures(2, include_bias=False).fit(z).powers_, int)
    m = monomials(z, powers)

    def classifier() -> Any:
        return LogisticRegression(C=10.0, class_weight="balanced", max_iter=5000)

    predicted = np.empty(len(failed), dtype=bool)
    for train, test in StratifiedKFold(folds, shuffle=True, random_state=seed).split(m, failed):
        predicted[test] = classifier().fit(m[train], failed[train]).predict(m[test])
    fitted = classifier().fit(m, failed)
    return FailureModel(scaling, powers, fitted.coef_.ravel().astype(float), float(fitted.intercept_[0]),
                        float(balanced_accuracy_score(failed, predicted)), n_failed, len(failed))
