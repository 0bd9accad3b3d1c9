"""Joint trajectories through waypoints with parabolic blends (Kunz & Stilman).

The method is the one of thesis section 7.2.1, after T. Kunz and M. Stilman,
"Turning Paths Into Trajectories Using Parabolic Blends", Georgia Tech
technical report GT-GOLEM-2011-006 (2011):

* every segment between waypoints ``q_i`` and ``q_{i+1}`` is run at constant
  velocity ``v_i = (q_{i+1} - q_i) / dT_i`` (eq. 7-1), where the duration is the
  one at which the slowest joint reaches its velocity limit,
  ``dT_i = max_j |q_{i+1}[j] - q_i[j]| / v_max[j]`` (eq. 7-6), so all joints start
  and arrive together (the segment is synchronised);
* around every waypoint a parabolic blend of constant acceleration
  ``a_i = (v_i - v_{i-1}) / tb_i`` (eq. 7-2) joins the neighbouring segments; its
  duration is the one at which the most demanding joint reaches its
  acceleration limit, ``tb_i = max_j |v_i[j] - v_{i-1}[j]| / a_max[j]`` (eq. 7-7);
* the first and last waypoints are blends from and to rest (``v_0 = v_n = 0``),
  so the trajectory starts and ends exactly at them, at rest (eq. 7-4, 7-5);
* neighbouring blends must not overlap (eq. 7-3, ``tb_i + tb_{i+1} <= 2 dT_i``).
  When a blend is longer than one of its adjacent segments, Kunz and Stilman
  slow both adjacent segments down by ``f = sqrt(min(dT_{i-1}, dT_i) / tb_i)``
  (velocities times ``f``, durations divided by ``f``, so the blend shrinks by
  ``f`` and exactly fits) and start the check again, until every blend fits.
  Since ``tb_i <= dT_{i-1}`` and ``tb_i <= dT_i`` for every blend, eq. 7-3 holds.

What the trajectory promises: ``|qd| <= v_max`` and ``|qdd| <= a_max`` per joint
at all times; the first and last waypoints are hit exactly, at rest; interior
waypoints are *not* hit (the method cuts corners): at the waypoint's time the
trajectory is ``|v_i - v_{i-1}| * tb_i / 8`` away from it, per joint.

:func:`plan_parabolic_blend` is the pure planning function (reusable by
planners); :class:`TrajectoryGenerator` is the co-simulation unit wrapping it.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field

import numpy as np

from cosim.units.protocol import Variable
from cosim.units.python.batch import NotBatchable, PythonBatchUnit
from cosim.units.python.unit import PythonUnit

from .panda_model import FRANKA_DOC_LIMITS, N_JOINTS, thesis_to_urdf
from .panda_rows import KernelsUnavailable, TrajectoryRowKernel, row_address

MAX_SLOWDOWNS = 10_000  # a safety net: the fix converges in a handful of passes on real paths


@dataclass(frozen=True)
class ParabolicBlendTrajectory:
    """A planned trajectory: alternating blend and linear phases of constant acceleration.

    Phase ``k`` starts at ``phase_start[k]`` in position ``phase_q[k]`` with
    velocity ``phase_v[k]`` and has constant acceleration ``phase_a[k]``.
    """

    waypoints: np.ndarray  # (n, d) as planned (duplicates removed)
    segment_durations: np.ndarray  # dT_i, (n-1,)
    blend_durations: np.ndarray  # tb_i, (n,)
    waypoint_times: np.ndarray  # T_i, (n,)
    velocities: np.ndarray  # v_i of the linear segments, (n-1, d)
    slowdowns: int  # how many times the overlap fix (eq. 7-3) had to slow segments down
    phase_start: np.ndarray = field(repr=False)
    phase_q: np.ndarray = field(repr=False)
    phase_v: np.ndarray = field(repr=False)
    phase_a: np.ndarray = field(repr=False)
    _starts: list = field(init=False, repr=False, compare=False)
    _duration: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_starts", self.phase_start.tolist())  # bisect is fastest on a list
        # sample() needs it at every call: computed once
        object.__setattr__(self, "_duration", float(self.waypoint_times[-1] + self.blend_durations[-1] / 2))

    @property
    def duration(self) -> float:
        """Total duration t_f (s), eq. 7-4."""
        return self._duration

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration at time ``t`` (s from the start).

        Before 0 and after :attr:`duration` the trajectory rests at its first and
        last waypoint.
        """
        if t <= 0.0:
            z = np.zeros(self.waypoints.shape[1])
            return self.waypoints[0].copy(), z, z.copy()
        if t >= self._duration:
            z = np.zeros(self.waypoints.shape[1])
            return self.waypoints[-1].copy(), z, z.copy()
        k = bisect.bisect_right(self._starts, t) - 1
        dt = t - self._starts[k]
        a = self.phase_a[k]
        v = self.phase_v[k] + a * dt
        q = self.phase_q[k] + self.phase_v[k] * dt + 0.5 * a * dt * dt
        return q, v, a.copy()

    def sample_many(self, times) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`sample` at many times at once: arrays of shape (len(times), d)."""
        out = [self.sample(float(t)) for t in np.asarray(times, dtype=float)]
        return tuple(np.array(x) for x in zip(*out))  # type: ignore[return-value]


def _timing(q: np.ndarray, dT: np.ndarray, amax: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segment velocities (with rest before and after) and blend durations for durations dT."""
    v = np.zeros((len(q) + 1, q.shape[1]))  # v[0] and v[n] are the virtual rest segments
    v[1:-1] = (q[1:] - q[:-1]) / dT[:, None]
    tb = np.max(np.abs(np.diff(v, axis=0)) / amax, axis=1)  # eq. 7-7
    return v, tb


