"""The Franka Emika Panda as every robot unit sees it: model, limits, angle conventions.

One place loads the robot so that the inverse-dynamics unit, the Exudyn unit
and any planner agree on kinematics, inertias and limits.

Robot model
    The URDF shipped in ``example-robot-data`` (``panda_description/urdf/panda.urdf``),
    whose inertial parameters are those identified by Gaz et al. (2019), the set
    the thesis used.  The two finger joints are locked (closed, 0 m) with
    :func:`pinocchio.buildReducedModel`, so the model has exactly the 7 arm
    joints; the hand and fingers become part of link 7's inertia.

End effector
    ``ee_pos`` everywhere means the origin of the URDF frame ``panda_hand_tcp``
    (0.107 m flange + 0.1034 m hand along link 7's z axis), in the base frame.

Joint limits
    :data:`FRANKA_DOC_LIMITS` are Franka's published documentation values
    ("Robot and interface specifications", frankaemika.github.io/docs/control_parameters.html,
    Panda, joint space): they are the defaults of every unit.
    :data:`DATASHEET_VELOCITY` is the datasheet's second set (150 deg/s joints
    1-4, 180 deg/s joints 5-7).

Angle conventions
    Units take and give radians in the URDF convention.  The thesis (and the
    Unity scene it used) measures angles in degrees from a zero pose where the
    arm is stretched out horizontally; :func:`thesis_to_urdf` converts.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

N_JOINTS = 7
EE_FRAME = "panda_hand_tcp"
GRAVITY = np.array([0.0, 0.0, -9.81])  # pinocchio's default, m/s^2


@dataclass(frozen=True)
class JointLimits:
    """Per-joint limits, arrays of 7 (rad, rad/s, rad/s^2, N.m)."""

    q_min: np.ndarray
    q_max: np.ndarray
    qd_max: np.ndarray
    qdd_max: np.ndarray
    tau_max: np.ndarray


# Franka documentation, "Robot and interface specifications" (Panda), joint space limits.
FRANKA_DOC_LIMITS = JointLimits(
    q_min=np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973]),
    q_max=np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973]),
    qd_max=np.array([2.1750, 2.1750, 2.1750, 2.1750, 2.6100, 2.6100, 2.6100]),
    qdd_max=np.array([15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0]),
    tau_max=np.array([87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0]),
)

# Franka Emika Panda datasheet: joint speeds 150 deg/s (joints 1-4) and 180 deg/s (joints 5-7).
DATASHEET_VELOCITY = np.deg2rad([150.0, 150.0, 150.0, 150.0, 180.0, 180.0, 180.0])

# Thesis (Unity) angle zero -> URDF angle zero, see thesis_to_urdf.
_THESIS_OFFSET_DEG = np.array([0.0, 90.0, 0.0, 0.0, 0.0, 90.0, 0.0])
_THESIS_SIGN = np.array([1.0, 1.0, 1.0, -1.0, 1.0, 1.0, 1.0])


def thesis_to_urdf(q_deg) -> np.ndarray:
    """Thesis joint angles (degrees, Unity zero pose) -> URDF joint angles (radians).

    ``q_urdf = (q1, q2 + 90 deg, q3, -q4, q5, q6 + 90 deg, q7)``.  In the thesis
    (section 7.2.3, eq. 7-21/7-22) the all-zero pose is the arm stretched out
    horizontally with the hand pointing down; in the URDF that pose is
    ``(0, 90, 0, 0, 0, 90, 0)`` degrees, and the thesis's elbow angle q4 bends
    the forearm *downwards* for positive values, which is URDF's negative q4.
    ``tests/models/test_trajectory.py`` checks this against the poses the thesis
    describes with pinocchio forward kinematics.

    Accepts an array of shape (..., 7); raises ValueError for another last axis.
    """
    q = np.asarray(q_deg, dtype=float)
    if q.shape[-1:] != (N_JOINTS,):
        raise ValueError(f"expected 7 joint angles in the last axis, got shape {q.shape}")
    return np.deg2rad(_THESIS_SIGN * q + _THESIS_OFFSET_DEG)


def urdf_to_thesis(q_rad) -> np.ndarray:
    """Inverse of :func:`thesis_to_urdf`: URDF radians -> thesis degrees."""
    q = np.asarray(q_rad, dtype=float)
    if q.shape[-1:] != (N_JOINTS,):
        raise ValueError(f"expected 7 joint angles in the last axis, got shape {q.shape}")
    return _THESIS_SIGN * (np.rad2deg(q) - _THESIS_OFFSET_DEG)


def urdf_path() -> str:
    """Path of the Panda URDF in the installed example-robot-data package.

    Raises FileNotFoundError if the package's data files are not installed.
    """
    try:  # the Python module exists in some builds of the package, not in the cmeel wheel
        import example_robot_data  # type: ignore

        base = example_robot_data.getModelPath("panda_description/urdf/panda.urdf")
        path = os.path.join(base, "panda_description/urdf/panda.urdf")
        if os.path.isfile(path):
            return path
    except Exception:
        pass
    # the cmeel wheel installs the data under <site-packages>/cmeel.prefix/share
    candidates = [
        os.path.join(p, "cmeel.prefix", "share", "example-robot-data", "robots", "panda_description", "urdf", "panda.urdf")
        for p in _site_dirs()
    ]
    for c in candidates:
        if os.path.isfile(c):
            return c
    raise FileNotFoundError("panda.urdf of example-robot-data not found; install 'example-robot-data'")


def _site_dirs() -> list[str]:
    import site
    import sysconfig

    dirs = [sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]]
    try:
        dirs += site.getsitepackages()
    except AttributeError:  # virtualenvs of old
        pass
    return list(dict.fromkeys(dirs))


@functools.lru_cache(maxsize=1)
def _arm_model() -> pin.Model:
    full = pin.buildModelFromUrdf(urdf_path())
    lock = [full.getJointId(n) for n in ("panda_finger_joint1", "panda_finger_joint2")]
    model = pin.buildReducedModel(full, lock, pin.neutral(full))  # fingers closed (0 m)
    assert model.nq == N_JOINTS
    return model


def panda_model(payload_mass: float = 0.0, payload_com=(0.0, 0.0, 0.0), payload_inertia=(0.0,) * 6) -> pin.Model:
    """A fresh copy of the 7-joint Panda model, with an optional rigid payload.

    The payload is a rigid body fixed to the hand: ``payload_mass`` (kg),
    ``payload_com`` (m, its centre of mass in the ``panda_hand_tcp`` frame) and
    ``payload_inertia`` (kg.m^2, ``Ixx, Iyy, Izz, Ixy, Ixz, Iyz`` about its centre
    of mass, in ``panda_hand_tcp`` axes).  It is added to link 7's inertia.

    Raises ValueError for a negative mass.
    """
    if payload_mass < 0:
        raise ValueError(f"payload_mass must be >= 0, got {payload_mass}")
    model = pin.Model(_arm_model())
    if payload_mass > 0 or np.any(np.asarray(payload_inertia) != 0):
        ixx, iyy, izz, ixy, ixz, iyz = (float(x) for x in payload_inertia)
        I_com = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        tcp = model.frames[model.getFrameId(EE_FRAME)]
        payload = pin.Inertia(float(payload_mass), np.asarray(payload_com, dtype=float), I_com)
        joint = tcp.parentJoint
        model.inertias[joint] = model.inertias[joint] + tcp.placement.act(payload)
    return model


@functools.lru_cache(maxsize=8)
def cached_model(payload_mass: float = 0.0, payload_com=(0.0, 0.0, 0.0), payload_inertia=(0.0,) * 6) -> pin.Model:
    """Like :func:`panda_model`, shared per process for equal arguments (tuples): do not modify."""
    return panda_model(payload_mass, payload_com, payload_inertia)


def ee_frame_id(model: pin.Model) -> int:
    """Index of the end-effector frame (``panda_hand_tcp``) in ``model``."""
    return model.getFrameId(EE_FRAME)


def ee_position(model: pin.Model, data: pin.Data, q) -> np.ndarray:
    """End-effector (TCP) position in the base frame (m) at joint angles ``q`` (rad)."""
    pin.framesForwardKinematics(model, data, np.asarray(q, dtype=float))
    return data.oMf[ee_frame_id(model)].translation.copy()


def robot_variables():
    """The ports every robot unit shares, so units are interchangeable in a spec.

    Parameters: joint limits (default :data:`FRANKA_DOC_LIMITS`) and a rigid
    payload fixed to the hand (default none).  Inputs: the reference
    ``q_ref``, ``qd_ref``, ``qdd_ref``.  Outputs: the motion ``q``, ``qd``,
    ``qdd``, the joint torques ``tau`` actually applied, ``ee_pos`` (TCP in the
    base frame), ``ee_path_length`` (distance the TCP has travelled since the
    start, summed over communication steps as straight chords, so it is the
    thesis's Cartesian distance), ``tracking_error`` (max over joints of ``|q - q_ref|``),
    ``tau_ratio`` (``|tau| / tau_max`` per joint) and ``limit_violated`` (a
    position, velocity or torque limit is exceeded at this instant).
    """
    from cosim.units.protocol import Variable

    L = FRANKA_DOC_LIMITS
    src = " (Franka documentation)"
    arr = dict(shape=(N_JOINTS,))
    return (
        Variable("q_min", "parameter", unit="rad", start=tuple(L.q_min), description="lower position limits" + src, variability="fixed", **arr),
        Variable("q_max", "parameter", unit="rad", start=tuple(L.q_max), description="upper position limits" + src, variability="fixed", **arr),
        Variable("qd_max", "parameter", unit="rad/s", start=tuple(L.qd_max), description="velocity limits" + src, variability="fixed", **arr),
        Variable("tau_max", "parameter", unit="N.m", start=tuple(L.tau_max), description="torque limits" + src, variability="fixed", **arr),
        Variable("payload_mass", "parameter", unit="kg", start=0.0, min=0.0, description="rigid payload fixed to the hand", variability="fixed"),
        Variable("payload_com", "parameter", unit="m", start=0.0, shape=(3,), description="payload centre of mass in the panda_hand_tcp frame", variability="fixed"),
        Variable("payload_inertia", "parameter", unit="kg.m2", start=0.0, shape=(6,), description="payload Ixx Iyy Izz Ixy Ixz Iyz about its COM, TCP axes", variability="fixed"),
        Variable("q_ref", "input", unit="rad", start=tuple(0.5 * (L.q_min + L.q_max)), description="reference joint angles", **arr),
        Variable("qd_ref", "input", unit="rad/s", start=0.0, description="reference joint velocities", **arr),
        Variable("qdd_ref", "input", unit="rad/s2", start=0.0, description="reference joint accelerations", **arr),
        Variable("q", "output", unit="rad", start=0.0, description="joint angles", **arr),
        Variable("qd", "output", unit="rad/s", start=0.0, description="joint velocities", **arr),
        Variable("qdd", "output", unit="rad/s2", start=0.0, description="joint accelerations", **arr),
        Variable("tau", "output", unit="N.m", start=0.0, description="joint torques applied", **arr),
        Variable("ee_pos", "output", unit="m", start=0.0, shape=(3,), description="TCP position in the base frame"),
        Variable("ee_path_length", "output", unit="m", start=0.0,
                 description="length of the TCP path since the start: sum of straight TCP displacements between communication points"),
        Variable("tracking_error", "output", unit="rad", start=0.0, description="max over joints of |q - q_ref|"),
        Variable("tau_ratio", "output", start=0.0, description="|tau| / tau_max per joint", **arr),
        Variable("limit_violated", "output", type="Boolean", start=False, description="a position, velocity or torque limit is exceeded now"),
    )


def limits_exceeded(q, qd, tau_ratio, q_min, q_max, qd_max) -> bool:
    """True if a position, velocity or torque limit is exceeded (ndarray methods: this runs every step)."""
    return bool(
        tau_ratio.max() > 1.0 or (q - q_min).min() < 0.0 or (q_max - q).min() < 0.0 or (abs(qd) - qd_max).max() > 0.0
    )


def payload_key(mass, com, inertia) -> tuple:
    """Hashable key of payload parameters, for :func:`cached_model`."""
    return (float(mass), tuple(float(x) for x in np.ravel(com)), tuple(float(x) for x in np.ravel(inertia)))
