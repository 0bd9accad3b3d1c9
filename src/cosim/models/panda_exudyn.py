"""The Panda as a multibody system in Exudyn, with its joint servo inside.

Plant
    An Exudyn ``ObjectKinematicTree`` (minimal coordinates, 7 revolute joints)
    built from the pinocchio model's joint placements and link inertias (see
    :mod:`cosim.models.panda_model`), so its forward dynamics equal pinocchio's ABA
    to round-off (checked in ``tests/models/test_panda_units.py``).  The
    ``exudyn.robotics`` Panda model is not used: it does not match the URDF.
    A rigid payload (parameters ``payload_*``) is part of link 7's inertia
    (the servo's feed-forward knows it).  A freely swinging pendulum
    (parameters ``pendulum_*``, the thesis's bin-picking load: 250 g bob,
    20 g rod) hangs from the TCP by a spherical joint as a separate rigid body;
    the servo does *not* know it (the PD part takes its load), so with a
    pendulum ``tau`` differs from RNEA of the arm alone by the pendulum's
    reaction.

Servo
    Runs inside this unit, at every internal solver step, because a joint PD
    outside the physics unit with torques held over a 1 ms communication step
    went unstable with realistic gains (the model has no rotor inertia).  Per joint::

        tau = tau_ff + kp * (q_r - q) + kd * (qd_r - qd),
        tau_ff = RNEA(q_r, qd_r, qdd_r)          (pinocchio, same model as the plant)

    The PD part is Exudyn's built-in kinematic-tree joint control
    (``jointPControlVector``/``jointDControlVector``), which enters the solver's
    Jacobian and is evaluated in C++.  The reference and feed-forward enter as one
    constant torque per solver step, ``jointForceVector = tau_ff + kp q_r + kd qd_r``,
    with zero position and velocity offsets: Exudyn then applies
    ``jointForceVector - kp q - kd qd``, the same law with one parameter set per
    step instead of three.  The reference within a
    communication step ``[t, t+h]`` is extrapolated from the inputs sampled at
    ``t`` (exact inside a parabolic-blend phase) and evaluated at
    ``t_k + ref_phase * dt`` of each internal step ``[t_k, t_k + dt]``; the default
    0.5 is the middle of the step.  ``ref_timing``
    says when the inputs were sampled: at ``t`` (``"step_start"``, default:
    Jacobi) or at ``t + h`` (``"step_end"``: Gauss-Seidel with the trajectory
    stepped first), in which case the reference is extrapolated backwards, so
    the arm does not run one communication step ahead of its reference.

Stepping
    ``MainSolverImplicitSecondOrder`` (generalized-alpha), initialised once per
    run; every internal step sets both ``solver.it.startTime`` and
    ``solver.it.endTime`` and calls ``SolveSteps`` (setting only one of them
    silently re-integrates from the start).  The generalized-alpha method
    satisfies the equations of motion at the end of each step, so the output
    ``tau`` (the servo law at the end-of-step state) equals
    ``RNEA(q, qd, qdd)`` of the outputs to the Newton tolerance.

Newton Jacobian
    ``SolveSteps`` asks for a new Newton Jacobian at every call, i.e. every
    communication step, and Exudyn builds it by numerical differentiation (14
    evaluations of the tree's forces for 7 joints): two thirds of the solver's time.
    Without a pendulum, :class:`NewtonJacobian` answers that request instead:
    ``J = c M(q) - beta h^2 K - gamma h D`` with the mass matrix ``M`` Exudyn has
    just evaluated at the step's predicted state and the stiffness and damping
    parts ``K``, ``D`` (PD gains, gravity, Coriolis; they change slowly) kept from
    Exudyn's own differentiation, redone every ``JACOBIAN_REFRESH_STEPS`` steps and
    whenever the modified Newton method asks again within a step (poor
    contraction).  The Jacobian only steers the Newton iteration: the converged
    step satisfies the same equations to the same tolerance, so results agree with
    a fresh Jacobian per step to that tolerance (checked against the outputs before
    this change in ``tests/models/test_panda_exudyn_reference.py``).

Lock-step
    :class:`PandaExudynBatch`, the unit's vectorised twin, runs K design points
    of a sweep as K kinematic trees in one Exudyn system, one ``SolveSteps``
    per communication step for all of them (``cosim.execution.lockstep``; the
    study's configuration only), its per-row arithmetic in one compiled call
    (:mod:`cosim.models.panda_rows`).  Its rows agree with single runs to the
    Newton tolerance (they share one Newton iteration), not bit for bit.

The Exudyn system is built once per instance and rebuilt only when the payload
changes (or, with a pendulum, every run: its initial pose follows the arm's);
``initialize()`` after ``reset()`` otherwise just re-applies gains and the
initial state (about 0.05 ms).
"""

