"""Fitting one objective's surrogate with scikit-learn, and its k-fold coefficient of prognosis Q².

Q² = 1 - sum (y - y_cv)^2 / sum (y - mean y)^2, where ``y_cv`` is each design's prediction by the surrogate fitted
on the other folds (k-fold cross-validation): 1 is a perfect prognosis, 0 no better than the mean.  ``auto``
fits every candidate (Gaussian processes with a Matern 3/2 and 5/2 kernel, polynomials of degree 1-6 with ridge
regularisation) and keeps the one with the highest Q²; the chosen one is then refitted on all the designs.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cosim.analysis.surrogate.models import GaussianProcess, Polynomial, Scaling, Surrogate
from cosim.errors import AnalysisError

METHODS = ("auto", "gp", "poly")
GP_SHAPES = ("matern32", "matern52")
POLY_DEGREES = (1, 2, 3, 4, 5, 6)
RIDGE_ALPHAS = tuple(10.0 ** np.arange(-10, 3))
FOLDS = 5
RESTARTS = 2  # more optimiser starts from random hyper-parameters: each costs a whole fit


@dataclass
class Fitted:
    """A surrogate and how well it predicts designs it was not fitted on."""

    model: Surrogate
    q2: float  # k-fold coefficient of prognosis
    rmse: float  # k-fold root-mean-square error, in the objective's unit
    candidate: str  # e.g. "gp matern52", "poly 3"
    tried: dict[str, float]  # candidate -> its k-fold Q²
    simulated: list[float] = field(default_factory=list)  # the fitted designs' objective values ...
    cross_validated: list[float] = field(default_factory=list)  # ... and their k-fold predictions (Q²'s plot)


def scaling_of(x: np.ndarray, y: np.ndarray) -> Scaling:
    """The unit-box and standardising scaling of the training designs (a constant column keeps span 1)."""
    low, high = x.min(axis=0), x.max(axis=0)
    span = np.where(high > low, high - low, 1.0)
    scale = float(np.std(y))
    return Scaling(low, span, float(np.mean(y)), scale if scale > 0 else 1.0)


def fit_gp(x: np.ndarray, y: np.ndarray, shape: str, seed: int = 0, restarts: int = RESTARTS,
           start: GaussianProcess | None = None, iterations: int | None = None,
           shortest: float = 1e-3) -> GaussianProcess:
    """A Gaussian process with an anisotropic kernel, hyper-parameters by maximum likelihood (``restarts`` more
    optimiser starts from random hyper-parameters).  ``start``: a fitted process whose hyper-parameters are the
    first start instead of the defaults (unit length scales of 0.5); ``iterations``: at most this many L-BFGS
    iterations per start (None: scikit-learn's default, which can run to thousands on a flat likelihood; 0: the
    start's hyper-parameters as they are, only conditioned on the designs);
    ``shortest``: the lower bound of the length scales in the unit box.  The optimiser of ``--sampler surrogate``
    uses all three to keep its own time small against the simulations' (a length scale near 1e-3 puts kernel
    entries of 1e-300 and below into the Cholesky factorisation, whose subnormal arithmetic is 500 times slower)."""
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, Matern, WhiteKernel

    scaling = scaling_of(x, y)
    z, t = scaling.inputs(x), (y - scaling.y_mean) / scaling.y_scale
    d = x.shape[1]
    bounds = (shortest, 1e3)
    scales, constant, noise = np.full(d, 0.5), 1.0, 1e-6
    if start is not None:  # the same hyper-parameters in this fit's own unit box and standardisation
        scales = np.clip(start.length_scales * start.scaling.span / scaling.span, 2 * shortest, 5e2)
        constant = float(np.clip(start.constant * (start.scaling.y_scale / scaling.y_scale) ** 2, 2e-3, 5e2))
        noise = float(np.clip(start.noise * (start.scaling.y_scale / scaling.y_scale) ** 2, 2e-10, 5e-2))
    shape_kernel = RBF(scales, bounds) if shape == "rbf" else \
        Matern(scales, bounds, nu=1.5 if shape == "matern32" else 2.5)
    # the noise floor keeps the kernel matrix well conditioned (its Cholesky factor goes into the model)
    kernel = ConstantKernel(constant, (1e-3, 1e3)) * shape_kernel + WhiteKernel(noise, (1e-10, 1e-1))
    gp = GaussianProcessRegressor(kernel, alpha=0.0, normalize_y=False, n_restarts_optimizer=restarts,
                                  random_state=seed, optimizer="fmin_l_bfgs_b" if iterations is None
                                  else _limited_lbfgs(iterations) if iterations > 0 else None)
    with warnings.catch_warnings():  # a hyper-parameter at its bound is reported by Q², not by a warning
        warnings.simplefilter("ignore")
        gp.fit(z, t)
    k = gp.kernel_
    return GaussianProcess(scaling, shape, float(k.k1.k1.constant_value),
                           np.broadcast_to(np.asarray(k.k1.k2.length_scale, float), (d,)).copy(),
                           float(k.k2.noise_level), z.copy(), np.asarray(gp.alpha_, float).ravel(),
                           np.asarray(gp.L_, float))


def _limited_lbfgs(iterations: int) -> Any:
    """scikit-learn's hyper-parameter optimiser (L-BFGS-B on the log marginal likelihood), stopped after
    ``iterations``."""
    from scipy.optimize import minimize

    def optimise(objective: Any, theta: np.ndarray, bounds: np.ndarray) -> tuple[np.ndarray, float]:
        result = minimize(objective, theta, method="L-BFGS-B", jac=True, bounds=bounds,
                          options={"maxiter": iterations})
        return result.x, float(result.fun)

    return optimise


def fit_poly(x: np.ndarray, y: np.ndarray, degree: int) -> Polynomial:
    """A ridge regression over the monomials up to ``degree``, its penalty by generalised cross-validation."""
    from sklearn.linear_model import RidgeCV
    from sklearn.preprocessing import PolynomialFeatures

    scaling = scaling_of(x, y)
    z, t = scaling.inputs(x), (y - scaling.y_mean) / scaling.y_scale
    features = PolynomialFeatures(degree, include_bias=False).fit(z)
    ridge = RidgeCV(alphas=RIDGE_ALPHAS).fit(features.transform(z), t)
    from cosim.analysis.surrogate.models import monomials

    powers = np.asarray(features.powers_, int)
    # the model's own monomials (not sklearn's) fix the intercept, so the stored numbers reproduce the fit
    residual = t - monomials(z, powers) @ ridge.coef_
    return Polynomial(scaling, powers, np.asarray(ridge.coef_, float), float(np.mean(residual)), 0.0)


def candidates(method: str) -> list[str]:
    """The candidate names ``method`` chooses among."""
    gps = [f"gp {s}" for s in GP_SHAPES]
    polys = [f"poly {d}" for d in POLY_DEGREES]
    return {"auto": gps + polys, "gp": gps, "poly": polys}[method]


def fit_candidate(name: str, x: np.ndarray, y: np.ndarray, seed: int = 0) -> Surrogate:
    kind, setting = name.split()
    return fit_gp(x, y, setting, seed) if kind == "gp" else fit_poly(x, y, int(setting))


def cross_validated(name: str, x: np.ndarray, y: np.ndarray, folds: int = FOLDS, seed: int = 0) -> np.ndarray:
    """Each design's prediction by the candidate fitted on the other folds."""
    from sklearn.model_selection import KFold

    out = np.empty(len(y))
    for train, test in KFold(min(folds, len(y)), shuffle=True, random_state=seed).split(x):
        out[test] = fit_candidate(name, x[train], y[train], seed).predict(x[test])[0]
    return out


