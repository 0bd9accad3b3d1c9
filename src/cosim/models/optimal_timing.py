"""Energy-optimal timing along a fixed joint path (Verscheure et al. 2009), and the unit that plays it.

The geometric path is the one of the parabolic-blend trajectory
(:func:`models.trajectory.plan_parabolic_blend`): the waypoints with their
blends.  Its path parameter ``s`` is the blend's own time, so ``q(s)``,
``q'(s)`` and ``q''(s)`` are the blend's position, velocity and acceleration
(exact, piecewise quadratic), and the blend's timing is ``s_dot = 1``.
Or the path is given as samples (:class:`models.sampled_path.SampledPath`, a
cubic spline through them, ``s`` = the samples' time): the same planner re-times
it, and where the path does not start or end at rest the timing does (``s_dot = 0``).

Timing ``s(t)`` is found with the convex reformulation of D. Verscheure,
B. Demeulenaere, J. Swevers, J. De Schutter, M. Diehl, "Time-Optimal Path
Tracking for Robots: A Convex Optimization Approach", IEEE TAC 54(10), 2009
(and their time-energy variant): ``b(s) = s_dot^2``, ``a(s) = s_ddot``, so
that ``b' = 2 a`` and the joint quantities are linear in ``(a, b)``::

    qd   = q'(s) s_dot                    |qd|^2 = q'^2 b
    qdd  = q'(s) a + q''(s) b
    tau  = m(s) a + c(s) b + g(s)         m = M q',  c = M q'' + C(q, q') q',  g = gravity

``m``, ``c``, ``g`` come from pinocchio's RNEA at the grid points
(``g = rnea(q, 0, 0)``, ``m = rnea(q, 0, q') - g``, ``c = rnea(q, q', q'') - g``).
On a grid ``s_0 .. s_N`` (the blend's phase boundaries are grid points; ``a``
is constant on each interval, ``b`` linear) the interval's duration is
``2 ds / (c_k + c_k+1)`` with ``c <= sqrt(b)`` (a second-order cone, tight
at the optimum).

Objective: the electric energy of the energy unit's drive model
(:mod:`cosim.models.motor_gear_energy`, thesis 7.2.2) plus ``time_weight`` times the
duration.  Per joint and interval (midpoint torque) the energy is the copper
loss ``R_T i^2 dt`` (convex: quadratic over linear in ``(b, c)``) plus the
mechanical energy ``max(tau q' ds / eta, eta tau q' ds)`` -- motoring costs
1/eta, braking recuperates eta; ``tau q' ds`` is linear in ``(a, b)``, so this
is convex too (without recuperation: also ``>= 0``).  Two things of the drive
model are not convex and are frozen at the current timing: the efficiency
``eta = eta_motor eta_gear(|n_motor|)`` (speed dependent) and whether the
current is the motoring ``tau / (R eta k_m)`` or the braking
``tau eta / (R k_m)`` one.  So the convex problem is solved in passes (a
sequential convex scheme): each pass re-freezes them at the best timing so
far, keeps ``s_dot`` within a trust region around it, and its result is kept
only if the energy unit's exact model, evaluated on the grid (:func:`_energy`),
improves; otherwise the trust region shrinks (and the passes stop when the rejected
timing lies inside the smaller region too: the next pass would return it again).  The first timing is the blend,
uniformly slowed down to the duration bound: the result is never worse than it
by that measure, which agrees with a dense evaluation to ~0.05 %.

Constraints: ``|qd| <= v_max`` (as bounds on ``b``, exact between grid points,
see the code), ``|qdd| <= a_max`` at both ends of every interval (exact: it
is linear in ``s`` inside), ``|tau| <= tau_max`` at the start, middle and end
of every interval (checked on dense sampling by the tests), and optionally
``duration <= max_duration``.  On a sampled path (a cubic spline) ``q'`` is
quadratic and ``q''`` linear inside an interval: the speed and acceleration
limits then hold at the grid points, between them up to the spline's curvature
(exactly on a straight line, as the tests check).

Solvers (both ship with CasADi; each built once per grid size and reused with
new path data as parameters): by default each pass is solved by Fatrop, on the
same convex problem written stage by stage along the path
(:mod:`models.timing_fatrop`: ~1 ms per iteration); its timing is kept only if
it meets every grid limit and the duration bound exactly, else IPOPT (the whole
problem as one NLP, ~5 ms per iteration) solves that pass.  Fatrop stops at a
looser tolerance than IPOPT (1e-6, or "acceptable" 1e-4, against 1e-8), so the
passes take slightly different steps: the energy agrees with IPOPT alone
(``solver="ipopt"``) to about the passes' own stopping tolerance
(``TOLERANCE``; measured: benchmarks/optimal_timing.md).  The blend's own
duration is usually its path's minimum time under the limits, so "at most the
blend's duration" returns the blend's timing: with Fatrop the planner first asks
for the minimum time, and if the bound leaves no room (``NO_ROOM``) keeps the
blend without any pass.

Raises :class:`TimingInfeasible` when no timing within the limits (and the
duration bound) exists, :class:`RuntimeError` when IPOPT fails otherwise.
"""

from __future__ import annotations

import bisect
import functools
import math
import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import pinocchio as pin

from cosim.units.protocol import Variable

from . import timing_fatrop
from .motor_gear_energy import RAD_PER_S_TO_RPM
from .panda_model import FRANKA_DOC_LIMITS, N_JOINTS, cached_model, payload_key
from .sampled_path import SampledPath
from .trajectory import ParabolicBlendTrajectory, TrajectoryGenerator, plan_parabolic_blend