from __future__ import annotations

import math
from operator import gt, lt, sub

import exudyn as exu
import numpy as np
import pinocchio as pin
from exudyn.itemInterface import (
    MarkerBodyRigid,
    MarkerKinematicTreeRigid,
    NodeGenericODE2,
    ObjectGenericODE2,
    ObjectJointSpherical,
    ObjectKinematicTree,
)
from exudyn.utilities import RigidBodyInertia

from cosim.units.protocol import Variable
from cosim.units.python.batch import NotBatchable, PythonBatchUnit
from cosim.units.python.unit import PythonUnit

from .panda_model import EE_FRAME, GRAVITY, N_JOINTS, cached_model, ee_frame_id, payload_key, robot_variables
from .panda_rows import KernelsUnavailable, PandaRowKernels

# libfranka example joint_impedance_control.cpp: k_gains and d_gains.
DEFAULT_KP = (600.0, 600.0, 600.0, 600.0, 250.0, 150.0, 50.0)  # N.m/rad
REF_TIMINGS = ("step_start", "step_end")
DEFAULT_KD = (50.0, 50.0, 50.0, 50.0, 30.0, 25.0, 15.0)  # N.m.s/rad
ONE_STEP = 1 + 1e-9  # a communication step up to this many substeps is one solver step (round-off in t + h)


def build_kinematic_tree(model: pin.Model, q0, qd0, gravity=GRAVITY):
    """An Exudyn system of the serial revolute chain in pinocchio ``model``.

    Returns ``(system_container, mbs, node, tree)``; the system is assembled.
    Joint ``i``'s placement in its parent (rotation ``R``, translation ``p``)
    maps to ``jointTransformations[i] = R`` and ``jointOffsets[i] = p``; link
    inertias are given about the centre of mass in joint coordinates, as both
    libraries store them.  Raises ValueError for a model that is not a chain of
    revolute-z joints.
    """
    sc = exu.SystemContainer()
    mbs = sc.AddSystem()
    node, tree = add_kinematic_tree(mbs, model, q0, qd0, gravity)
    mbs.Assemble()
    return sc, mbs, node, tree


def add_kinematic_tree(mbs, model: pin.Model, q0, qd0, gravity=GRAVITY) -> tuple[int, int]:
    """Add the chain of :func:`build_kinematic_tree` to ``mbs`` (not assembled); returns ``(node, tree)``."""
    n = model.nv
    for i in range(1, model.njoints):
        if model.joints[i].shortname() != "JointModelRZ" or model.parents[i] != i - 1:
            raise ValueError("only serial chains of revolute-z joints are supported")
    rots, offsets = exu.Matrix3DList(), exu.Vector3DList()
    inertias, coms, masses = exu.Matrix3DList(), exu.Vector3DList(), []
    for i in range(1, model.njoints):
        placement, inertia = model.jointPlacements[i], model.inertias[i]
        rots.Append(placement.rotation)
        offsets.Append(placement.translation)
        inertias.Append(inertia.inertia)  # about the COM, joint axes
        coms.Append(inertia.lever)
        masses.append(inertia.mass)
    node = mbs.AddNode(NodeGenericODE2(referenceCoordinates=[0.0] * n, initialCoordinates=list(q0),
                                       initialCoordinates_t=list(qd0), numberOfODE2Coordinates=n))
    zeros = [0.0] * n
    tree = mbs.AddObject(ObjectKinematicTree(
        nodeNumber=node, jointTypes=[exu.JointType.RevoluteZ] * n, linkParents=list(range(-1, n - 1)),
        jointTransformations=rots, jointOffsets=offsets, linkInertiasCOM=inertias, linkCOMs=coms,
        linkMasses=masses, gravity=list(gravity), jointForceVector=zeros, jointPositionOffsetVector=zeros,
        jointVelocityOffsetVector=zeros, jointPControlVector=zeros, jointDControlVector=zeros,
    ))
    return node, tree


