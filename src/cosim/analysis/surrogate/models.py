"""The fitted surrogates in their portable form: plain numbers, evaluated with numpy alone.

A surrogate maps a design (one value per parameter) to an objective's prediction and its uncertainty (one
standard deviation).  Both kinds scale the design into the unit box of the training data first
(``(x - low) / span``) and predict the objective standardised (``(y - y_mean) / y_scale``):

- :class:`GaussianProcess`: a kriging predictor with the kernel ``c * k(d) + noise`` over the anisotropic
  distance ``d = |(x - x_i) / length_scales|`` (``k`` a Matern 3/2, Matern 5/2 or squared-exponential shape);
  mean ``sum_i k(x, x_i) alpha_i``, variance ``c + noise - |L^-1 k(x, X)|^2`` with ``L`` the Cholesky factor of
  the training kernel matrix (the variance includes the fitted noise, as scikit-learn's ``return_std`` does).
- :class:`Polynomial`: a ridge regression over the monomials ``prod_j x_j^p_j`` (total degree <= ``degree``);
  its uncertainty is the k-fold root-mean-square prediction error, the same everywhere.

Every number needed lives in :meth:`to_json`, so :func:`model_from_json` rebuilds the model exactly, and the C
code of ``cosim export-surrogate`` (:mod:`cosim.export.surrogate_fmu`) evaluates the same formulas in the same
order: the FMU's outputs equal :meth:`predict`'s.  No pickle: a file from elsewhere runs no code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from cosim.errors import AnalysisError

SHAPES = ("matern32", "matern52", "rbf")  # the kernel shapes the C code knows


# The C library's exp, element by element: numpy's own (SIMD) exp differs from it in the last bit for ~5 % of
# arguments, which the near-singular kernel matrix amplifies to 1e-10 in the prediction; with the same exp as the
# C code of the FMU, Python and FMU agree to 1e-12.
_libm_exp = np.frompyfunc(math.exp, 1, 1)


def exp(values: np.ndarray) -> np.ndarray:
    return _libm_exp(values).astype(float)


def kernel_shape(distance: np.ndarray, shape: str) -> np.ndarray:
    """The kernel's correlation at scaled distance ``distance`` (1 at 0), for one of SHAPES."""
    if shape == "matern32":
        s = math.sqrt(3.0) * distance
        return (1.0 + s) * exp(-s)
    if shape == "matern52":
        s = math.sqrt(5.0) * distance
        return (1.0 + s + s * s / 3.0) * exp(-s)
    if shape == "rbf":
        return exp(-0.5 * distance * distance)
    raise AnalysisError(f"unknown kernel shape '{shape}' (known: {', '.join(SHAPES)})")


@dataclass
class Scaling:
    """Design in the unit box, objective standardised: what both kinds share."""

    low: np.ndarray  # per parameter
    span: np.ndarray  # per parameter, > 0
    y_mean: float
    y_scale: float  # > 0

    def inputs(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x, dtype=float) - self.low) / self.span

    def to_json(self) -> dict[str, Any]:
        return {"low": self.low.tolist(), "span": self.span.tolist(), "y_mean": self.y_mean, "y_scale": self.y_scale}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Scaling:
        return cls(np.asarray(data["low"], float), np.asarray(data["span"], float), float(data["y_mean"]),
                   float(data["y_scale"]))