JointPath = ParabolicBlendTrajectory | SampledPath  # a geometric path q(s): sample(s) -> (q, q', q'')

NJ = N_JOINTS
# fractions of the limits the grid constraints use (1: none needed so far, see the module docstring)
MARGINS = {"velocity": 1.0, "acceleration": 1.0, "torque": 1.0}
DEFAULT_GRID = 60
TRUST_RADIUS = 0.3  # first trust region: s_dot within +-30 % of the best timing so far
TOLERANCE = 1e-4  # stop when a pass improves the energy by less than this fraction
NO_ROOM = 1e-6  # a duration bound within this fraction of the path's minimum time leaves no room: keep the start


@dataclass(frozen=True)
class DriveParameters:
    """The energy unit's parameters (models/motor_gear_energy.py), arrays per joint."""

    gear_ratio: np.ndarray = field(default_factory=lambda: np.full(NJ, 100.0))
    r_terminal: np.ndarray = field(default_factory=lambda: np.full(NJ, 0.22))
    k_m: np.ndarray = field(default_factory=lambda: np.full(NJ, 0.134))
    eta_motor: np.ndarray = field(default_factory=lambda: np.full(NJ, 0.92))
    eta_gear_speed: np.ndarray = field(default_factory=lambda: np.array([500.0, 1000.0, 2000.0, 3000.0]))
    eta_gear_value: np.ndarray = field(default_factory=lambda: np.array([0.75, 0.69, 0.63, 0.58]))
    recuperation: bool = True

    def efficiency(self, omega: np.ndarray) -> np.ndarray:
        """eta_motor * eta_gear(|n_motor|) at joint speeds ``omega`` (rad/s, shape (..., 7))."""
        n_motor = np.abs(omega) * self.gear_ratio * RAD_PER_S_TO_RPM
        return self.eta_motor * np.interp(n_motor, self.eta_gear_speed, self.eta_gear_value)

    def electric_power(self, tau: np.ndarray, omega: np.ndarray) -> np.ndarray:
        """p_el per joint (W) exactly as the energy unit computes it (shape (..., 7))."""
        eta = self.efficiency(omega)
        braking = tau * omega < 0.0
        tau_motor = np.where(braking, tau * eta / self.gear_ratio, tau / (self.gear_ratio * eta))
        p = self.r_terminal * (tau_motor / self.k_m) ** 2 + tau_motor * omega * self.gear_ratio
        return p if self.recuperation else np.maximum(p, 0.0)


class TimingInfeasible(ValueError):
    """No timing of the path meets the limits (and the duration bound)."""


# --------------------------------------------------------------------------- path data


def _grid(blend: JointPath, n_grid: int) -> np.ndarray:
    """Grid in the blend's time: every phase boundary, each phase split by its share of ``n_grid``."""
    bounds = np.append(blend.phase_start, blend.duration)
    lengths = np.diff(bounds)
    keep = lengths > 1e-12
    bounds = np.append(bounds[:-1][keep], blend.duration)
    lengths = lengths[keep]
    if n_grid < len(lengths):
        raise ValueError(f"n_grid = {n_grid} is smaller than the path's {len(lengths)} phases")
    # exactly n_grid intervals (one NLP per grid size): at least one per phase, the rest by largest remainder
    share = lengths / lengths.sum() * (n_grid - len(lengths))
    counts = 1 + np.floor(share).astype(int)
    counts[np.argsort(share - np.floor(share))[::-1][: n_grid - counts.sum()]] += 1
    pieces = [np.linspace(bounds[i], bounds[i + 1], counts[i] + 1)[:-1] for i in range(len(lengths))]
    return np.append(np.concatenate(pieces), blend.duration)


@dataclass(frozen=True)
class PathData:
    """The path on a grid: per interval the start, middle and end values of q, q', q'' (from inside it)."""

    s: np.ndarray  # (N+1,)
    q: np.ndarray  # (N, 3, 7): start, mid, end of each interval
    dq: np.ndarray  # (N, 3, 7)
    ddq: np.ndarray  # (N, 3, 7)
    m: np.ndarray  # (N, 3, 7) torque coefficients of s_ddot
    c: np.ndarray  # (N, 3, 7) ... of s_dot^2
    g: np.ndarray  # (N, 3, 7) ... constant (gravity)

    @property
    def n(self) -> int:
        return len(self.s) - 1


def path_data(blend: JointPath, model: pin.Model, n_grid: int) -> PathData:
    """Sample the path on the grid and the torque coefficients there (pinocchio RNEA)."""
    s = _grid(blend, n_grid)
    n = len(s) - 1
    data = model.createData()
    q, dq, ddq, m, c, g = (np.empty((n, 3, NJ)) for _ in range(6))
    zero = np.zeros(NJ)
    for k in range(n):
        # the ends a hair inside the interval: the values from inside it (the blend's q'' jumps at
        # phase boundaries, which are grid points; sample() rests before 0 and after the end)
        points = (np.nextafter(s[k], np.inf), 0.5 * (s[k] + s[k + 1]), np.nextafter(s[k + 1], -np.inf))
        for p, point in enumerate(points):
            q[k, p], dq[k, p], ddq[k, p] = blend.sample(point)
            g[k, p] = pin.rnea(model, data, q[k, p], zero, zero)
            m[k, p] = pin.rnea(model, data, q[k, p], zero, dq[k, p]) - g[k, p]
            c[k, p] = pin.rnea(model, data, q[k, p], dq[k, p], ddq[k, p]) - g[k, p]
    return PathData(s=s, q=q, dq=dq, ddq=ddq, m=m, c=c, g=g)