def q_squared(y: np.ndarray, predicted: np.ndarray) -> float:
    """1 - sum of squared errors / sum of squares about the mean (NaN for a constant ``y``)."""
    total = float(np.sum((y - np.mean(y)) ** 2))
    return float("nan") if total == 0 else 1.0 - float(np.sum((y - predicted) ** 2)) / total


def fit_objective(x: np.ndarray, y: np.ndarray, method: str = "auto", folds: int = FOLDS, seed: int = 0) -> Fitted:
    """The best candidate of ``method`` for designs ``x`` (n, d) and objective values ``y`` (n,), by k-fold Q².

    Raises AnalysisError for an unknown method or fewer designs than folds + 1.
    """
    if method not in METHODS:
        raise AnalysisError(f"--method {method}: use one of {', '.join(METHODS)}")
    if len(y) < folds + 1:
        raise AnalysisError(f"{len(y)} designs with a value: a surrogate with {folds}-fold cross-validation needs "
                            f"at least {folds + 1}")
    from threadpoolctl import threadpool_limits

    # the matrices are small (hundreds): BLAS threads only spin, and cost twice the CPU on a shared machine
    with threadpool_limits(limits=1, user_api="blas"):
        return _fit_best(x, y, method, folds, seed)


def _fit_best(x: np.ndarray, y: np.ndarray, method: str, folds: int, seed: int) -> Fitted:
    tried: dict[str, float] = {}
    best: tuple[float, str, np.ndarray] | None = None
    for name in candidates(method):
        if name.startswith("poly") and _terms(x.shape[1], int(name.split()[1])) > 0.8 * len(y) * (folds - 1) / folds:
            continue  # more terms than a fold's designs can determine
        predicted = cross_validated(name, x, y, folds, seed)
        tried[name] = q = q_squared(y, predicted)
        if best is None or (np.isfinite(q) and not q <= best[0]):
            best = (q, name, predicted)
    assert best is not None  # "poly 1" always fits
    q, name, predicted = best
    model = fit_candidate(name, x, y, seed)
    if isinstance(model, Polynomial):
        model.error = float(np.sqrt(np.mean((y - predicted) ** 2))) / model.scaling.y_scale
    return Fitted(model, q, float(np.sqrt(np.mean((y - predicted) ** 2))), name, tried, y.tolist(),
                  predicted.tolist())


def _terms(d: int, degree: int) -> int:
    from math import comb

    return comb(d + degree, degree) - 1