# Shape assumptions of the pendulum (the thesis gives only its masses): a thin rod
# and a spherical bob; the radii only keep the inertia about the rod axis non-zero.
ROD_RADIUS = 0.005  # m
BOB_RADIUS = 0.03  # m


def add_pendulum(mbs, tree, model: pin.Model, q0, qd0, bob_mass: float, rod_mass: float, length: float,
                 gravity=GRAVITY) -> int:
    """Hang a rod-and-bob pendulum from the TCP of the kinematic tree by a spherical joint.

    It starts hanging straight down, moving with the TCP.  Returns the body's
    object number.  The body frame has its origin at the centre of mass and z
    pointing from the bob to the anchor.
    """
    m = bob_mass + rod_mass
    d = (rod_mass * length / 2 + bob_mass * length) / m  # COM below the anchor
    z_rod, z_bob = d - length / 2, d - length  # rod centre and bob in body coordinates
    ixx = rod_mass * (length**2 / 12 + z_rod**2) + bob_mass * (0.4 * BOB_RADIUS**2 + z_bob**2)
    izz = 0.5 * rod_mass * ROD_RADIUS**2 + 0.4 * bob_mass * BOB_RADIUS**2
    inertia = RigidBodyInertia(mass=m, inertiaTensor=np.diag([ixx, ixx, izz]))
    data = model.createData()
    frame = model.getFrameId(EE_FRAME)
    pin.forwardKinematics(model, data, np.asarray(q0, float), np.asarray(qd0, float))
    anchor = pin.updateFramePlacement(model, data, frame).translation.copy()
    v_anchor = pin.getFrameVelocity(model, data, frame, pin.LOCAL_WORLD_ALIGNED).linear.copy()
    body = mbs.CreateRigidBody(inertia=inertia, referencePosition=anchor - np.array([0.0, 0.0, d]),
                               initialVelocity=v_anchor, gravity=list(gravity),
                               nodeType=exu.NodeType.RotationEulerParameters)
    tcp = model.frames[frame]
    m_tree = mbs.AddMarker(MarkerKinematicTreeRigid(objectNumber=tree, linkNumber=tcp.parentJoint - 1,
                                                    localPosition=tcp.placement.translation))
    m_body = mbs.AddMarker(MarkerBodyRigid(bodyNumber=body, localPosition=[0.0, 0.0, d]))
    mbs.AddObject(ObjectJointSpherical(markerNumbers=[m_tree, m_body]))
    mbs.Assemble()
    return body


def solve_one_step(solver, mbs, settings: exu.SimulationSettings, start: float, end: float) -> None:
    """One implicit step of ``mbs`` from ``start`` to ``end`` (both set every call, see PandaExudyn's notes).

    Raises RuntimeError naming the interval and Exudyn's error when the solver fails.
    """
    it = solver.it
    it.startTime = start
    it.endTime = end
    if not solver.SolveSteps(mbs, settings):
        raise RuntimeError(f"Exudyn solver failed in [{start:g}, {end:g}] s: {solver.GetErrorString()}")


def solver_settings() -> exu.SimulationSettings:
    """The simulation settings of every run: one implicit step per ``SolveSteps`` call, no files."""
    s = exu.SimulationSettings()
    s.timeIntegration.numberOfSteps = 1  # SolveSteps runs one internal step per call
    s.timeIntegration.verboseMode = 0
    s.solution.file.write = False  # default: a solution/ folder in the working directory
    s.solution.sensors.active = False
    s.timeIntegration.newton.relativeTolerance = 1e-10  # tau output exact to ~1e-9 N.m
    # the Jacobian (mass matrix + PD terms) changes little per 1 ms step: reusing it saves ~10 %
    s.timeIntegration.newton.useModifiedNewton = True
    return s


JACOBIAN_REFRESH_STEPS = 10  # re-differentiate K and D this often (fewest solver CPU seconds at 5-20)


