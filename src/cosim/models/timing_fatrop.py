"""One pass of the energy-optimal timing (models/optimal_timing.py) as an optimal-control problem for Fatrop.

The convex problem of a pass is the same as the IPOPT one of
:mod:`models.optimal_timing`; here it is written stage by stage along the path
so that Fatrop (a structure-exploiting interior-point solver shipped with
CasADi) solves it with a Riccati recursion, about 1 ms per iteration instead of
IPOPT's ~5 ms on the whole ~3500-row KKT system.

Stage ``k`` (interval ``k`` of the grid): state ``x_k = (b_k, c_k, T_k)``
(``s_dot^2``, the cone variable ``c <= sqrt(b)``, the time so far), control
``u_k = (a_k, dc_k, dt_k, e_k[7])``.  Every dynamic is linear
(``b_k+1 = b_k + 2 ds a_k``, ``c_k+1 = c_k + dc_k``, ``T_k+1 = T_k + dt_k``) and
every inequality is a convex function ``<= 0`` (or a linear one), so the
problem is a convex NLP; written with the interval time ``2 ds / (c_k + c_k+1)``
inside the dynamics instead, it is not, and Fatrop stalled in about half of the
passes.  Per stage: the energy epigraph (motoring and braking branch: copper
loss ``w tau_mid^2 2 ds / (c_k + c_k+1)`` plus the mechanical energy
``tau_mid q'_mid ds`` over or times eta), accelerations at both interval ends,
torques at start, middle and end, the cone ``c^2 <= b`` and the interval time
``dt >= 2 ds / (c_k + c_k+1)``.  Limits and the duration bound are tightened by
``SHRINK`` (relative) so that Fatrop's constraint tolerance cannot overshoot the
real ones; the caller checks the result against the real limits anyway and
falls back to IPOPT when Fatrop fails.
"""

from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from .panda_model import N_JOINTS as NJ

# per-interval data the pass needs, each (n, 7): columns of the parameter vector in this order
NAMES = ("dq0", "dq2", "ddq0", "ddq2", "m0", "m1", "m2", "c0", "c1", "c2", "g0", "g1", "g2",
         "w_motoring", "w_braking", "mech_motoring", "mech_braking")
NX, NU = 3, 3 + NJ  # x = (b, c, T); u = (a, dc, dt, e[7])
SHRINK = 1e-7  # limits and duration bound a hair inside the real ones (Fatrop's constraint tolerance)
BIG = 1e6  # a bound that is never active (J, s, (rad/s)^2 ...), where one call has a bound and another none
# Fatrop's tolerances: converged at 1e-6, or "acceptable" (1e-4 for 3 iterations): near the optimum the dual
# residual of some passes stalls at ~5e-5 while the timing no longer moves; the caller judges the timing by the
# energy unit's exact model and the limits anyway (measured against IPOPT at 1e-8: benchmarks/optimal_timing.md)
TOL = 1e-6
TOL_ACCEPTABLE = 1e-4
ACCEPTABLE_ITER = 3
MAX_ITER = 60  # a pass takes 15-30 iterations; beyond that it has stalled: IPOPT takes over


@functools.lru_cache(maxsize=8)
def fatrop_solver(n: int) -> ca.Function:
    """Fatrop solver of a pass for ``n`` intervals; parameters = NAMES (vec of (7, n) each), ds, time weight."""
    P = {name: ca.SX.sym(name, NJ, n) for name in NAMES}
    ds = ca.SX.sym("ds", n)
    time_weight = ca.SX.sym("time_weight")
    params = ca.vertcat(*[ca.vec(P[k]) for k in NAMES], ds, time_weight)
    w, g, equality, objective = [], [], [], 0
    xs = [ca.SX.sym(f"x{k}", NX) for k in range(n + 1)]
    for k in range(n):
        b, c, T = xs[k][0], xs[k][1], xs[k][2]
        u = ca.SX.sym(f"u{k}", NU)
        a, dc, dt, e = u[0], u[1], u[2], u[3:]
        col = {name: P[name][:, k] for name in NAMES}
        b1 = b + 2 * ds[k] * a
        w += [xs[k], u]
        g.append(xs[k + 1] - ca.vertcat(b1, c + dc, T + dt))  # dynamics first (Fatrop's stage layout)
        equality += [True] * NX
        if k == 0:
            g.append(T)  # the clock starts at 0
            equality.append(True)
        tau0 = col["m0"] * a + col["c0"] * b + col["g0"]
        tau1 = col["m1"] * a + col["c1"] * (b + ds[k] * a) + col["g1"]
        tau2 = col["m2"] * a + col["c2"] * b1 + col["g2"]
        interval_time = 2 * ds[k] / (2 * c + dc)  # convex in (c_k, c_k+1) for c > 0
        copper = tau1**2 * interval_time  # quadratic over linear: convex
        g += [e - (col["w_motoring"] * copper + col["mech_motoring"] * tau1),
              e - (col["w_braking"] * copper + col["mech_braking"] * tau1),
              col["dq0"] * a + col["ddq0"] * b, col["dq2"] * a + col["ddq2"] * b1,
              tau0, tau1, tau2, c**2 - b, interval_time - dt]
        equality += [False] * (7 * NJ + 2)
        objective += ca.sum1(e)
    w.append(xs[n])
    g.append(xs[n][1] ** 2 - xs[n][0])
    equality.append(False)
    objective += time_weight * xs[n][2]
    nlp = {"x": ca.vertcat(*w), "p": params, "f": objective, "g": ca.vertcat(*g)}
    options = {"structure_detection": "auto", "equality": equality, "print_time": False, "record_time": True,
               "fatrop": {"print_level": 0, "tol": TOL, "max_iter": MAX_ITER,
                          "tol_acceptable": TOL_ACCEPTABLE, "acceptable_iter": ACCEPTABLE_ITER}}
    return ca.nlpsol("timing_fatrop", "fatrop", nlp, options)