@dataclass
class GaussianProcess:
    """A fitted Gaussian process (see the module's docstring for the formulas)."""

    scaling: Scaling
    shape: str
    constant: float
    length_scales: np.ndarray  # per parameter
    noise: float
    x_train: np.ndarray  # (n, d), scaled
    alpha: np.ndarray  # (n,)
    cholesky: np.ndarray  # (n, n), lower triangular
    kind = "gp"

    def predict(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(mean, standard deviation) of the objective at the designs ``x`` (rows of parameter values).

        Every sum runs in the order of the C code (``cosim export-surrogate``), term by term, so the FMU's
        outputs equal these up to the last bits of ``exp``; vectorised over the designs only.
        """
        z = self.scaling.inputs(np.atleast_2d(x))
        k = self.cross_kernel(z)  # (m, n)
        n = len(self.alpha)
        mean = np.zeros(len(z))
        for i in range(n):
            mean = mean + k[:, i] * self.alpha[i]
        v = np.empty_like(k)  # L^-1 k, by forward substitution
        for i in range(n):
            s = k[:, i].copy()
            for j in range(i):
                s -= self.cholesky[i, j] * v[:, j]
            v[:, i] = s / self.cholesky[i, i]
        squares = np.zeros(len(z))
        for i in range(n):
            squares = squares + v[:, i] * v[:, i]
        variance = np.maximum(self.constant + self.noise - squares, 0.0)
        return mean * self.scaling.y_scale + self.scaling.y_mean, np.sqrt(variance) * self.scaling.y_scale

    def cross_kernel(self, z: np.ndarray) -> np.ndarray:
        """``c * k(d)`` between scaled designs ``z`` (m, d) and the training designs: (m, n)."""
        squared = np.zeros((len(z), len(self.x_train)))
        for j in range(z.shape[1]):
            step = (z[:, j, None] - self.x_train[None, :, j]) / self.length_scales[j]
            squared = squared + step * step
        return self.constant * kernel_shape(np.sqrt(squared), self.shape)

    def describe(self) -> str:
        scales = ", ".join(f"{s:.3g}" for s in self.length_scales)
        return f"Gaussian process, {self.shape} kernel, length scales (unit box) {scales}, {len(self.alpha)} designs"

    def to_json(self) -> dict[str, Any]:
        return {"kind": self.kind, "scaling": self.scaling.to_json(), "shape": self.shape,
                "constant": self.constant, "length_scales": self.length_scales.tolist(), "noise": self.noise,
                "x_train": self.x_train.tolist(), "alpha": self.alpha.tolist(), "cholesky": self.cholesky.tolist()}


@dataclass
class Polynomial:
    """A fitted polynomial ridge regression (see the module's docstring)."""

    scaling: Scaling
    powers: np.ndarray  # (terms, d) integer exponents
    coefficients: np.ndarray  # (terms,)
    intercept: float
    error: float  # k-fold RMS error, standardised units
    kind = "poly"

    def predict(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(mean, standard deviation) of the objective at the designs ``x`` (rows of parameter values)."""
        z = self.scaling.inputs(np.atleast_2d(x))
        terms = monomials(z, self.powers)
        mean = np.full(len(z), self.intercept)
        for t in range(len(self.coefficients)):  # term by term, in the C code's order
            mean = mean + terms[:, t] * self.coefficients[t]
        std = np.full(len(z), self.error * self.scaling.y_scale)
        return mean * self.scaling.y_scale + self.scaling.y_mean, std

    def describe(self) -> str:
        return f"polynomial of degree {int(self.powers.sum(axis=1).max())}, ridge, {len(self.coefficients)} terms"

    def to_json(self) -> dict[str, Any]:
        return {"kind": self.kind, "scaling": self.scaling.to_json(), "powers": self.powers.tolist(),
                "coefficients": self.coefficients.tolist(), "intercept": self.intercept, "error": self.error}


def monomials(z: np.ndarray, powers: np.ndarray) -> np.ndarray:
    """(m, terms): each term ``prod_j z_j^p_j`` by repeated multiplication (the order the C code uses)."""
    out = np.ones((len(z), len(powers)))
    for t, row in enumerate(powers):
        for j, p in enumerate(row):
            for _ in range(int(p)):
                out[:, t] *= z[:, j]
    return out


Surrogate = GaussianProcess | Polynomial


def model_from_json(data: dict[str, Any]) -> Surrogate:
    """A surrogate from :meth:`to_json`'s dict; AnalysisError when it is not one."""
    try:
        scaling = Scaling.from_json(data["scaling"])
        if data["kind"] == "gp":
            if data["shape"] not in SHAPES:
                raise ValueError(f"unknown kernel shape {data['shape']!r}")
            return GaussianProcess(scaling, str(data["shape"]), float(data["constant"]),
                                   np.asarray(data["length_scales"], float), float(data["noise"]),
                                   np.asarray(data["x_train"], float), np.asarray(data["alpha"], float),
                                   np.asarray(data["cholesky"], float))
        if data["kind"] == "poly":
            return Polynomial(scaling, np.asarray(data["powers"], int), np.asarray(data["coefficients"], float),
                              float(data["intercept"]), float(data["error"]))
        raise ValueError(f"unknown kind {data['kind']!r} (known: gp, poly)")
    except (KeyError, TypeError, ValueError) as exc:
        raise AnalysisError(f"not a surrogate model: {exc}") from None