def plan_parabolic_blend(waypoints, vmax, amax) -> ParabolicBlendTrajectory:
    """Plan a trajectory through ``waypoints`` (n x d) within ``vmax``, ``amax`` (d each).

    Consecutive identical waypoints are merged (a zero-length segment has no
    direction).  A single distinct waypoint gives a trajectory of duration 0.

    Raises ValueError for fewer than one waypoint, mismatched shapes,
    non-finite values or limits that are not strictly positive, and
    RuntimeError if the overlap fix does not converge (not seen in practice).
    """
    q = np.atleast_2d(np.asarray(waypoints, dtype=float))
    vmax = np.asarray(vmax, dtype=float).reshape(-1)
    amax = np.asarray(amax, dtype=float).reshape(-1)
    if q.shape[0] < 1 or q.shape[1] == 0:
        raise ValueError("need at least one waypoint")
    d = q.shape[1]
    if vmax.shape != (d,) or amax.shape != (d,):
        raise ValueError(f"vmax and amax need {d} elements, got {vmax.size} and {amax.size}")
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(vmax)) and np.all(np.isfinite(amax))):
        raise ValueError("waypoints and limits must be finite")
    if np.any(vmax <= 0) or np.any(amax <= 0):
        raise ValueError("velocity and acceleration limits must be > 0")
    keep = np.ones(len(q), dtype=bool)
    keep[1:] = np.any(q[1:] != q[:-1], axis=1)
    q = q[keep]
    n = len(q)

    dT = np.max(np.abs(np.diff(q, axis=0)) / vmax, axis=1) if n > 1 else np.zeros(0)  # eq. 7-6
    v, tb = _timing(q, dT, amax)
    slowdowns = 0
    i = 0
    while i < n:  # Kunz & Stilman's fix for overlapping blends (eq. 7-3)
        adjacent = [dT[s] for s in (i - 1, i) if 0 <= s < n - 1]
        shortest = min(adjacent) if adjacent else np.inf
        if tb[i] > shortest * (1 + 1e-12):
            f = np.sqrt(shortest / tb[i])
            for s in (i - 1, i):
                if 0 <= s < n - 1:
                    dT[s] /= f
            v, tb = _timing(q, dT, amax)
            slowdowns += 1
            if slowdowns > MAX_SLOWDOWNS:
                raise RuntimeError("parabolic blend timing did not converge")
            i = 0
        else:
            i += 1

    T = np.empty(n)
    T[0] = tb[0] / 2
    T[1:] = T[0] + np.cumsum(dT)
    # Phases (eq. 7-5): blend i from T_i - tb_i/2 (on segment i-1's line), then
    # linear segment i from T_i + tb_i/2.  Zero-length blends are skipped.
    starts, qs, vs, acc = [], [], [], []
    for i in range(n):
        if tb[i] > 0:
            starts.append(T[i] - tb[i] / 2)
            qs.append(q[i] - v[i] * tb[i] / 2)
            vs.append(v[i])
            acc.append((v[i + 1] - v[i]) / tb[i])  # eq. 7-2
        if i < n - 1:
            starts.append(T[i] + tb[i] / 2)
            qs.append(q[i] + v[i + 1] * tb[i] / 2)
            vs.append(v[i + 1])
            acc.append(np.zeros(d))
    if not starts:  # a single waypoint: rest there
        starts, qs, vs, acc = [0.0], [q[0]], [np.zeros(d)], [np.zeros(d)]
    return ParabolicBlendTrajectory(
        waypoints=q,
        segment_durations=dT,
        blend_durations=tb,
        waypoint_times=T,
        velocities=v[1:-1],
        slowdowns=slowdowns,
        phase_start=np.array(starts),
        phase_q=np.array(qs),
        phase_v=np.array(vs),
        phase_a=np.array(acc),
    )