class NewtonJacobian:
    """Exudyn's ``ComputeNewtonJacobian`` for the generalized-alpha solver, cheaper on a kinematic tree.

    Registered with ``solver.SetUserFunctionComputeNewtonJacobian`` for systems
    without algebraic equations (constraints).  Exudyn's own Jacobian is
    ``c M + J_rhs`` with ``c = (1 - alpha_m) / (1 - alpha_f)`` and
    ``J_rhs = -beta h^2 dF/dq - gamma h dF/dqd`` (F: the forces on the right-hand
    side); this keeps ``J_rhs`` (from ``ComputeJacobianODE2RHS``, the same numerical
    differentiation) for up to ``refresh_steps`` requests and adds the current mass
    matrix each time.  Holds no reference to the unit or the solver (the solver is
    passed in), so registering it creates no reference cycle through C++.
    """

    def __init__(self, refresh_steps: int = JACOBIAN_REFRESH_STEPS):
        self.refresh_steps = refresh_steps
        self.reset()

    def reset(self) -> None:
        """Forget the kept part (new gains, new run)."""
        self._rhs_part = None
        self._step_size = None
        self._age = 0

    def __call__(self, solver, mbs, settings) -> bool:
        it = solver.it
        h = it.currentStepSize
        if (self._rhs_part is None or it.newtonSteps > 1 or h != self._step_size
                or self._age >= self.refresh_steps):
            # it.newtonSteps > 1: the modified Newton method found the Jacobian poor and asks again
            self._differentiate(solver, mbs, h)
        self._age += 1
        # c M + J_rhs in the fresh array Exudyn hands out (no temporaries: at K lock-step rows they are 7K x 7K)
        jacobian = solver.GetSystemMassMatrix()
        jacobian *= self._mass_factor
        jacobian += self._rhs_part
        solver.SetSystemJacobian(jacobian)
        return True

    def _differentiate(self, solver, mbs, h: float) -> None:
        """Exudyn's numerical differentiation of the forces: the part of the Jacobian kept for later steps."""
        solver.ComputeJacobianODE2RHS(mbs, -solver.newmarkBeta * h * h, -solver.newmarkGamma * h)
        self._rhs_part = solver.GetSystemJacobian()
        self._mass_factor = (1.0 - solver.alphaM) / (1.0 - solver.alphaF)
        self._step_size = h
        self._age = 0