def bounds(n: int, lb_b, ub_b, lb_c, lb_e: float, max_duration: float | None, a_max, tau_max, one_branch):
    """(lbx, ubx, lbg, ubg) of :func:`fatrop_solver`'s layout; limits already tightened by the caller.

    ``one_branch`` (n, 7): where the motoring and braking rows of the energy epigraph are the same
    function (a joint that does not move on the interval: no mechanical energy, same copper weight),
    the braking row is left free.  Two identical constraint rows make the KKT system singular, and
    Fatrop then stalls with a regularised Hessian.

    A bound that is infinite in one call and finite in the next is given as ``+-BIG`` instead: Fatrop
    keeps which constraints are bounded from its first call, and a bound that later turns infinite
    (or finite) left it iterating up to 1000 times, ignoring ``max_iter``.
    """
    inf = np.inf
    size = (NX + NU) * n + NX
    lbx, ubx = np.full(size, -inf), np.full(size, inf)
    stage = np.arange(n + 1) * (NX + NU)
    lbx[stage], ubx[stage] = lb_b, np.minimum(ub_b, BIG)
    lbx[stage + 1] = lb_c
    lbx[stage[:-1] + NX + 2] = 0.0  # dt >= 0
    for j in range(NJ):
        lbx[stage[:-1] + NX + 3 + j] = max(lb_e, -BIG)
    ubx[stage[-1] + 2] = BIG if max_duration is None else max_duration
    row_lb = np.concatenate([np.zeros(2 * NJ), -a_max, -a_max, -tau_max, -tau_max, -tau_max, [-inf, -inf]])
    row_ub = np.concatenate([np.full(2 * NJ, inf), a_max, a_max, tau_max, tau_max, tau_max, [0.0, 0.0]])
    lbg, ubg = [], []
    for k in range(n):
        head = [np.zeros(NX)] + ([[0.0]] if k == 0 else [])  # dynamics (+ the clock's start)
        rows = row_lb.copy()
        rows[NJ:2 * NJ][one_branch[k]] = -BIG
        lbg += head + [rows]
        ubg += head + [row_ub]
    return lbx, ubx, np.concatenate(lbg + [[-inf]]), np.concatenate(ubg + [[0.0]])


def initial_guess(b: np.ndarray, ds: np.ndarray, tau1: np.ndarray, values: dict, recuperation: bool) -> np.ndarray:
    """A start near the timing ``b``, strictly inside the cone, interval-time and epigraph constraints."""
    n = len(b) - 1
    c = np.sqrt(b) * (1 - 1e-3)
    dt = 2 * ds / np.maximum(c[:-1] + c[1:], 1e-300)
    copper = tau1**2 * dt[:, None]
    e = np.maximum(values["w_motoring"] * copper + values["mech_motoring"] * tau1,
                   values["w_braking"] * copper + values["mech_braking"] * tau1)
    if not recuperation:
        e = np.maximum(e, 0.0)
    x = np.zeros((n + 1, NX + NU))
    x[:, 0], x[:, 1], x[:, 2] = b, c, np.concatenate([[0.0], np.cumsum(dt * (1 + 1e-3))])
    x[:-1, 3] = np.diff(b) / (2 * ds)
    x[:-1, 4] = np.diff(c)
    x[:-1, 5] = dt * (1 + 1e-3)
    x[:-1, 6:] = e + 1e-3 * np.abs(e) + 1e-4
    return x.ravel()[: (NX + NU) * n + NX]


def timing_of(x: np.ndarray, n: int) -> np.ndarray:
    """The b = s_dot^2 at the grid points of a Fatrop solution."""
    return np.asarray(x).ravel()[0::NX + NU][: n + 1]