# --------------------------------------------------------------------------- the NLP


@functools.lru_cache(maxsize=8)
def _nlp(n: int, recuperation: bool):
    """IPOPT solver for ``n`` intervals; parameters carry the path, limits go in the bounds."""
    b = ca.SX.sym("b", n + 1)
    c = ca.SX.sym("c", n + 1)  # c <= sqrt(b) (second-order cone, tight at the optimum)
    e = ca.SX.sym("e", NJ, n)  # energy per joint and interval (epigraph variables)
    P = {name: ca.SX.sym(name, NJ, n) for name in
         ("dq0", "dq1", "dq2", "ddq0", "ddq2", "m0", "m1", "m2", "c0", "c1", "c2", "g0", "g1", "g2",
          "w_motoring", "w_braking", "inv_eta", "eta")}
    ds = ca.SX.sym("ds", n)
    time_weight = ca.SX.sym("time_weight")
    params = ca.vertcat(*[ca.vec(P[k]) for k in P], ds, time_weight)

    ones = ca.DM.ones(NJ, 1)
    b0, b1 = b[:n].T, b[1:].T
    a = (b1 - b0) / (2 * ds.T)
    row = lambda v: ca.mtimes(ones, v)  # noqa: E731 - broadcast a (1, n) row to all joints
    tau0 = P["m0"] * row(a) + P["c0"] * row(b0) + P["g0"]
    tau1 = P["m1"] * row(a) + P["c1"] * row((b0 + b1) / 2) + P["g1"]
    tau2 = P["m2"] * row(a) + P["c2"] * row(b1) + P["g2"]
    dt = 2 * ds.T / (c[:n].T + c[1:].T)
    duration = ca.sum2(dt)
    copper = tau1**2 * row(dt)  # integral of tau^2 over the interval (midpoint torque)
    mech = tau1 * P["dq1"] * row(ds.T)  # integral of tau * qd dt = tau q' ds
    g_motoring = e - (P["w_motoring"] * copper + P["inv_eta"] * mech)
    g_braking = e - (P["w_braking"] * copper + P["eta"] * mech)
    acc0 = P["dq0"] * row(a) + P["ddq0"] * row(b0)
    acc2 = P["dq2"] * row(a) + P["ddq2"] * row(b1)
    cone = c**2 - b
    g = ca.vertcat(ca.vec(g_motoring), ca.vec(g_braking), ca.vec(acc0), ca.vec(acc2),
                   ca.vec(tau0), ca.vec(tau1), ca.vec(tau2), cone, duration)
    x = ca.vertcat(b, c, ca.vec(e))
    objective = ca.sum1(ca.sum2(e)) + time_weight * duration
    solver = ca.nlpsol("timing", "ipopt", {"x": x, "p": params, "f": objective, "g": g},
                       {"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False, "record_time": True,
                        "ipopt.tol": 1e-8, "ipopt.max_iter": 500, "ipopt.mu_strategy": "adaptive"})
    sizes = {"n": n, "x": x.numel(), "g": g.numel()}
    return solver, tuple(P), sizes


# --------------------------------------------------------------------------- the result


