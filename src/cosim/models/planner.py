"""Cartesian path planning for the Panda among box obstacles (the thesis's MoveIt step, section 7.3.1).

What :func:`plan_cartesian_path` does, after MoveIt's ``computeCartesianPath``:

* the TCP (``panda_hand_tcp``) follows straight lines between the task's
  waypoints at a constant orientation (gripper down), sampled every
  ``eef_step`` metres;
* every sample is solved by damped-least-squares inverse kinematics (pinocchio
  frame Jacobian, 6-D pose error) *starting from the previous sample's
  solution*, so the joint path is continuous wherever it exists; joint limits
  are enforced by clamping;
* a sample is rejected, and planning stops there, when the IK does not
  converge (``unreachable``; ``joint limit`` when a clamped joint blocks it),
  when a joint moves more than ``max_joint_step`` between samples
  (``joint jump``, an absolute form of MoveIt's ``jump_threshold``; the
  relative MoveIt form is applied afterwards when ``jump_threshold > 0``), or
  when the arm collides with the plant or itself (coal, :mod:`cosim.models.collision`);
* the result says which fraction of the path was planned (MoveIt's
  definition: completed segments plus the completed share of the blocked one,
  divided by the number of segments) and what blocked it.

Timing (:func:`time_parameterize`): the robot stops at every task waypoint (it
grasps in the box and releases over the conveyor).  Between two waypoints
the dense joint path is thinned to keyframes (a keyframe is dropped while the
straight joint-space chord stays within ``path_tolerance`` of every dense
sample it replaces) and timed with :func:`models.trajectory.plan_parabolic_blend`,
which keeps every joint within its velocity and acceleration limits.  Parabolic
blends through 5-20 keyframes per segment were chosen over a time-optimal
dense parameterisation (TOTG, TOPP-RA) because they reuse the thesis's own
timing law (section 7.2.1), are exact and cheap; the price is that blends cut
corners (at most ``|dv| tb / 8`` per joint), so the executed path deviates
slightly from the checked one, which the execution-time collision check
(:class:`PlantCollisionChecker`) covers.

Why plan in ``initialize()``: as in the thesis (section 7.3.2), planning is done
once per design point before stepping; the unit then only plays the planned
trajectory.  Its ports equal :class:`models.trajectory.TrajectoryGenerator`'s
(``q_ref``, ``qd_ref``, ``qdd_ref``, ``finished``, ``duration``), so a player of
a trajectory planned elsewhere can replace it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from cosim.units.protocol import Variable
from cosim.units.python.unit import PythonUnit

from .collision import READY_POSE, CellCollision, link_of
from .panda_model import EE_FRAME, FRANKA_DOC_LIMITS, N_JOINTS
from .plant import load_plant
from .trajectory import ParabolicBlendTrajectory, plan_parabolic_blend

# blocked_code values (Integer output)
OK, UNREACHABLE, JOINT_LIMIT, JOINT_JUMP, COLLISION_PLANT, SELF_COLLISION = 0, 1, 2, 3, 4, 5
CODE_NAMES = {OK: "ok", UNREACHABLE: "unreachable", JOINT_LIMIT: "joint limit", JOINT_JUMP: "joint jump",
              COLLISION_PLANT: "collision with plant", SELF_COLLISION: "self-collision"}


@dataclass(frozen=True)
class PlannerSettings:
    """Planner knobs; defaults are MoveIt-like (1 cm steps) and documented in the unit."""

    eef_step: float = 0.01  # m between IK samples (MoveIt's eef_step)
    max_joint_step: float = 0.2  # rad, largest allowed change of any joint between two samples
    jump_threshold: float = 0.0  # MoveIt's relative threshold (x mean step); 0 disables
    ik_tolerance: float = 1e-4  # m (and rad for the orientation error)
    ik_damping: float = 1e-3  # lambda of damped least squares
    ik_iterations: int = 60  # per sample; the start pose gets 10x as many
    self_collision: bool = True
    collision_margin: float = 0.0  # m
    free_yaw: bool = True  # along the path hold only the tool axis (gripper down), see CartesianPlanner.ik

    def __post_init__(self) -> None:
        if not (self.eef_step > 0 and self.max_joint_step > 0 and self.ik_tolerance > 0 and self.ik_iterations > 0):
            raise ValueError("eef_step, max_joint_step, ik_tolerance and ik_iterations must be > 0")
        if self.jump_threshold < 0 or self.collision_margin < 0 or self.ik_damping < 0:
            raise ValueError("jump_threshold, collision_margin and ik_damping must be >= 0")


@dataclass
class CartesianPath:
    """A planned (possibly partial) joint path along the task's straight segments.

    ``q`` (n x 7) are the accepted samples from the first waypoint on;
    ``stops`` the indices into ``q`` where each *reached* waypoint lies (first 0).
    """

    q: np.ndarray
    stops: list[int]
    fraction: float
    code: int = OK
    blocked_by: str = ""
    blocked_link: str = ""
    segment: int = -1  # index of the blocked segment, -1 if none
    tcp: np.ndarray = field(default=None, repr=False)  # (n, 3) TCP positions of q

    @property
    def ok(self) -> bool:
        return self.code == OK and self.fraction >= 1.0 - 1e-12

    @property
    def joint_distance(self) -> float:
        """Sum over joints of the path length in joint space (rad)."""
        return float(np.abs(np.diff(self.q, axis=0)).sum()) if len(self.q) > 1 else 0.0

    @property
    def cartesian_distance(self) -> float:
        """Length of the TCP polyline (m)."""
        return float(np.linalg.norm(np.diff(self.tcp, axis=0), axis=1).sum()) if len(self.tcp) > 1 else 0.0


class CartesianPlanner:
    """Plans straight TCP segments for the Panda among the obstacles of a :class:`CellCollision`."""

    def __init__(self, collision: CellCollision, settings: PlannerSettings = PlannerSettings(),
                 q_min=FRANKA_DOC_LIMITS.q_min, q_max=FRANKA_DOC_LIMITS.q_max):
        self.cc = collision
        self.s = settings
        self.model = collision.model  # the reduced URDF model: same kinematics as models.panda_model
        self.data = self.model.createData()
        self.ee = self.model.getFrameId(EE_FRAME)
        self.q_min, self.q_max = np.asarray(q_min, float), np.asarray(q_max, float)

    def tcp(self, q) -> pin.SE3:
        pin.framesForwardKinematics(self.model, self.data, q)
        return self.data.oMf[self.ee]

    def _error(self, q, p, R, free_yaw: bool) -> np.ndarray:
        M = self.tcp(q)
        if free_yaw:  # only the tool axis is held: the angular error is z_tcp x z_goal, in the world xy plane
            return np.concatenate([p - M.translation, np.cross(M.rotation[:, 2], R[:, 2])[:2]])
        return np.concatenate([p - M.translation, pin.log3(R @ M.rotation.T)])  # world-frame pose error

    def ik(self, p, R, q0, iterations: int, max_step: float = np.inf, free_yaw: bool = False,
           limits: bool = True) -> tuple[np.ndarray, bool]:
        """DLS inverse kinematics for TCP pose (p, R) from ``q0``; (q, converged).  Never raises.

        With ``limits`` false the joint limits are ignored (used to tell why an
        IK within the limits failed).

        With ``free_yaw`` only the TCP's z axis is held to ``R``'s (5-D task, the
        hand may turn about the vertical); the tool axis must then be vertical,
        as it is for every task here.
        """
        q = np.array(q0, dtype=float)
        lam2 = self.s.ik_damping ** 2
        rows = [0, 1, 2, 3, 4] if free_yaw else slice(None)
        for _ in range(iterations):
            e = self._error(q, p, R, free_yaw)
            if np.abs(e).max() < self.s.ik_tolerance:
                return q, True
            J = pin.computeFrameJacobian(self.model, self.data, q, self.ee, pin.LOCAL_WORLD_ALIGNED)[rows]
            dq = J.T @ np.linalg.solve(J @ J.T + lam2 * np.eye(len(e)), e)
            n = np.abs(dq).max()
            if n > max_step:  # free IK to the start: small steps keep it near the seed's branch
                dq *= max_step / n
            q = np.clip(q + dq, self.q_min, self.q_max) if limits else q + dq
        return q, bool(np.abs(self._error(q, p, R, free_yaw)).max() < self.s.ik_tolerance)

    def _ik_failure(self, p, R, q0, iterations: int, max_step: float = np.inf,
                    free_yaw: bool = False) -> tuple[int, str, str]:
        """Why the IK of (p, R) from ``q0`` failed: (code, reason, joint).

        The IK is solved again without joint limits: if that converges, the
        joint furthest outside its range blocked (JOINT_LIMIT); otherwise the
        pose is out of reach.  Judging from where the limited IK stopped is not
        reproducible: near a singularity damped least squares oscillates, and
        whether its last iterate sits on a limit depends on the last bits of
        the floating-point arithmetic (it differed between two x86-64 CPUs).
        """
        q, ok = self.ik(p, R, q0, iterations, max_step, free_yaw, limits=False)
        if ok:
            outside = np.maximum(self.q_min - q, q - self.q_max)
            if outside.max() > 0:
                j = int(np.argmax(outside)) + 1
                return JOINT_LIMIT, f"joint limit of panda_joint{j}", f"panda_joint{j}"
        return UNREACHABLE, "out of reach (IK did not converge)", ""

    def _collision(self, q) -> tuple[int, str, str] | None:
        pair = self.cc.first_collision(q)
        if pair is None:
            return None
        a, b = link_of(pair[0]), link_of(pair[1])
        if pair[1] in self.cc.names[self.cc.n_arm:] or pair[0] in self.cc.names[self.cc.n_arm:]:
            link, obstacle = (a, b) if b in self.cc.names[self.cc.n_arm:] else (b, a)
            return COLLISION_PLANT, f"collision of {link} with {obstacle}", link
        return SELF_COLLISION, f"self-collision of {a} with {b}", a

    def seed(self, p_first, R) -> np.ndarray:
        """Franka's ready pose turned by joint 1 toward the first waypoint, joint 7 turned to the hand's yaw.

        In the ready pose the hand points down along link 7's axis, so turning
        joint 7 by ``a`` turns the hand about the vertical by ``-a``; starting
        the IK there keeps it off joint 7's limits.
        """
        q = READY_POSE.copy()
        q[0] = np.clip(math.atan2(p_first[1], p_first[0]), self.q_min[0], self.q_max[0])
        yaw_error = pin.log3(R @ self.tcp(q).rotation.T)[2]
        q[6] = (q[6] - yaw_error + math.pi) % (2 * math.pi) - math.pi  # nearest equivalent in (-pi, pi]
        return q

    def plan(self, waypoints, R, q_seed=None) -> CartesianPath:
        """Plan through ``waypoints`` (n x 3, base frame) at TCP orientation ``R``.

        The start configuration is the IK solution of the first waypoint from
        ``q_seed`` (default :meth:`seed`).  Never raises for an infeasible task:
        the result carries the fraction and the reason.
        """
        W = np.asarray(waypoints, dtype=float)
        n_seg = len(W) - 1
        q0 = self.seed(W[0], R) if q_seed is None else q_seed
        q, ok = self.ik(W[0], R, q0, 10 * self.s.ik_iterations, max_step=0.1)
        if not ok:
            code, why, link = self._ik_failure(W[0], R, q0, 10 * self.s.ik_iterations, max_step=0.1)
            return self._result([q], [0], 0.0, code, f"start pose {why}", link, 0)
        hit = self._collision(q)
        if hit:
            return self._result([q], [0], 0.0, hit[0], f"start pose: {hit[1]}", hit[2], 0)
        qs, stops, progress = [q], [0], [0.0]  # progress: MoveIt fraction reached at each sample
        for s in range(n_seg):
            a, b = W[s], W[s + 1]
            n = max(1, math.ceil(np.linalg.norm(b - a) / self.s.eef_step - 1e-9))
            for k in range(1, n + 1):
                target = a + (b - a) * (k / n)
                q_new, ok = self.ik(target, R, q, self.s.ik_iterations, free_yaw=self.s.free_yaw)
                failure = None
                if not ok:
                    code, why, link = self._ik_failure(target, R, q, self.s.ik_iterations, free_yaw=self.s.free_yaw)
                    failure = (code, why, link)
                elif np.abs(q_new - q).max() > self.s.max_joint_step:
                    j = int(np.argmax(np.abs(q_new - q))) + 1
                    failure = (JOINT_JUMP, f"joint jump of panda_joint{j} ({np.abs(q_new - q).max():.2f} rad in one step)",
                               f"panda_joint{j}")
                else:
                    failure = self._collision(q_new)
                if failure:
                    frac = (s + (k - 1) / n) / n_seg
                    path = self._result(qs, stops, frac, failure[0], f"segment {s + 1} at {100 * (k - 1) / n:.0f} %: {failure[1]}",
                                        failure[2], s)
                    return self._relative_jumps(path, progress)
                qs.append(q_new)
                progress.append((s + k / n) / n_seg)
                q = q_new
            stops.append(len(qs) - 1)
        return self._relative_jumps(self._result(qs, stops, 1.0, OK, "", "", -1), progress)

    def _relative_jumps(self, path: CartesianPath, progress: list[float]) -> CartesianPath:
        """MoveIt's jump_threshold: cut at the first step longer than threshold x the mean step (joint-space norm)."""
        if self.s.jump_threshold <= 0 or len(path.q) < 2:
            return path
        d = np.linalg.norm(np.diff(path.q, axis=0), axis=1)
        bad = np.flatnonzero(d > self.s.jump_threshold * d.mean())
        if not len(bad):
            return path
        i = int(bad[0])  # samples 0..i are kept
        s = int(np.searchsorted(path.stops, i, side="right") - 1)  # the segment of step i -> i+1
        j = int(np.argmax(np.abs(path.q[i + 1] - path.q[i]))) + 1
        return self._result(list(path.q[: i + 1]), path.stops[: s + 1], progress[i], JOINT_JUMP,
                            f"segment {s + 1}: joint jump of panda_joint{j} ({d[i]:.3f} rad > {self.s.jump_threshold:g} x mean step)",
                            f"panda_joint{j}", s)

    def _result(self, qs, stops, fraction, code, why, link, segment) -> CartesianPath:
        q = np.array(qs)
        tcp = np.array([self.tcp(x).translation.copy() for x in q])
        return CartesianPath(q, list(stops), float(fraction), code, why, link, segment if code else -1, tcp)