N_MAX_WAYPOINTS = 16
CONVENTIONS = ("urdf_rad", "thesis_deg")
SAMPLINGS = ("instant", "step_midpoint")


class TrajectoryGenerator(PythonUnit):
    """Parabolic-blend joint trajectory for the Panda (Kunz & Stilman, thesis 7.2.1).

    Waypoints: ``waypoints`` is a flat array of ``16 x 7`` values, waypoint ``k``
    (1-based) joint ``j`` at element ``waypoints[(k-1)*7 + j]``; the first
    ``n_waypoints`` rows are used.  A flat array (rather than fixed ``q_start``,
    ``q_via``, ``q_end`` ports) lets one unit serve the 3-waypoint
    pick-and-place study and the 7-waypoint bin-picking task, and lets a design
    space vary single elements (the thesis's ``q2[2]`` is ``waypoints[9]``).
    ``convention`` says how they are given: ``"urdf_rad"`` (radians, URDF zero,
    default) or ``"thesis_deg"`` (degrees, the thesis's Unity zero pose, see
    :func:`models.panda_model.thesis_to_urdf`), so a spec can copy the thesis's
    numbers.  Outputs are always URDF radians.

    Limits ``v_max``, ``a_max`` default to Franka's documentation values
    (:data:`models.panda_model.FRANKA_DOC_LIMITS`); ``velocity_scale`` (a
    speed override in (0, 1], default 1) plans with ``velocity_scale * v_max``.  Outputs at time ``t`` are the
    trajectory at ``t - start_time``; after the end it rests at the last waypoint
    with ``finished`` true.

    ``sampling``: with ``"instant"`` (default) the outputs after ``do_step(t, h)``
    are the trajectory at ``t + h``.  With ``"step_midpoint"`` they describe the
    step just taken: ``q_ref``, ``qd_ref`` at ``t + h/2`` and ``qdd_ref`` the mean
    acceleration over ``[t, t + h]``.  It is meant for the inverse-dynamics
    level under Gauss-Seidel, where the energy unit holds the robot's outputs
    over that same step: its integral then is a midpoint rule (second order,
    and a jump of the acceleration inside a step is weighted by the time on
    each side) instead of a rectangle rule that charges the end value to the
    whole step, which lets the communication step grow from 1 ms to 10 ms
    for the same energy.  ``finished`` always refers to ``t + h``.
    """

    variables = (
        # no declared unit: rad or deg depending on `convention`, so a design parameter's "unit": "deg" on it
        # labels the values and is not converted (a declared "rad" would turn the thesis's degrees into radians)
        Variable("waypoints", "parameter", start=0.0, shape=(N_MAX_WAYPOINTS * N_JOINTS,),
                 description="flat n_max x 7 waypoints, row k = waypoint k; rad under convention 'urdf_rad', "
                             "deg under 'thesis_deg'", variability="fixed"),
        Variable("n_waypoints", "parameter", type="Integer", start=2, min=1, max=N_MAX_WAYPOINTS,
                 description="number of waypoints used", variability="fixed"),
        Variable("convention", "parameter", type="String", start="urdf_rad",
                 description="'urdf_rad' or 'thesis_deg'", variability="fixed"),
        Variable("v_max", "parameter", unit="rad/s", start=tuple(FRANKA_DOC_LIMITS.qd_max), shape=(N_JOINTS,),
                 description="joint velocity limits (Franka documentation)", variability="fixed"),
        Variable("a_max", "parameter", unit="rad/s2", start=tuple(FRANKA_DOC_LIMITS.qdd_max), shape=(N_JOINTS,),
                 description="joint acceleration limits (Franka documentation)", variability="fixed"),
        Variable("velocity_scale", "parameter", start=1.0, min=0.0, max=1.0,
                 description="speed override: the trajectory is planned with velocity_scale * v_max, in (0, 1]",
                 variability="fixed"),
        Variable("sampling", "parameter", type="String", start="instant",
                 description="'instant': outputs at the communication point t+h; 'step_midpoint': q_ref and qd_ref "
                             "at the middle of the step just taken, qdd_ref its mean over the step (see the class docstring)",
                 variability="fixed"),
        Variable("q_ref", "output", unit="rad", start=0.0, shape=(N_JOINTS,)),
        Variable("qd_ref", "output", unit="rad/s", start=0.0, shape=(N_JOINTS,)),
        Variable("qdd_ref", "output", unit="rad/s2", start=0.0, shape=(N_JOINTS,)),
        Variable("finished", "output", type="Boolean", start=False, description="t >= duration"),
        Variable("duration", "output", unit="s", start=0.0, description="total duration t_f (eq. 7-4)"),
    )

    def enter_initialization(self) -> None:
        # Plan already here, so q_ref etc. are valid in initialization mode (as FMI
        # allows for outputs that depend on parameters only) and a master can hand
        # the start of the reference to the robot before the robot initializes.
        # exit_initialization() plans again, in case parameters changed meanwhile.
        super().enter_initialization()
        self._call("initialize", self.start_time)
        self._planned_with = self._parameter_values()

    def exit_initialization(self) -> None:
        # Planning costs more than a whole run's steps at 10 ms: plan again only if a
        # parameter changed since enter_initialization() (the trajectory has no inputs,
        # so its outputs are then exactly what initialize() would write again).
        planned_with, self._planned_with = getattr(self, "_planned_with", None), None
        if planned_with is None or planned_with != self._parameter_values():
            super().exit_initialization()

    def _parameter_values(self) -> tuple:
        values = []
        for v in self.description.variables:
            if v.causality == "parameter":
                value = getattr(self, v.name)
                values.append(value.tobytes() if isinstance(value, np.ndarray) else value)
        return tuple(values)

    def initialize(self) -> None:
        n = int(self.n_waypoints)
        if not 1 <= n <= N_MAX_WAYPOINTS:
            raise ValueError(f"n_waypoints must be in 1..{N_MAX_WAYPOINTS}, got {n}")
        if self.convention not in CONVENTIONS:
            raise ValueError(f"convention must be one of {CONVENTIONS}, got {self.convention!r}")
        wp = self.waypoints.reshape(N_MAX_WAYPOINTS, N_JOINTS)[:n]
        if self.convention == "thesis_deg":
            wp = thesis_to_urdf(wp)
        if self.sampling not in SAMPLINGS:
            raise ValueError(f"sampling must be one of {SAMPLINGS}, got {self.sampling!r}")
        if not 0.0 < float(self.velocity_scale) <= 1.0:
            raise ValueError(f"velocity_scale must be in (0, 1], got {self.velocity_scale}")
        self.trajectory = self.plan(wp)
        self.duration = self.trajectory.duration
        self._midpoint = self.sampling == "step_midpoint"
        self._write(self.start_time, 0.0)

    def plan(self, waypoints: np.ndarray):
        """The trajectory through ``waypoints`` (URDF radians, n x 7): anything with
        ``sample(t) -> (q, qd, qdd)`` and ``duration``.  Subclasses re-time it
        (models.optimal_timing)."""
        return plan_parabolic_blend(waypoints, float(self.velocity_scale) * self.v_max, self.a_max)

    def do_step(self, t: float, h: float) -> None:
        self._write(t + h, h)

    def _write(self, t: float, h: float) -> None:
        local = t - self.start_time
        if self._midpoint and h > 0:
            q, qd, _ = self.trajectory.sample(local - 0.5 * h)
            self.q_ref[:] = q
            self.qd_ref[:] = qd
            # (qd(t) - qd(t - h)) / h: exact inside a phase, and across a blend's
            # start or end the time-weighted mix of the two accelerations
            qd_end = self.trajectory.sample(local)[1]
            t_last, qd_last = self._last_end
            # the previous step's end is this step's start (steps follow each other)
            qd_start = qd_last if abs(t_last - (local - h)) <= 1e-12 * max(1.0, abs(local)) else \
                self.trajectory.sample(local - h)[1]
            np.subtract(qd_end, qd_start, out=self.qdd_ref)
            self.qdd_ref /= h
            self._last_end = (local, qd_end)
        else:
            q, qd, qdd = self.trajectory.sample(local)
            self.q_ref[:] = q
            self.qd_ref[:] = qd
            self.qdd_ref[:] = qdd
            self._last_end = (local, qd)
        # a hair of tolerance so a run that stops at t_f on a tick grid counts as finished
        self.finished = bool(local >= self.duration - 1e-9)