class PandaExudyn(PythonUnit):
    """Panda arm simulated in Exudyn with a PD + inverse-dynamics feed-forward joint servo.

    The arm starts on the reference: ``q = q_ref``, ``qd = qd_ref`` as
    the inputs are at initialization (or, if they differ at the first step at the
    start time, as they are then).  Ports: :func:`models.panda_model.robot_variables`
    plus the servo and pendulum parameters below and ``pendulum_angle``.
    Raises (as a UnitError) when the solver fails or the motion diverges.
    """

    variables = robot_variables() + (
        Variable("kp", "parameter", unit="N.m/rad", start=DEFAULT_KP, shape=(N_JOINTS,),
                 description="servo position gains (libfranka example)", variability="fixed"),
        Variable("kd", "parameter", unit="N.m.s/rad", start=DEFAULT_KD, shape=(N_JOINTS,),
                 description="servo velocity gains (libfranka example)", variability="fixed"),
        Variable("substep", "parameter", unit="s", start=1e-3, min=0.0,
                 description="largest internal solver step; a communication step is split evenly", variability="fixed"),
        Variable("ref_phase", "parameter", start=0.5, min=0.0, max=1.0,
                 description="where in each internal step the reference is evaluated (0 start, 0.5 middle, 1 end)",
                 variability="fixed"),
        Variable("ref_timing", "parameter", type="String", start="step_start",
                 description="when the reference inputs seen by do_step(t, h) were sampled: 'step_start' (at t, "
                             "e.g. Jacobi) or 'step_end' (at t + h: Gauss-Seidel after a trajectory unit that stepped first)",
                 variability="fixed"),
        Variable("pendulum_bob_mass", "parameter", unit="kg", start=0.0, min=0.0,
                 description="bob of a pendulum swinging from the TCP (bin picking: 0.25); 0 and no rod: none",
                 variability="fixed"),
        Variable("pendulum_rod_mass", "parameter", unit="kg", start=0.0, min=0.0,
                 description="rod of the pendulum (bin picking: 0.02)", variability="fixed"),
        Variable("pendulum_length", "parameter", unit="m", start=0.2, min=0.0,
                 description="anchor to bob centre (not given in the thesis; an assumption)", variability="fixed"),
        Variable("pendulum_angle", "output", unit="rad", start=0.0,
                 description="angle of the pendulum from the downward vertical (0 without a pendulum)"),
    )

    def initialize(self) -> None:
        if not self.substep > 0:
            raise ValueError(f"substep must be > 0, got {self.substep}")
        key = payload_key(self.payload_mass, self.payload_com, self.payload_inertia)
        q0 = np.array(self.q_ref, dtype=float)  # the run starts on the reference
        qd0 = np.array(self.qd_ref, dtype=float)
        pendulum = self.pendulum_bob_mass + self.pendulum_rod_mass > 0 and self.pendulum_length > 0
        if pendulum or getattr(self, "_key", None) != key:
            self._build(key, q0, qd0)
        self._body = None
        if pendulum:  # starts hanging below the TCP wherever the arm starts: a fresh system
            self._body = add_pendulum(self._mbs, self._tree, self._model, q0, qd0, float(self.pendulum_bob_mass),
                                      float(self.pendulum_rod_mass), float(self.pendulum_length))
            self._key = None  # the next run rebuilds
            self._jacobian = None  # constraints: Exudyn's own Jacobian (NewtonJacobian has no constraint part)
        else:
            sd = self._mbs.systemData
            sd.SetODE2Coordinates(q0, configuration=exu.ConfigurationType.Initial)
            sd.SetODE2Coordinates_t(qd0, configuration=exu.ConfigurationType.Initial)
            if self._jacobian is None:  # a fresh system and solver (see _build)
                self._jacobian = NewtonJacobian()
                self._solver.SetUserFunctionComputeNewtonJacobian(self._mbs, self._jacobian)
        self._kp = np.array(self.kp, dtype=float)
        self._kd = np.array(self.kd, dtype=float)
        self._mbs.SetObjectParameter(self._tree, "jointPControlVector", self._kp)
        self._mbs.SetObjectParameter(self._tree, "jointDControlVector", self._kd)
        # limits as Python floats for the per-step checks in _read_outputs
        self._q_min_list, self._q_max_list = np.asarray(self.q_min, float).tolist(), np.asarray(self.q_max, float).tolist()
        self._qd_max_list = np.asarray(self.qd_max, float).tolist()
        self._tau_max_list = np.asarray(self.tau_max, float).tolist()
        self._set_servo(q0, qd0, np.array(self.qdd_ref, dtype=float))
        st = self._settings.timeIntegration
        st.startTime = self.start_time
        st.endTime = self.start_time + self.substep
        self._solver.InitializeSolver(self._mbs, self._settings)  # also computes initial accelerations
        if self._jacobian is not None:
            self._jacobian.reset()  # the gains may have changed
        self._start_ref = (q0, qd0)
        # the study's configuration: the inputs are the reference at the end of the step, applied there
        # (step_end, ref_phase 1); do_step then skips the general reference arithmetic when one solver
        # step covers the communication step
        self._at_reference = self.ref_timing == "step_end" and self.ref_phase == 1.0
        self._ee_last = None  # the path starts at the initial pose (a list of 3 floats once set)
        self.ee_path_length = 0.0
        self._read_outputs(q0)

    def _build(self, key, q0, qd0) -> None:
        self._model = cached_model(*key)
        self._data = self._model.createData()
        self._ee = ee_frame_id(self._model)
        self._sc, self._mbs, self._node, self._tree = build_kinematic_tree(self._model, q0, qd0)
        self._settings = solver_settings()
        self._solver = exu.MainSolverImplicitSecondOrder()
        self._jacobian: NewtonJacobian | None = None  # Exudyn's own Newton Jacobian until initialize() sets one
        self._key = key

    def _set_servo(self, q_r, qd_r, qdd_r) -> None:
        """Apply the servo law for reference ``(q_r, qd_r, qdd_r)`` to the next solver step."""
        # kp q_r + kd qd_r + tau_ff: the part of the law that is constant over the step
        # (in place on fresh arrays: the same operations in the same order as the plain expression)
        tau = self._kp * q_r
        tau += self._kd * qd_r
        tau += pin.rnea(self._model, self._data, q_r, qd_r, qdd_r)  # the feed-forward, a new array
        self._tau_const = tau
        self._mbs.SetObjectParameter(self._tree, "jointForceVector", tau)

    def do_step(self, t: float, h: float) -> None:
        if self._at_reference and h <= self.substep * ONE_STEP:
            # the study's case (step_end, ref_phase 1, one solver step per communication step): the
            # general path below would compute the same (reference time 0: the inputs as they are;
            # one solver step from t to t + h) with more Python around it
            q_ref = self.q_ref
            self._start_ref = None
            self._set_servo(q_ref, self.qd_ref, self.qdd_ref)
            solve_one_step(self._solver, self._mbs, self._settings, t, t + h)
            self._read_outputs(q_ref)
            return
        if self.ref_timing not in REF_TIMINGS:
            raise ValueError(f"ref_timing must be one of {REF_TIMINGS}, got {self.ref_timing!r}")
        if self.ref_timing == "step_end":
            # The inputs already hold the reference at t + h (the trajectory stepped
            # first); the start of the run was delivered in initialization.
            self._start_ref = None
            shift = h
        else:
            shift = 0.0
        if self._start_ref is not None:
            # The run starts on the reference.  A master may deliver the reference's
            # start only after this unit initialized (its outputs were not ready in
            # initialization mode): then start again from what the first step sees.
            q0, qd0 = self._start_ref
            self._start_ref = None
            if t == self.start_time and not (np.array_equal(q0, self.q_ref) and np.array_equal(qd0, self.qd_ref)):
                self.initialize()
                self._start_ref = None
        n_sub = max(1, math.ceil(h / self.substep - 1e-9))  # 1 for h <= substep * ONE_STEP
        dt = h / n_sub
        q_ref, qd_ref, qdd_ref = self.q_ref, self.qd_ref, self.qdd_ref  # float arrays, not modified here
        solver, mbs, settings = self._solver, self._mbs, self._settings
        for k in range(n_sub):
            tau_k = (k + self.ref_phase) * dt - shift  # reference time, relative to the input sample
            if tau_k == 0.0:  # the inputs are the reference (the study's step_end, ref_phase 1, one solver step)
                self._set_servo(q_ref, qd_ref, qdd_ref)
            else:
                qd_r = qd_ref + qdd_ref * tau_k
                # q + qd tau + qdd tau^2 / 2 = q + (qd + qd_r) tau / 2, with one temporary less
                self._set_servo(q_ref + (qd_ref + qd_r) * (0.5 * tau_k), qd_r, qdd_ref)
            solve_one_step(solver, mbs, settings, t + k * dt, t + (k + 1) * dt)
        end = h - shift  # t + h relative to the input sample
        self._read_outputs(q_ref if end == 0.0 else q_ref + qd_ref * end + 0.5 * qdd_ref * end * end)

    def _read_outputs(self, q_ref_now: np.ndarray) -> None:
        """Outputs at the end of the step from Exudyn's state.

        Runs every communication step, so the reductions (max, limits, finiteness)
        use Python floats: on 7 values they cost a fraction of numpy's per-call
        overhead, and give the same results (the same IEEE operations).
        """
        sd = self._mbs.systemData
        # the tree's node was added first: its 7 coordinates lead the system's ODE2 vector
        q, qd, qdd = sd.GetODE2Coordinates(), sd.GetODE2Coordinates_t(), sd.GetODE2Coordinates_tt()
        if self._body is not None:
            q, qd, qdd = q[:N_JOINTS], qd[:N_JOINTS], qdd[:N_JOINTS]
        # outputs are written into the unit's arrays, never rebound: a master may hold on to them
        self.q[:], self.qd[:], self.qdd[:] = q, qd, qdd
        # the servo law at the end-of-step state: what the solver applied there
        tau = self._tau_const - self._kp * q - self._kd * qd
        self.tau[:] = tau
        pin.forwardKinematics(self._model, self._data, q)
        ee = pin.updateFramePlacement(self._model, self._data, self._ee).translation
        self.ee_pos[:] = ee
        ee_now = ee.tolist()
        if self._ee_last is not None:  # one straight chord per communication step
            self.ee_path_length += math.dist(ee_now, self._ee_last)
        self._ee_last = ee_now
        q_list, qd_list, tau_list = q.tolist(), qd.tolist(), tau.tolist()
        self.tracking_error = max(map(abs, map(sub, q_list, q_ref_now.tolist())))
        ratio = [abs(x) / m for x, m in zip(tau_list, self._tau_max_list)]
        self.tau_ratio[:] = ratio
        self.limit_violated = (max(ratio) > 1.0 or any(map(lt, q_list, self._q_min_list))
                               or any(map(gt, q_list, self._q_max_list))
                               or any(abs(v) > m for v, m in zip(qd_list, self._qd_max_list)))
        if self._body is not None:
            axis = self._mbs.GetObjectOutputBody(self._body, exu.OutputVariableType.RotationMatrix).reshape(3, 3)[:, 2]
            self.pendulum_angle = float(np.arccos(np.clip(axis[2], -1.0, 1.0)))  # body z is world z at rest
        if not math.isfinite(sum(q_list)):  # a NaN or an infinity makes the sum non-finite
            raise RuntimeError("the simulation diverged (non-finite joint angles)")