def keyframes(q: np.ndarray, tolerance: float) -> np.ndarray:
    """Indices of samples to keep: each dropped sample lies within ``tolerance`` (rad, per joint) of the chord."""
    keep, i, n = [0], 0, len(q)
    while i < n - 1:
        j = i + 1
        while j + 1 < n:
            cand = j + 1
            t = np.linspace(0.0, 1.0, cand - i + 1)[1:-1, None]
            chord = q[i] + t * (q[cand] - q[i])
            if np.abs(chord - q[i + 1:cand]).max() > tolerance:
                break
            j = cand
        keep.append(j)
        i = j
    return np.array(keep)


@dataclass(frozen=True)
class SegmentedTrajectory:
    """Parabolic-blend trajectories played one after another, at rest at every joint (stop)."""

    parts: tuple[ParabolicBlendTrajectory, ...]
    starts: np.ndarray  # start time of each part

    @property
    def duration(self) -> float:
        return float(self.starts[-1] + self.parts[-1].duration) if self.parts else 0.0

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration at ``t`` (s); at rest at the ends."""
        k = max(0, int(np.searchsorted(self.starts, t, side="right")) - 1)
        return self.parts[k].sample(t - self.starts[k])


def time_parameterize(path: CartesianPath, v_max, a_max, tolerance: float = 0.01) -> SegmentedTrajectory:
    """Time a planned path: rest at each reached waypoint (and at the end of a partial path).

    Raises ValueError for non-positive limits (from :func:`plan_parabolic_blend`).
    """
    bounds = list(path.stops)
    if bounds[-1] != len(path.q) - 1:  # a partial path ends where planning stopped
        bounds.append(len(path.q) - 1)
    parts, starts, t = [], [], 0.0
    for a, b in zip(bounds[:-1], bounds[1:]):
        seg = path.q[a:b + 1]
        traj = plan_parabolic_blend(seg[keyframes(seg, tolerance)], v_max, a_max)
        parts.append(traj)
        starts.append(t)
        t += traj.duration
    if not parts:  # nothing planned beyond the start: rest there
        parts, starts = [plan_parabolic_blend(path.q[:1], v_max, a_max)], [0.0]
    return SegmentedTrajectory(tuple(parts), np.array(starts))


def _plant_parameters():
    return (
        Variable("plant_file", "parameter", type="String", start="",
                 description="plant JSON (models/plant.py); '' = the bin-picking cell, models/bin_picking_plant.json", variability="fixed"),
        Variable("box_variant", "parameter", type="String", start="simple",
                 description="which box_variants entry of the plant file is added ('simple' or 'complex')", variability="fixed"),
        Variable("offset_x", "parameter", unit="m", start=0.0,
                 description="robot base offset, Unity x (toward the conveyor; thesis x_pos)", variability="fixed"),
        Variable("offset_y", "parameter", unit="m", start=0.0,
                 description="robot base offset, Unity y (up; thesis y_pos)", variability="fixed"),
        Variable("offset_z", "parameter", unit="m", start=0.0,
                 description="robot base offset, Unity z (toward the box; thesis z_pos)", variability="fixed"),
        Variable("collision_margin", "parameter", unit="m", start=0.0, min=0.0,
                 description="pairs closer than this count as colliding", variability="fixed"),
        Variable("self_collision", "parameter", type="Boolean", start=True,
                 description="check the arm against itself", variability="fixed"),
    )


def _plant_in_base(unit) -> tuple:
    plant = load_plant(unit.plant_file, unit.box_variant)
    offset = plant.unity_offset_to_world((unit.offset_x, unit.offset_y, unit.offset_z))
    return plant.in_base_frame(offset), offset


def _check_variables():
    return (
        Variable("check_period", "parameter", unit="s", start=0.01, min=0.0,
                 description="time between collision checks of the executed arm (0: every step)", variability="fixed"),
        Variable("compute_clearance", "parameter", type="Boolean", start=False,
                 description="also compute the minimum distance at each check (~4x the cost)", variability="fixed"),
        Variable("q", "input", unit="rad", start=tuple(READY_POSE), shape=(N_JOINTS,), description="executed joint angles"),
        Variable("collision", "output", type="Boolean", start=False, description="a pair collides at the last check"),
        Variable("collided", "output", type="Boolean", start=False, description="a collision was seen at some check of this run"),
        Variable("first_contact", "output", type="String", start="", description="the first colliding pair, 'link/obstacle'"),
        Variable("clearance", "output", unit="m", start=float("inf"), description="smallest distance at the checks so far"),
        Variable("checks", "output", type="Integer", start=0, description="number of checks so far"),
    )


class _ExecutionCheck:
    """Collision checks of the executed ``q`` input every ``check_period`` (shared by the two units below).

    The outputs after ``do_step(t, h)`` describe ``q`` as it was at ``t`` (the
    input held over the step): no direct feed-through, so the check can sit
    in the loop planner -> robot -> planner without an algebraic loop.
    """

    def _check_reset(self, cc: CellCollision) -> None:
        self._cc = cc
        self.collision = self.collided = False
        self.first_contact = ""
        self.clearance = float("inf")
        self.checks = 0
        self._next = self.start_time

    def _check(self, t: float) -> None:
        if t < self._next - 1e-12:
            return
        self._next = t + float(self.check_period)
        q = np.array(self.q, dtype=float)
        pair = self._cc.first_collision(q)
        self.collision = pair is not None
        if pair is not None and not self.collided:
            self.first_contact = f"{link_of(pair[0])}/{link_of(pair[1])}"
        self.collided = self.collided or self.collision
        if self.compute_clearance:
            self.clearance = min(self.clearance, self._cc.min_distance(q)[0])
        self.checks += 1


class BinPickingPlanner(_ExecutionCheck, PythonUnit):
    """Plans the plant's task once in ``initialize()`` and plays the timed joint trajectory.

    Outputs as :class:`models.trajectory.TrajectoryGenerator` (URDF radians) plus
    the planning results.  With an incomplete plan and ``execute_partial`` the
    planned part is played (the robot stops where planning stopped, as the
    thesis's runs "terminated early"); without it the robot rests at the start.
    Given the executed joint angles at its input ``q`` it also checks them
    against the plant every ``check_period`` (outputs ``collision``,
    ``collided``, ``first_contact``, see :class:`PlantCollisionChecker`), so one
    unit holds the plant for both planning and the execution check.

    Raises (as a UnitError) for a missing plant file, an unknown box variant or
    bad settings; an infeasible task is a result, not an error.
    """

    variables = _plant_parameters() + (
        Variable("eef_step", "parameter", unit="m", start=0.01, min=1e-4, description="TCP distance between IK samples", variability="fixed"),
        Variable("max_joint_step", "parameter", unit="rad", start=0.2, min=0.0,
                 description="largest change of any joint between two samples (joint-jump threshold)", variability="fixed"),
        Variable("jump_threshold", "parameter", start=0.0, min=0.0,
                 description="MoveIt's relative jump threshold (x mean step); 0 disables", variability="fixed"),
        Variable("path_tolerance", "parameter", unit="rad", start=0.01, min=0.0,
                 description="keyframe thinning tolerance of the time parameterisation", variability="fixed"),
        Variable("velocity_scaling", "parameter", start=1.0, min=1e-3, max=1.0, description="fraction of v_max used", variability="fixed"),
        Variable("acceleration_scaling", "parameter", start=1.0, min=1e-3, max=1.0, description="fraction of a_max used", variability="fixed"),
        Variable("v_max", "parameter", unit="rad/s", start=tuple(FRANKA_DOC_LIMITS.qd_max), shape=(N_JOINTS,),
                 description="joint velocity limits (Franka documentation)", variability="fixed"),
        Variable("a_max", "parameter", unit="rad/s2", start=tuple(FRANKA_DOC_LIMITS.qdd_max), shape=(N_JOINTS,),
                 description="joint acceleration limits (Franka documentation)", variability="fixed"),
        Variable("execute_partial", "parameter", type="Boolean", start=True,
                 description="play the planned part of an incomplete plan (else rest at the start)", variability="fixed"),
        Variable("q_ref", "output", unit="rad", start=0.0, shape=(N_JOINTS,)),
        Variable("qd_ref", "output", unit="rad/s", start=0.0, shape=(N_JOINTS,)),
        Variable("qdd_ref", "output", unit="rad/s2", start=0.0, shape=(N_JOINTS,)),
        Variable("finished", "output", type="Boolean", start=False, description="t >= duration"),
        Variable("duration", "output", unit="s", start=0.0, description="duration of the played trajectory"),
        Variable("fraction_planned", "output", start=0.0, description="MoveIt's fraction of the Cartesian path planned (0..1)"),
        Variable("planned_ok", "output", type="Boolean", start=False, description="the whole task was planned"),
        Variable("blocked_code", "output", type="Integer", start=0,
                 description="0 ok, 1 unreachable, 2 joint limit, 3 joint jump, 4 collision with plant, 5 self-collision"),
        Variable("blocked_by", "output", type="String", start="", description="what stopped planning, in words"),
        Variable("blocked_link", "output", type="String", start="", description="the link (or joint) that blocked"),
        Variable("joint_distance", "output", unit="rad", start=0.0, description="planned joint path length, summed over joints"),
        Variable("cartesian_distance", "output", unit="m", start=0.0, description="planned TCP path length"),
        Variable("planning_time", "output", unit="s", start=0.0, description="wall time of planning (for benchmarks)"),
    ) + _check_variables()
    data_files = ("plant_file",)  # a plant file of the study travels with the unit to remote workers
    feedthrough = {v.name: () for v in variables if v.causality == "output"}  # q only feeds the next step's check

    def enter_initialization(self) -> None:
        # plan already here so q_ref is valid before the robot initializes (see TrajectoryGenerator)
        super().enter_initialization()
        self._call("initialize", self.start_time)

    def initialize(self) -> None:
        import time

        key = (self.plant_file, self.box_variant, float(self.offset_x), float(self.offset_y), float(self.offset_z),
               float(self.collision_margin), bool(self.self_collision), float(self.eef_step), float(self.max_joint_step),
               float(self.jump_threshold), float(self.path_tolerance), float(self.velocity_scaling),
               float(self.acceleration_scaling), tuple(self.v_max), tuple(self.a_max), bool(self.execute_partial))
        # plan only when something changed: enter_ and exit_initialization both call us, and a
        # sweep worker re-initializes the same instance for every point
        if getattr(self, "_plan_key", None) != key:
            t0 = time.perf_counter()
            plant, _ = _plant_in_base(self)
            settings = PlannerSettings(eef_step=float(self.eef_step), max_joint_step=float(self.max_joint_step),
                                       jump_threshold=float(self.jump_threshold), self_collision=bool(self.self_collision),
                                       collision_margin=float(self.collision_margin))
            self._cell = CellCollision(plant.obstacles, settings.self_collision, settings.collision_margin)
            planner = CartesianPlanner(self._cell, settings)
            self.path = planner.plan(plant.waypoints, plant.tcp_rotation)
            path = self.path
            if not path.ok and not self.execute_partial:
                path = CartesianPath(path.q[:1], [0], path.fraction, path.code, path.blocked_by, path.blocked_link, path.segment, path.tcp[:1])
            self.trajectory = time_parameterize(path, np.asarray(self.v_max) * self.velocity_scaling,
                                                np.asarray(self.a_max) * self.acceleration_scaling, float(self.path_tolerance))
            self._planning_time = time.perf_counter() - t0
            self._plan_key = key
        p = self.path
        self.planning_time = self._planning_time  # 0-cost when the same plan was reused
        self.fraction_planned = p.fraction
        self.planned_ok = p.ok
        self.blocked_code = int(p.code)
        self.blocked_by = p.blocked_by
        self.blocked_link = p.blocked_link
        self.joint_distance = p.joint_distance
        self.cartesian_distance = p.cartesian_distance
        self.duration = self.trajectory.duration
        self._write(self.start_time)
        self._check_reset(self._cell)

    def do_step(self, t: float, h: float) -> None:
        self._check(t)
        self._write(t + h)

    def _write(self, t: float) -> None:
        local = t - self.start_time
        q, qd, qdd = self.trajectory.sample(local)
        self.q_ref[:] = q
        self.qd_ref[:] = qd
        self.qdd_ref[:] = qdd
        self.finished = bool(local >= self.duration - 1e-9)


class PlantCollisionChecker(_ExecutionCheck, PythonUnit):
    """Checks the *executed* arm (input ``q``) against the plant and itself every ``check_period``.

    For use beside another trajectory source (a player of an external plan);
    :class:`BinPickingPlanner` has the same check built in.  ``collision`` is
    true at a check that finds a colliding pair (held until the next check);
    ``collided`` latches it for the run; ``first_contact`` names the first pair;
    ``clearance`` is the smallest distance seen at the checks (only with
    ``compute_clearance``).  The pendulum payload is not checked (its geometry
    is not modelled).
    """

    variables = _plant_parameters() + _check_variables()
    data_files = ("plant_file",)  # a plant file of the study travels with the unit to remote workers
    feedthrough = {v.name: () for v in _check_variables() if v.causality == "output"}

    def initialize(self) -> None:
        plant, _ = _plant_in_base(self)
        key = (self.plant_file, self.box_variant, float(self.offset_x), float(self.offset_y), float(self.offset_z),
               float(self.collision_margin), bool(self.self_collision))
        if getattr(self, "_key", None) != key:
            self._cc_cached = CellCollision(plant.obstacles, bool(self.self_collision), float(self.collision_margin))
            self._key = key
        self._check_reset(self._cc_cached)

    def do_step(self, t: float, h: float) -> None:
        self._check(t)