class TrajectoryGeneratorBatch(PythonBatchUnit):
    """:class:`TrajectoryGenerator` for K design points at once (lock-step runs, cosim.execution.lockstep).

    Each row is planned by the single unit's own code (:meth:`TrajectoryGenerator.plan`
    and :func:`plan_parabolic_blend`); the phases of all rows are padded into
    one table and sampled with the single unit's formulas, element for
    element, so row k's outputs are those of a single unit with row k's
    parameters bit for bit.  Raises NotBatchable when the rows disagree on
    ``sampling``.
    """

    def initialize(self) -> None:
        single = self.single_class(self.name)
        single.setup(self.start_time, self.stop_time)
        plans = []
        for k in range(self.rows):
            for v in self.description.variables:
                if v.causality == "parameter":
                    setattr(single, v.name, getattr(self, v.name)[k])
            single.initialize()  # the single unit's checks and plan
            plans.append(single.trajectory)
        if len(set(self.sampling.tolist())) != 1:
            raise NotBatchable("rows differ in 'sampling'")
        self._midpoint = self.sampling[0] == "step_midpoint"
        phases = max(len(p.phase_start) for p in plans)
        self._starts = np.full((self.rows, phases), np.inf)  # padding never starts
        self._q, self._v, self._a = (np.zeros((self.rows, phases, N_JOINTS)) for _ in range(3))
        for k, p in enumerate(plans):
            m = len(p.phase_start)
            self._starts[k, :m] = p.phase_start
            self._q[k, :m], self._v[k, :m], self._a[k, :m] = p.phase_q, p.phase_v, p.phase_a
        # flat (rows * phases) tables: one take per sample instead of 2-D fancy indexing
        self._base = np.arange(self.rows) * phases
        self._starts_flat = self._starts.reshape(-1)
        self._q_flat, self._v_flat, self._a_flat = (x.reshape(-1, N_JOINTS) for x in (self._q, self._v, self._a))
        self._first = np.array([p.waypoints[0] for p in plans])
        self._last = np.array([p.waypoints[-1] for p in plans])
        self.duration[:] = [p.duration for p in plans]
        self._kernel = self._row_kernel()
        self._write(self.start_time, 0.0)

    def _row_kernel(self) -> TrajectoryRowKernel | None:
        """The compiled sampling of every row (the numpy one of :meth:`_sample` in C, the same bits), bound to
        this run's tables and output arrays; None where the library cannot be built here."""
        try:
            kernel = TrajectoryRowKernel(self._starts, self._q, self._v, self._a, self._first, self._last,
                                         self.duration)
            rows = self.rows
            self._ends = [np.zeros((rows, N_JOINTS)) for _ in range(2)]  # qd at steps' ends, taken in turn
            self._at = {name: row_address(name, array, rows, N_JOINTS) for name, array in
                        (("q_ref", self.q_ref), ("qd_ref", self.qd_ref), ("qdd_ref", self.qdd_ref))}
            self._ends_at = [row_address("qd_end", end, rows, N_JOINTS) for end in self._ends]
            self._turn = 0
        except (KernelsUnavailable, ValueError):  # no C compiler here, or an array not as the kernel takes it
            return None
        return kernel

    def _sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """ParabolicBlendTrajectory.sample of every row at ``t`` (same operations, per element)."""
        k = self._base + np.maximum((self._starts <= t).sum(axis=1) - 1, 0)  # bisect_right - 1, per row
        dt = (t - self._starts_flat[k])[:, None]
        a = self._a_flat[k]
        v0 = self._v_flat[k]
        v = v0 + a * dt
        q = self._q_flat[k] + v0 * dt + 0.5 * a * dt * dt
        if t <= 0.0:
            return self._first.copy(), np.zeros_like(v), np.zeros_like(a)
        rest = t >= self.duration
        if rest.any():
            q[rest], v[rest], a[rest] = self._last[rest], 0.0, 0.0
        return q, v, a

    def do_step(self, t: float, h: float) -> None:
        self._write(t + h, h)

    def _write_compiled(self, local: float, h: float) -> None:
        """:meth:`_write` with the compiled sampling: the same values into the same arrays.  qd at the last
        step's end is kept in ``_ends[_turn]``; this step's end goes into the other buffer."""
        kernel, at = self._kernel, self._at
        assert kernel is not None
        last = self._turn
        self._turn = 1 - last
        if self._midpoint and h > 0:
            kernel.sample(local - 0.5 * h, at["q_ref"], at["qd_ref"], None)
            kernel.sample(local, None, self._ends_at[self._turn], None)
            # the previous step's end is this step's start (steps follow each other)
            if not abs(self._last_time - (local - h)) <= 1e-12 * max(1.0, abs(local)):
                kernel.sample(local - h, None, self._ends_at[last], None)
            np.subtract(self._ends[self._turn], self._ends[last], out=self.qdd_ref)
            self.qdd_ref /= h
        else:
            kernel.sample(local, at["q_ref"], at["qd_ref"], at["qdd_ref"])
            self._ends[self._turn][:] = self.qd_ref
        self._last_time = local
        self.finished[:] = local >= self.duration - 1e-9

    def _write(self, t: float, h: float) -> None:
        local = t - self.start_time
        if self._kernel is not None:
            self._write_compiled(local, h)
            return
        if self._midpoint and h > 0:
            q, qd, _ = self._sample(local - 0.5 * h)
            self.q_ref[:] = q
            self.qd_ref[:] = qd
            qd_end = self._sample(local)[1]
            t_last, qd_last = self._last_end
            qd_start = qd_last if abs(t_last - (local - h)) <= 1e-12 * max(1.0, abs(local)) else \
                self._sample(local - h)[1]
            np.subtract(qd_end, qd_start, out=self.qdd_ref)
            self.qdd_ref /= h
            self._last_end = (local, qd_end)
        else:
            q, qd, qdd = self._sample(local)
            self.q_ref[:] = q
            self.qd_ref[:] = qd
            self.qdd_ref[:] = qdd
            self._last_end = (local, qd)
        self.finished[:] = local >= self.duration - 1e-9


TrajectoryGenerator.batch_class = TrajectoryGeneratorBatch