class PandaExudynBatch(PythonBatchUnit):
    """:class:`PandaExudyn` for K design points at once (lock-step runs, :mod:`cosim.execution.lockstep`).

    One Exudyn system holds K kinematic trees, one per row, and one
    ``SolveSteps`` call advances them all.  Per communication step the Python
    around the solver is a fixed number of calls for all K rows: one compiled
    call for the feed-forward RNEA and servo constant of every active row
    (:mod:`cosim.models.panda_rows`), one parameter set for all K constant
    torques (an ``ObjectGenericODE2`` on the K trees' nodes carries them as its
    ``forceVector``; the trees' own ``jointForceVector`` stays zero), the solver
    call, three state reads, one compiled call for the outputs (servo torque,
    TCP kinematics, path, tracking error, torque ratios, limit flags), and one
    Newton-Jacobian callback (:class:`NewtonJacobian`, the K blocks at once).
    The linear solver is sparse (K independent 7x7 blocks: linear in K, where
    a dense LU is cubic).

    Same model, servo law and solver settings as the single unit, but the K
    trees share one Newton iteration, whose convergence test and step-size
    control see all K residuals together, and the feed-forward and TCP come
    from CasADi's generated C instead of pinocchio (equal to round-off): a
    row's results equal a single run's to the Newton tolerance, not bit for
    bit (checked within the stated bounds of ``tests/models/test_panda_exudyn_reference.py``).

    Only the study's configuration runs here: ``ref_timing = "step_end"``,
    ``ref_phase = 1``, one solver step per communication step, no pendulum;
    otherwise :class:`NotBatchable` is raised and the points run one by one.
    Rows whose point has ended are still integrated (with their last torque)
    but no longer computed or read.
    """

    @property
    def active(self) -> np.ndarray:
        """The rows still running (int64 indices; the compiled calls read them in place)."""
        return self._active

    @active.setter
    def active(self, rows: np.ndarray) -> None:
        self._active = np.ascontiguousarray(rows, dtype=np.int64)
        self._active_count, self._active_address = len(self._active), self._active.ctypes.data

    def initialize(self) -> None:
        if not (np.all(self.ref_timing == "step_end") and np.all(self.ref_phase == 1.0)):
            raise NotBatchable("PandaExudyn runs in lock-step only with ref_timing 'step_end' and ref_phase 1")
        if ((self.pendulum_bob_mass + self.pendulum_rod_mass > 0) & (self.pendulum_length > 0)).any():
            raise NotBatchable("PandaExudyn with a pendulum runs one by one (constraints)")
        if not (np.all(self.substep > 0) and np.all(self.substep == self.substep[0])):
            raise NotBatchable("PandaExudyn runs in lock-step only with one substep > 0 for all points")
        keys = [payload_key(self.payload_mass[k], self.payload_com[k], self.payload_inertia[k]) for k in range(self.rows)]
        q0 = np.array(self.q_ref, dtype=float)  # every run starts on its reference
        qd0 = np.array(self.qd_ref, dtype=float)
        if getattr(self, "_keys", None) != keys:
            self._build(keys, q0, qd0)
        mbs = self._mbs
        mbs.systemData.SetODE2Coordinates(q0.ravel(), configuration=exu.ConfigurationType.Initial)
        mbs.systemData.SetODE2Coordinates_t(qd0.ravel(), configuration=exu.ConfigurationType.Initial)
        for k, tree in enumerate(self._trees):
            mbs.SetObjectParameter(tree, "jointPControlVector", self.kp[k])
            mbs.SetObjectParameter(tree, "jointDControlVector", self.kd[k])
        # the attributes are written in place until the next reset: the compiled calls keep their addresses
        self._force = np.zeros((self.rows, N_JOINTS))  # kp q_ref + kd qd_ref + RNEA per row: Exudyn's constant torques
        self._force_flat = self._force.reshape(-1)
        self._q_flat, self._qd_flat, self._qdd_flat = self.q.reshape(-1), self.qd.reshape(-1), self.qdd.reshape(-1)
        arrays = {name: getattr(self, name) for name in
                  ("q_ref", "qd_ref", "qdd_ref", "kp", "kd", "payload_mass", "payload_com", "payload_inertia", "q_min",
                   "q_max", "qd_max", "tau_max", "q", "qd", "tau", "ee_pos", "ee_path_length", "tracking_error",
                   "tau_ratio", "limit_violated")}
        try:
            self._kernels = PandaRowKernels(dict(arrays, force=self._force, ee_last=np.zeros((self.rows, 3))), self.rows)
        except KernelsUnavailable as exc:  # e.g. no C compiler: the single unit needs none
            raise NotBatchable(str(exc)) from exc
        everyone = np.arange(self.rows, dtype=np.int64)
        self._set_servo(len(everyone), everyone.ctypes.data)
        st = self._settings.timeIntegration
        st.startTime = self.start_time
        st.endTime = self.start_time + float(self.substep[0])
        self._solver.InitializeSolver(mbs, self._settings)
        self._jacobian.reset()
        self._read_outputs(len(everyone), everyone.ctypes.data, first=True)
        self.ee_path_length[:] = 0.0

    def _build(self, keys, q0, qd0) -> None:
        self._sc = exu.SystemContainer()
        self._mbs = self._sc.AddSystem()
        self._trees, nodes = [], []
        for k, key in enumerate(keys):
            node, tree = add_kinematic_tree(self._mbs, cached_model(*key), q0[k], qd0[k])
            nodes.append(node)
            self._trees.append(tree)
        # one force vector over all K trees' joints: one parameter set per step instead of K
        self._forces = self._mbs.AddObject(ObjectGenericODE2(nodeNumbers=nodes, forceVector=[0.0] * (N_JOINTS * len(keys))))
        self._mbs.Assemble()
        self._settings = solver_settings()
        self._settings.linearSolver.solverType = exu.LinearSolverType.EigenSparse
        self._solver = exu.MainSolverImplicitSecondOrder()
        self._jacobian = NewtonJacobian()
        self._solver.SetUserFunctionComputeNewtonJacobian(self._mbs, self._jacobian)
        self._keys = keys

    def _set_servo(self, count: int, rows_address: int) -> None:
        """Apply the servo law of the listed rows for their reference inputs to the next solver step."""
        self._kernels.servo(count, rows_address)
        self._mbs.SetObjectParameter(self._forces, "forceVector", self._force_flat)

    def do_step(self, t: float, h: float) -> None:
        if h > self.substep[0] * ONE_STEP:
            raise NotBatchable("PandaExudyn runs in lock-step only with one solver step per communication step")
        count, address = self._active_count, self._active_address
        self._set_servo(count, address)
        solve_one_step(self._solver, self._mbs, self._settings, t, t + h)
        self._read_outputs(count, address)

    def _read_outputs(self, count: int, rows_address: int, first: bool = False) -> None:
        """The listed rows' outputs from the end-of-step state (every row's q, qd, qdd are read)."""
        sd = self._mbs.systemData  # the trees' nodes, in row order, make up the system's ODE2 vector
        self._q_flat[:] = sd.GetODE2Coordinates()
        self._qd_flat[:] = sd.GetODE2Coordinates_t()
        self._qdd_flat[:] = sd.GetODE2Coordinates_tt()
        if self._kernels.outputs(count, rows_address, first):
            raise RuntimeError("the simulation diverged (non-finite joint angles)")


PandaExudyn.batch_class = PandaExudynBatch