@dataclass(frozen=True)
class OptimalTiming:
    """A timing ``s(t)`` of a path (the blend's or a sampled one); ``sample`` like :class:`ParabolicBlendTrajectory`."""

    blend: JointPath
    s: np.ndarray  # grid (N+1), in the blend's time
    b: np.ndarray  # s_dot^2 at the grid points
    t: np.ndarray  # time at the grid points (t[0] = 0)
    planned_energy: float  # the optimised energy bound (J)
    solve_time: float  # s, all passes, path data included
    passes: int
    # CasADi's own counters summed over the passes (Fatrop's and IPOPT's): iterations, the solvers' CPU / wall
    # time (t_proc_total, t_wall_total) and the part of it in CasADi's function evaluations (t_proc_nlp_*);
    # fatrop_passes / fatrop_iterations (the minimum-time check included) and ipopt_passes
    solver_stats: dict = field(default_factory=dict, compare=False)
    _times: list = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_times", self.t.tolist())

    @property
    def duration(self) -> float:
        return float(self.t[-1])

    @property
    def waypoints(self) -> np.ndarray:
        return self.blend.waypoints

    def path_state(self, t: float) -> tuple[float, float, float]:
        """(s, s_dot, s_ddot) at time ``t``; rest before 0 and after the end."""
        if t <= 0.0:
            return 0.0, 0.0, 0.0
        if t >= self.duration:
            return float(self.s[-1]), 0.0, 0.0
        k = min(bisect.bisect_right(self._times, t) - 1, len(self.s) - 2)
        ds = self.s[k + 1] - self.s[k]
        acc = (self.b[k + 1] - self.b[k]) / (2 * ds)
        tau = t - self._times[k]
        v0 = math.sqrt(self.b[k])
        s = self.s[k] + v0 * tau + 0.5 * acc * tau * tau
        return min(max(s, self.s[k]), self.s[k + 1]), v0 + acc * tau, acc

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Joint position, velocity and acceleration at time ``t`` (s from the start)."""
        if t <= 0.0 or t >= self.duration:
            q = self.blend.waypoints[0] if t <= 0.0 else self.blend.waypoints[-1]
            return q.copy(), np.zeros(NJ), np.zeros(NJ)
        s, sd, sdd = self.path_state(t)
        q, dq, ddq = self.blend.sample(s)
        return q, dq * sd, ddq * sd * sd + dq * sdd

    def sample_many(self, times) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        out = [self.sample(float(t)) for t in np.asarray(times, dtype=float)]
        return tuple(np.array(x) for x in zip(*out))  # type: ignore[return-value]


def _braking(path: PathData, b: np.ndarray) -> np.ndarray:
    """(n, 7): does the joint brake (tau * qd < 0) in the middle of each interval at the timing b?"""
    ds = np.diff(path.s)
    tau = path.m[:, 1] * (np.diff(b) / (2 * ds))[:, None] + path.c[:, 1] * (0.5 * (b[:-1] + b[1:]))[:, None] + path.g[:, 1]
    return tau * path.dq[:, 1] < 0.0


def plan_optimal_timing(blend: JointPath, model: pin.Model, v_max, a_max, tau_max,
                        drive: DriveParameters | None = None, max_duration: float | None = None,
                        time_weight: float = 0.0, n_grid: int = DEFAULT_GRID,
                        max_passes: int = 4, solver: str = "fatrop") -> OptimalTiming:
    """The timing of ``blend``'s path minimising energy + ``time_weight`` (J/s) x duration,
    with the duration at most ``max_duration`` (s; None: no bound, then ``time_weight`` > 0).

    ``blend``: the path, a :class:`ParabolicBlendTrajectory` or a
    :class:`models.sampled_path.SampledPath`; where the path does not start (end)
    at rest (``q' != 0``), the timing does (``s_dot = 0`` there).
    ``v_max``, ``a_max``, ``tau_max``: per-joint limits.  ``solver``: "fatrop" (default, IPOPT
    where a Fatrop pass fails) or "ipopt" (every pass; the planner before Fatrop).  Raises
    :class:`TimingInfeasible` when the limits (and the duration) cannot be met,
    ValueError for bad arguments, RuntimeError when IPOPT fails otherwise.
    """
    start = time.perf_counter()
    drive = drive or DriveParameters()
    v_max, a_max, tau_max = (np.asarray(x, dtype=float).reshape(NJ) for x in (v_max, a_max, tau_max))
    if not (np.all(v_max > 0) and np.all(a_max > 0) and np.all(tau_max > 0)):
        raise ValueError("v_max, a_max and tau_max must be > 0")
    if max_duration is not None and not (math.isfinite(max_duration) and max_duration > 0):
        raise ValueError(f"max_duration must be a finite number > 0, got {max_duration}")
    if not (math.isfinite(time_weight) and time_weight >= 0):
        raise ValueError(f"time_weight must be >= 0 (J/s), got {time_weight}")
    if max_duration is None and time_weight == 0:
        raise ValueError("without a duration bound (max_duration) the time weight must be > 0")
    if blend.duration <= 0:  # a single waypoint: nothing to time
        return OptimalTiming(blend, np.zeros(2), np.zeros(2), np.zeros(2), 0.0, time.perf_counter() - start, 0)
    path = path_data(blend, model, n_grid)
    n = path.n
    if solver not in ("fatrop", "ipopt"):
        raise ValueError(f"solver must be 'fatrop' or 'ipopt', got {solver!r}")
    ipopt, names, sizes = _nlp(n, bool(drive.recuperation))
    ds = np.diff(path.s)
    w = drive.r_terminal / (drive.gear_ratio * drive.k_m) ** 2  # copper loss per (joint torque)^2, eta = 1

    # bounds: x = [b, c, e]; g = [motoring, braking, acc0, acc2, tau0, tau1, tau2, cone, duration]
    inf = np.inf
    lbx = np.concatenate([np.zeros(n + 1), np.zeros(n + 1), np.full(NJ * n, 0.0 if not drive.recuperation else -inf)])
    ubx = np.full(sizes["x"], inf)
    lbx[n + 2:2 * n + 1] = 1e-6  # interior path speeds: strictly forward
    # speed limits as bounds on b: q'^2 is convex and b linear in s on an interval, so on it
    # q'^2 b <= max(q'(start)^2, q'(end)^2) max(b(start), b(end)): the limit holds between grid points too
    dq_peak = np.maximum(path.dq[:, 0] ** 2, path.dq[:, 2] ** 2)  # (n, 7)
    with np.errstate(divide="ignore"):
        b_cap = np.min((v_max * MARGINS["velocity"]) ** 2 / dq_peak, axis=1)  # per interval
    ubx[: n + 1] = np.minimum(np.append(b_cap, np.inf), np.append(np.inf, b_cap))
    # at rest at both ends: the blend's path is (q' = 0 there), a sampled one may not be: then s_dot = 0
    moving = 1e-9 * np.max(np.abs(path.dq))
    ubx[0] = 0.0 if np.max(np.abs(path.dq[0, 0])) > moving else ubx[0]
    ubx[n] = 0.0 if np.max(np.abs(path.dq[-1, 2])) > moving else ubx[n]
    col = lambda v, k: np.tile(v, k)  # noqa: E731 - per-joint bounds for k columns (column-major vec)
    acc_bound = col(a_max * MARGINS["acceleration"], n)
    tau_bound = col(tau_max * MARGINS["torque"], n)
    lbg = np.concatenate([np.zeros(2 * NJ * n), -acc_bound, -acc_bound,
                          -tau_bound, -tau_bound, -tau_bound, np.full(n + 1, -inf), [0.0]])
    ubg = np.concatenate([np.full(2 * NJ * n, inf), acc_bound, acc_bound,
                          tau_bound, tau_bound, tau_bound, np.zeros(n + 1),
                          # a hair inside the bound, so IPOPT's constraint tolerance cannot overshoot it
                          [max_duration * (1 - 1e-7) if max_duration else inf]])

    # start from the blend, uniformly slowed down to the duration bound if that is longer (s_dot constant)
    b = np.full(n + 1, min(1.0, blend.duration / max_duration) ** 2 if max_duration else 1.0)
    cap = ubx[: n + 1].copy()
    # (the slowed blend lasts the bound exactly: compare with a rounding tolerance)
    feasible = _within_limits(path, b, cap, a_max, tau_max) and (
        max_duration is None or _duration(path, b) <= max_duration * (1 + 1e-9))
    best = (_energy(path, drive, b) + time_weight * _duration(path, b), b) if feasible else (math.inf, b)
    x0 = np.concatenate([b, np.sqrt(b), np.zeros(NJ * n)])
    radius, passes = TRUST_RADIUS, 0
    solver_stats = {"iterations": 0, "t_proc_total": 0.0, "t_wall_total": 0.0, "t_proc_functions": 0.0,
                    "fatrop_passes": 0, "fatrop_iterations": 0, "ipopt_passes": 0}
    if solver == "fatrop" and feasible and max_duration is not None and max_duration <= blend.duration * (1 + 1e-9):
        # a bound at the full-speed path's own duration: usually nothing is faster (the blend is its path's minimum
        # time), and the start is then the only timing within the bound -- a problem without interior, on which
        # both interior-point solvers only slowly find that out.  Ask Fatrop for the minimum time first.
        shortest = _minimum_time(path, drive, lbx, ubx, lbx[n + 1:2 * n + 2], a_max, tau_max, cap, solver_stats)
        if shortest is not None and shortest >= max_duration * (1 - NO_ROOM):
            max_passes = 0  # no room: keep the start
    for passes in range(1, max_passes + 1):
        # the convex model at the current timing: efficiencies at its speeds, copper loss of the
        # current its power directions need (motoring 1/eta^2, braking eta^2)
        speed = np.sqrt(0.5 * (b[:-1] + b[1:]))
        eta = drive.efficiency(path.dq[:, 1, :] * speed[:, None])  # (n, 7)
        w_copper = np.where(_braking(path, b), w * eta**2, w / eta**2)
        values = {"dq0": path.dq[:, 0], "dq1": path.dq[:, 1], "dq2": path.dq[:, 2], "ddq0": path.ddq[:, 0], "ddq2": path.ddq[:, 2],
                  "m0": path.m[:, 0], "m1": path.m[:, 1], "m2": path.m[:, 2],
                  "c0": path.c[:, 0], "c1": path.c[:, 1], "c2": path.c[:, 2],
                  "g0": path.g[:, 0], "g1": path.g[:, 1], "g2": path.g[:, 2],
                  "w_motoring": w_copper, "w_braking": w_copper, "inv_eta": 1.0 / eta, "eta": eta}
        lbx_pass, ubx_pass = lbx.copy(), ubx.copy()
        if math.isfinite(best[0]):  # trust region: s_dot within (1 -/+ radius) of the best timing so far
            lbx_pass[: n + 1], ubx_pass[: n + 1] = _trust_region(best[1], radius, cap)
        candidate = None
        if solver == "fatrop":  # fast; its result is checked there, and IPOPT solves the pass if it fails
            candidate = _fatrop_pass(path, drive, values, b, lbx_pass, ubx_pass, lbx[n + 1:2 * n + 2], max_duration,
                                     a_max, tau_max, time_weight, cap, solver_stats)
            x = None if candidate is None else np.concatenate([candidate, np.sqrt(candidate), np.zeros(NJ * n)])
        if candidate is None:
            outcome = _ipopt_pass(ipopt, names, values, ds, time_weight, x0, lbx_pass, ubx_pass, lbg, ubg, solver_stats)
            if isinstance(outcome, str):  # IPOPT failed: its status
                if outcome in ("Infeasible_Problem_Detected", "Restoration_Failed") and not math.isfinite(best[0]):
                    raise TimingInfeasible(f"no timing of the path meets the velocity, acceleration and torque limits"
                                           f"{f' within {max_duration:.4g} s' if max_duration else ''} (IPOPT: {outcome})")
                if not math.isfinite(best[0]):
                    raise RuntimeError(f"IPOPT did not solve the timing problem: {outcome}")
                radius /= 2  # keep the best timing so far; try a smaller step
                continue
            candidate, x = np.clip(outcome[0], 0.0, cap), outcome[1]
        value = _energy(path, drive, candidate) + time_weight * _duration(path, candidate)
        improvement = best[0] - value
        if improvement > 0 or not math.isfinite(best[0]):
            best, b, x0 = (value, candidate), candidate, x  # x: the next IPOPT pass's start
            radius = min(2 * radius, 0.9) if math.isfinite(improvement) else radius
            if math.isfinite(improvement) and improvement < TOLERANCE * abs(value):
                break
        else:  # the model promised more than the true energy gives: a smaller step
            radius /= 2
            lower, upper = _trust_region(best[1], radius, cap)
            if radius < 1e-3 or (np.all(candidate >= lower) and np.all(candidate <= upper)):
                # the next pass would solve the same convex problem on a smaller region that still
                # holds this candidate, its optimum there: it would return it and be rejected again
                # (at a duration bound the path cannot beat, the first pass returns the start itself)
                break
    b = best[1]
    root = np.sqrt(b)
    t = np.concatenate([[0.0], np.cumsum(2 * ds / np.maximum(root[:-1] + root[1:], 1e-300))])
    return OptimalTiming(blend=blend, s=path.s, b=b, t=t, planned_energy=_energy(path, drive, b),
                         solve_time=time.perf_counter() - start, passes=passes, solver_stats=solver_stats)


def _minimum_time(path: PathData, drive: DriveParameters, lbx: np.ndarray, ubx: np.ndarray, lb_c: np.ndarray,
                  a_max: np.ndarray, tau_max: np.ndarray, cap: np.ndarray, stats: dict) -> float | None:
    """The path's minimum time under the grid limits (Fatrop, no energy terms), or None if Fatrop fails."""
    n = path.n
    zero = np.zeros((n, NJ))
    values = {"dq0": path.dq[:, 0], "dq1": path.dq[:, 1], "dq2": path.dq[:, 2], "ddq0": path.ddq[:, 0],
              "ddq2": path.ddq[:, 2], "m0": path.m[:, 0], "m1": path.m[:, 1], "m2": path.m[:, 2],
              "c0": path.c[:, 0], "c1": path.c[:, 1], "c2": path.c[:, 2], "g0": path.g[:, 0], "g1": path.g[:, 1],
              "g2": path.g[:, 2], "w_motoring": zero, "w_braking": zero, "inv_eta": zero, "eta": zero}
    start = np.minimum(np.ones(n + 1), cap)
    fastest = _fatrop_pass(path, drive, values, start, lbx, ubx, lb_c, None, a_max, tau_max, 1.0, cap, stats)
    return None if fastest is None else _duration(path, fastest)


def _ipopt_pass(ipopt, names, values, ds, time_weight, x0, lbx, ubx, lbg, ubg, stats: dict):
    """One pass with IPOPT: (b, x) of its solution, or its return status (str) when it failed."""
    p = np.concatenate([values[k].ravel() for k in names] + [ds, [time_weight]])  # (n, 7).ravel() = vec of (7, n)
    result = ipopt(x0=x0, p=p, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
    _add_stats(stats, ipopt.stats())
    stats["ipopt_passes"] += 1
    if not ipopt.stats()["success"]:
        return str(ipopt.stats()["return_status"])
    x = np.array(result["x"]).ravel()
    return x[: len(ds) + 1], x


def _fatrop_pass(path: PathData, drive: DriveParameters, values: dict, b: np.ndarray, lbx: np.ndarray, ubx: np.ndarray,
                 lb_c: np.ndarray, max_duration: float | None, a_max: np.ndarray, tau_max: np.ndarray,
                 time_weight: float, cap: np.ndarray, stats: dict) -> np.ndarray | None:
    """One pass with Fatrop (models/timing_fatrop.py): its timing b if it meets every grid limit
    and the duration bound, else None (the caller then solves the pass with IPOPT)."""
    n = path.n
    ds = np.diff(path.s)
    lb_b, ub_b = lbx[: n + 1], ubx[: n + 1]
    data = dict(values, mech_motoring=path.dq[:, 1] * ds[:, None] * values["inv_eta"],
                mech_braking=path.dq[:, 1] * ds[:, None] * values["eta"])
    p = np.concatenate([data[k].ravel() for k in timing_fatrop.NAMES] + [ds, [time_weight]])
    shrink = 1 - timing_fatrop.SHRINK
    bounds = timing_fatrop.bounds(n, lb_b, ub_b * shrink, lb_c, lbx[-1], max_duration * shrink if max_duration else None,
                                  a_max * MARGINS["acceleration"] * shrink, tau_max * MARGINS["torque"] * shrink,
                                  one_branch=(data["mech_motoring"] == data["mech_braking"])
                                  & (data["w_motoring"] == data["w_braking"]))
    start = np.clip(b, lb_b, ub_b * shrink)
    a = (np.diff(start) / (2 * ds))[:, None]
    tau1 = path.m[:, 1] * a + path.c[:, 1] * (0.5 * (start[:-1] + start[1:]))[:, None] + path.g[:, 1]
    solver = timing_fatrop.fatrop_solver(n)
    result = solver(x0=timing_fatrop.initial_guess(start, ds, tau1, data, drive.recuperation), p=p,
                    lbx=bounds[0], ubx=bounds[1], lbg=bounds[2], ubg=bounds[3])
    solver_stats = solver.stats()
    _add_stats(stats, solver_stats)
    stats["fatrop_passes"] += 1
    stats["fatrop_iterations"] += int(solver_stats.get("iter_count", 0))
    candidate = np.clip(timing_fatrop.timing_of(result["x"], n), 0.0, cap)
    # success, or stopped before the iteration limit (the "acceptable" tolerance reports the same failure status
    # as the limit; the count tells them apart); an early stop for another reason is judged the same way: by the
    # real limits here and by the exact energy in the caller, like every candidate
    stopped = solver_stats["success"] or int(solver_stats.get("iter_count", 0)) < timing_fatrop.MAX_ITER
    if not stopped or not _within_limits(path, candidate, cap, a_max, tau_max) or (
            max_duration is not None and _duration(path, candidate) > max_duration):
        return None
    return candidate


def _add_stats(total: dict, stats: dict) -> None:
    total["iterations"] += int(stats.get("iter_count", 0))
    for key in ("t_proc_total", "t_wall_total"):
        total[key] += float(stats.get(key, 0.0))
    total["t_proc_functions"] += sum(float(v) for k, v in stats.items() if k.startswith("t_proc_nlp_"))


def _trust_region(centre: np.ndarray, radius: float, cap: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bounds on b of the trust region: s_dot within (1 -/+ radius) of ``centre``'s, b at most ``cap``."""
    return np.minimum((1 - radius) ** 2 * centre, cap), np.minimum((1 + radius) ** 2 * centre, cap)


def _duration(path: PathData, b: np.ndarray) -> float:
    root = np.sqrt(b)
    return float(np.sum(2 * np.diff(path.s) / np.maximum(root[:-1] + root[1:], 1e-300)))


def _energy(path: PathData, drive: DriveParameters, b: np.ndarray) -> float:
    """The energy unit's electric energy of the timing ``b`` (midpoint rule on the grid, exact drive model)."""
    ds = np.diff(path.s)
    speed = np.sqrt(0.5 * (b[:-1] + b[1:]))
    tau = path.m[:, 1] * (np.diff(b) / (2 * ds))[:, None] + path.c[:, 1] * (speed**2)[:, None] + path.g[:, 1]
    root = np.sqrt(b)
    dt = 2 * ds / np.maximum(root[:-1] + root[1:], 1e-300)
    return float(np.sum(drive.electric_power(tau, path.dq[:, 1] * speed[:, None]) * dt[:, None]))


def _within_limits(path: PathData, b: np.ndarray, cap: np.ndarray, a_max: np.ndarray, tau_max: np.ndarray) -> bool:
    """Does the timing ``b`` meet the grid constraints (speed caps, accelerations, torques)?"""
    tol = 1 + 1e-9
    if np.any(b > cap * tol):
        return False
    a = (np.diff(b) / (2 * np.diff(path.s)))[:, None]
    ends = ((0, b[:-1]), (2, b[1:]))
    if any(np.any(np.abs(path.dq[:, k] * a + path.ddq[:, k] * bk[:, None]) > a_max * tol) for k, bk in ends):
        return False
    points = ((0, b[:-1]), (1, 0.5 * (b[:-1] + b[1:])), (2, b[1:]))
    return not any(np.any(np.abs(path.m[:, k] * a + path.c[:, k] * bk[:, None] + path.g[:, k]) > tau_max * tol)
                   for k, bk in points)


# --------------------------------------------------------------------------- the unit


def _array(name, start, unit, description, size=NJ):
    return Variable(name, "parameter", unit=unit, start=tuple(start), shape=(size,), description=description,
                    variability="fixed")


class OptimalTimingTrajectory(TrajectoryGenerator):
    """The trajectory generator's path, timed for least electric energy (+ a weight on time).

    Same ports as :class:`models.trajectory.TrajectoryGenerator` (so a spec
    swaps it in with one line: ``"python": "models.optimal_timing:OptimalTimingTrajectory"``)
    plus the limits and drive parameters the optimisation needs (defaults: Franka
    documentation torques, the energy unit's defaults, no payload) and its
    settings: ``time_weight`` (J/s) and ``max_duration_factor`` (the duration
    is at most this times the blend's; default 1: the least energy at most the
    blend's duration) / ``max_duration`` (s, 0 = none; the tighter bound wins).
    ``optimize = false`` plays the reference of a comparison instead: the
    parabolic blend uniformly slowed down to the duration bound.  Outputs
    added: ``blend_duration`` (the full-speed blend's), ``planned_energy`` (the
    energy on the planning grid, J) and ``solve_time`` (s).
    ``path_file``: a path given as samples instead (a table as ``cosim run --out``
    writes it, e.g. a recorded ``traj.q_ref``; see :class:`models.sampled_path.SampledPath`):
    the waypoints are then not used, and "the blend" above means the samples' own timing.
    An infeasible timing (limits, bound) raises :class:`TimingInfeasible`: the run fails with its message.
    """

    D = DriveParameters()
    variables = TrajectoryGenerator.variables + (
        _array("tau_max", FRANKA_DOC_LIMITS.tau_max, "N.m", "joint torque limits (Franka documentation)"),
        Variable("payload_mass", "parameter", unit="kg", start=0.0, min=0.0, variability="fixed",
                 description="rigid payload fixed to the hand (as the robot unit's)"),
        Variable("payload_com", "parameter", unit="m", start=0.0, shape=(3,), variability="fixed",
                 description="payload centre of mass in the panda_hand_tcp frame"),
        Variable("payload_inertia", "parameter", unit="kg.m2", start=0.0, shape=(6,), variability="fixed",
                 description="payload Ixx Iyy Izz Ixy Ixz Iyz about its COM, TCP axes"),
        _array("gear_ratio", D.gear_ratio, None, "gear ratio R (energy unit)"),
        _array("r_terminal", D.r_terminal, "Ohm", "terminal resistance R_T (energy unit)"),
        _array("k_m", D.k_m, "N.m/A", "torque constant (energy unit)"),
        _array("eta_motor", D.eta_motor, None, "motor efficiency (energy unit)"),
        _array("eta_gear_speed", D.eta_gear_speed, "rpm", "gear-efficiency table speeds (energy unit)", size=4),
        _array("eta_gear_value", D.eta_gear_value, None, "gear-efficiency table values (energy unit)", size=4),
        Variable("recuperation", "parameter", type="Boolean", start=True, variability="fixed",
                 description="braking power is fed back (energy unit)"),
        Variable("time_weight", "parameter", unit="J/s", start=0.0, min=0.0, variability="fixed",
                 description="objective = energy + time_weight * duration"),
        Variable("max_duration_factor", "parameter", start=1.0, min=0.0, variability="fixed",
                 description="duration <= this x the parabolic blend's (0: no such bound)"),
        Variable("max_duration", "parameter", unit="s", start=0.0, min=0.0, variability="fixed",
                 description="duration <= this (0: no such bound)"),
        Variable("n_grid", "parameter", type="Integer", start=DEFAULT_GRID, min=10, variability="fixed",
                 description="grid intervals along the path"),
        Variable("optimize", "parameter", type="Boolean", start=True, variability="fixed",
                 description="false: play the reference instead, the parabolic blend uniformly slowed down to the "
                             "duration bound (limits v_max/f, a_max/f^2), for comparisons at the same duration"),
        Variable("path_file", "parameter", type="String", start="", variability="fixed",
                 description="a path given as samples instead of the waypoints: a table (Parquet/CSV, as cosim run "
                             "--out writes) with 'time' and <path_columns>[1..7] (URDF rad); relative to the "
                             "working directory; '' = the waypoints' parabolic blend"),
        Variable("path_columns", "parameter", type="String", start="traj.q_ref", variability="fixed",
                 description="the columns of path_file holding the joint positions: <path_columns>[1] .. [7]"),
        Variable("blend_duration", "output", unit="s", start=0.0,
                 description="duration of the parabolic blend (of the samples' own timing with path_file)"),
        Variable("planned_energy", "output", unit="J", start=0.0, description="electric energy of the planned timing on the planning grid (drive model, midpoint rule)"),
        Variable("solve_time", "output", unit="s", start=0.0, description="time spent planning (path data + solver passes)"),
    )

    def plan(self, waypoints: np.ndarray):
        if self.path_file:
            return self._plan_sampled(SampledPath.from_table(self.path_file, self.path_columns))
        blend = super().plan(waypoints)
        bounds = [float(self.max_duration) if self.max_duration > 0 else math.inf,
                  float(self.max_duration_factor) * blend.duration if self.max_duration_factor > 0 else math.inf]
        self.blend_duration = blend.duration
        if not self.optimize:  # the reference: the same path, uniformly slowed down to the bound
            f = max(1.0, min(bounds) / blend.duration) if blend.duration > 0 and math.isfinite(min(bounds)) else 1.0
            model = cached_model(*payload_key(self.payload_mass, self.payload_com, self.payload_inertia))
            path = path_data(blend, model, int(self.n_grid)) if blend.duration > 0 else None
            self.planned_energy = _energy(path, self._drive(), np.full(path.n + 1, 1 / f**2)) if path else 0.0
            self.solve_time = 0.0
            return plan_parabolic_blend(waypoints, np.asarray(self.v_max) / f, np.asarray(self.a_max) / f**2)
        drive = self._drive()
        model = cached_model(*payload_key(self.payload_mass, self.payload_com, self.payload_inertia))
        timing = plan_optimal_timing(blend, model, self.v_max, self.a_max, self.tau_max, drive,
                                     time_weight=float(self.time_weight),
                                     max_duration=min(bounds) if math.isfinite(min(bounds)) else None,
                                     n_grid=int(self.n_grid))
        self.planned_energy = timing.planned_energy
        self.solve_time = timing.solve_time
        return timing

    def _plan_sampled(self, path: SampledPath):
        """Re-time a sampled path; the reference (optimize = false) is its own timing slowed down to the bound."""
        bounds = [float(self.max_duration) if self.max_duration > 0 else math.inf,
                  float(self.max_duration_factor) * path.duration if self.max_duration_factor > 0 else math.inf]
        self.blend_duration = path.duration
        model = cached_model(*payload_key(self.payload_mass, self.payload_com, self.payload_inertia))
        if not self.optimize:
            f = max(1.0, min(bounds) / path.duration) if math.isfinite(min(bounds)) else 1.0
            data = path_data(path, model, int(self.n_grid))
            b = np.full(data.n + 1, 1 / f**2)
            self.planned_energy, self.solve_time = _energy(data, self._drive(), b), 0.0
            return OptimalTiming(path, data.s, b, data.s * f, self.planned_energy, 0.0, 0)
        timing = plan_optimal_timing(path, model, self.v_max, self.a_max, self.tau_max, self._drive(),
                                     time_weight=float(self.time_weight),
                                     max_duration=min(bounds) if math.isfinite(min(bounds)) else None,
                                     n_grid=int(self.n_grid))
        self.planned_energy, self.solve_time = timing.planned_energy, timing.solve_time
        return timing

    def _drive(self) -> DriveParameters:
        return DriveParameters(*(np.asarray(getattr(self, k), dtype=float) for k in
                                 ("gear_ratio", "r_terminal", "k_m", "eta_motor", "eta_gear_speed", "eta_gear_value")),
                               recuperation=bool(self.recuperation))
