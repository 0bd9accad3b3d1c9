"""Parabolic-blend trajectories (thesis 7.2.1) and the thesis -> URDF angle mapping (7.2.3)."""

import numpy as np
import pinocchio as pin
import pytest

from cosim.models.panda_model import FRANKA_DOC_LIMITS, panda_model, thesis_to_urdf, urdf_to_thesis
from cosim.models.trajectory import N_MAX_WAYPOINTS, TrajectoryGenerator, plan_parabolic_blend

VMAX = FRANKA_DOC_LIMITS.qd_max
AMAX = FRANKA_DOC_LIMITS.qdd_max


def pick_and_place_waypoints(q22=-45.0, q24=70.0):
    """Thesis eq. 7-22/7-23 in thesis degrees, converted to URDF radians."""
    return thesis_to_urdf([[0, 0, 0, 0, 0, 0, 0], [-90, q22, 0, q24, 0, 0, 0], [-180, 0, 0, 0, 0, 0, 0]])


def dense(traj, n=20001):
    t = np.linspace(0.0, traj.duration, n)
    return (t, *traj.sample_many(t))


def assert_within_limits(traj, vmax, amax):
    _, _, qd, qdd = dense(traj)
    assert np.all(np.abs(qd) <= vmax * (1 + 1e-9))
    assert np.all(np.abs(qdd) <= amax * (1 + 1e-9))


@pytest.mark.parametrize("q22,q24", [(-100, 0), (0, 140), (0, 0), (-100, 140), (-45, 70)])
def test_pick_and_place_respects_limits_and_rests_at_both_ends(q22, q24):
    wp = pick_and_place_waypoints(q22, q24)
    traj = plan_parabolic_blend(wp, VMAX, AMAX)
    assert_within_limits(traj, VMAX, AMAX)
    q0, qd0, _ = traj.sample(0.0)
    q1, qd1, _ = traj.sample(traj.duration)
    np.testing.assert_allclose(q0, wp[0], atol=1e-12)
    np.testing.assert_allclose(q1, wp[-1], atol=1e-12)
    np.testing.assert_allclose(qd0, 0.0, atol=1e-12)
    np.testing.assert_allclose(qd1, 0.0, atol=1e-12)
    # at least one joint reaches its velocity limit on a segment (eq. 7-6) and
    # one its acceleration limit in a blend (eq. 7-7): the timing is not lazy
    _, _, qd, qdd = dense(traj)
    assert np.max(np.abs(qd) / VMAX) == pytest.approx(1.0, rel=1e-9)
    assert np.max(np.abs(qdd) / AMAX) == pytest.approx(1.0, rel=1e-9)


def test_trajectory_is_continuous_and_velocity_is_derivative_of_position():
    traj = plan_parabolic_blend(pick_and_place_waypoints(), VMAX, AMAX)
    t, q, qd, qdd = dense(traj, 40001)
    dt = t[1] - t[0]
    # central differences of q reproduce qd (q is C1, piecewise quadratic)
    np.testing.assert_allclose((q[2:] - q[:-2]) / (2 * dt), qd[1:-1], atol=2 * AMAX.max() * dt)
    assert np.max(np.abs(np.diff(qd, axis=0))) <= AMAX.max() * dt * (1 + 1e-9)


def test_segments_are_synchronised_and_interior_waypoints_are_cut_as_promised():
    wp = pick_and_place_waypoints(-60, 100)
    traj = plan_parabolic_blend(wp, VMAX, AMAX)
    # linear phase: every joint moves on the straight line towards the next waypoint
    T, tb = traj.waypoint_times, traj.blend_durations
    t_mid = 0.5 * ((T[0] + tb[0] / 2) + (T[1] - tb[1] / 2))
    q, qd, qdd = traj.sample(t_mid)
    np.testing.assert_allclose(qd, (wp[1] - wp[0]) / traj.segment_durations[0], rtol=1e-12)
    np.testing.assert_allclose(qdd, 0.0, atol=1e-12)
    # at the interior waypoint's time the distance to it is |v_i - v_{i-1}| tb_i / 8 (eq. 7-5)
    q1, _, _ = traj.sample(T[1])
    v = traj.velocities
    np.testing.assert_allclose(np.abs(q1 - wp[1]), np.abs(v[1] - v[0]) * tb[1] / 8, atol=1e-12)
    assert np.max(np.abs(q1 - wp[1])) > 1e-3  # the corner is really cut, not passed through


def naive_timing(wp, vmax, amax):
    """First iteration only (eq. 7-6, 7-7), no overlap fix."""
    dT = np.max(np.abs(np.diff(wp, axis=0)) / vmax, axis=1)
    v = np.vstack([np.zeros(wp.shape[1]), np.diff(wp, axis=0) / dT[:, None], np.zeros(wp.shape[1])])
    tb = np.max(np.abs(np.diff(v, axis=0)) / amax, axis=1)
    return dT, tb


def test_overlapping_blends_are_fixed():
    # short steps on joint 1, then a long move of joint 2: the naive blends overlap
    wp = np.array([[0.0] * 7, [0.05] + [0.0] * 6, [0.1] + [0.0] * 6, [0.15, 0.5] + [0.0] * 5])
    dT, tb = naive_timing(wp, VMAX, AMAX)
    assert np.any(tb[:-1] + tb[1:] > 2 * dT), "this case must need the fix (eq. 7-3 violated)"

    traj = plan_parabolic_blend(wp, VMAX, AMAX)
    assert traj.slowdowns > 0
    dT, tb = traj.segment_durations, traj.blend_durations
    assert np.all(tb[:-1] + tb[1:] <= 2 * dT * (1 + 1e-12))  # eq. 7-3 now holds
    assert_within_limits(traj, VMAX, AMAX)
    # phases are in time order (no blend starts before the previous one ended)
    assert np.all(np.diff(traj.phase_start) >= -1e-15)
    np.testing.assert_allclose(traj.sample(traj.duration)[0], wp[-1], atol=1e-12)


def test_duplicate_and_single_waypoints():
    wp = pick_and_place_waypoints()
    traj = plan_parabolic_blend(np.vstack([wp[:1], wp]), VMAX, AMAX)
    assert traj.duration == pytest.approx(plan_parabolic_blend(wp, VMAX, AMAX).duration)
    still = plan_parabolic_blend(wp[:1], VMAX, AMAX)
    assert still.duration == 0.0
    np.testing.assert_allclose(still.sample(0.3)[0], wp[0])
    with pytest.raises(ValueError):
        plan_parabolic_blend(wp, -VMAX, AMAX)
    with pytest.raises(ValueError):
        plan_parabolic_blend(wp, VMAX[:3], AMAX)


def test_unit_outputs_the_planned_trajectory_and_resets():
    wp_deg = [[0, 0, 0, 0, 0, 0, 0], [-90, -45, 0, 70, 0, 0, 0], [-180, 0, 0, 0, 0, 0, 0]]
    flat = np.zeros((N_MAX_WAYPOINTS, 7))
    flat[:3] = wp_deg
    traj = plan_parabolic_blend(thesis_to_urdf(wp_deg), VMAX, AMAX)

    u = TrajectoryGenerator("traj")
    for run in range(2):  # the second run after reset() must be identical
        u.set_values({"waypoints": flat.ravel(), "n_waypoints": 3, "convention": "thesis_deg"})
        u.setup(0.0, None)
        u.exit_initialization()
        assert u.get_values(["duration"])["duration"] == pytest.approx(traj.duration)
        np.testing.assert_allclose(u.get_values(["q_ref"])["q_ref"], thesis_to_urdf(wp_deg[0]))
        h, t = 1e-3, 0.0
        while t < 0.7:
            u.do_step(t, h)
            t += h
        out = u.get_values(["q_ref", "qd_ref", "qdd_ref", "finished"])
        q, qd, qdd = traj.sample(t)
        np.testing.assert_allclose(out["q_ref"], q, atol=1e-12)
        np.testing.assert_allclose(out["qd_ref"], qd, atol=1e-9)
        assert out["finished"] is False
        while t < traj.duration + 0.01:
            u.do_step(t, h)
            t += h
        out = u.get_values(["q_ref", "qd_ref", "finished"])
        assert out["finished"] is True
        np.testing.assert_allclose(out["q_ref"], thesis_to_urdf(wp_deg[-1]), atol=1e-12)
        np.testing.assert_allclose(out["qd_ref"], 0.0)
        u.reset()
    assert u.get_values(["n_waypoints"])["n_waypoints"] == 2  # reset re-applied the start value


def test_unit_outputs_are_valid_in_initialization_mode():
    # a master hands q_ref to the robot before the robot initializes: it must be the start already
    u = TrajectoryGenerator("traj")
    u.set_values({"waypoints[8]": -90, "waypoints[15]": -180, "n_waypoints": 3, "convention": "thesis_deg"})
    u.setup(0.0, None)
    u.enter_initialization()
    np.testing.assert_allclose(u.get_values(["q_ref"])["q_ref"], thesis_to_urdf([0] * 7))
    assert u.get_values(["duration"])["duration"] > 1.0


def test_unit_rejects_bad_parameters():
    from cosim.units.protocol import UnitError

    u = TrajectoryGenerator("traj")
    u.set_values({"convention": "degrees"})
    u.setup(0.0, None)
    with pytest.raises(UnitError, match="convention"):
        u.exit_initialization()
    u = TrajectoryGenerator("traj")
    u.set_values({"velocity_scale": 0.0})
    u.setup(0.0, None)
    with pytest.raises(UnitError, match="velocity_scale"):
        u.exit_initialization()


def test_velocity_scale_plans_with_scaled_velocity_limits():
    wp_deg = [[0, 0, 0, 0, 0, 0, 0], [-90, -45, 0, 70, 0, 0, 0], [-180, 0, 0, 0, 0, 0, 0]]
    flat = np.zeros((N_MAX_WAYPOINTS, 7))
    flat[:3] = wp_deg
    slow = plan_parabolic_blend(thesis_to_urdf(wp_deg), 0.4 * VMAX, AMAX)
    u = TrajectoryGenerator("traj")
    u.set_values({"waypoints": flat.ravel(), "n_waypoints": 3, "convention": "thesis_deg", "velocity_scale": 0.4})
    u.setup(0.0, None)
    u.exit_initialization()
    assert u.get_values(["duration"])["duration"] == pytest.approx(slow.duration)
    assert slow.duration > plan_parabolic_blend(thesis_to_urdf(wp_deg), VMAX, AMAX).duration * 2
    peak = max(np.max(np.abs(slow.sample(t)[1]) / VMAX) for t in np.linspace(0, slow.duration, 400))
    assert 0.39 < peak <= 0.4 + 1e-12


# --- thesis (Unity) angles -> URDF angles -------------------------------------------------


def frame_pos(model, data, name):
    return data.oMf[model.getFrameId(name)].translation


@pytest.fixture(scope="module")
def fk():
    model = panda_model()
    data = model.createData()

    def at(q_thesis_deg):
        pin.framesForwardKinematics(model, data, thesis_to_urdf(q_thesis_deg))
        return {n: frame_pos(model, data, n).copy() for n in ("panda_joint2", "panda_joint4", "panda_joint6", "panda_link8")} | {
            "tcp_z": data.oMf[model.getFrameId("panda_hand_tcp")].rotation[:, 2].copy()
        }

    return at


def test_thesis_zero_pose_is_the_arm_stretched_out_horizontally(fk):
    p = fk([0, 0, 0, 0, 0, 0, 0])
    shoulder, wrist, flange = p["panda_joint2"], p["panda_joint6"], p["panda_link8"]
    # shoulder and wrist at the same height, 0.7 m apart horizontally (0.316 + 0.384 m links)
    assert wrist[2] == pytest.approx(shoulder[2], abs=1e-9)
    assert np.hypot(*(wrist - shoulder)[:2]) == pytest.approx(0.316 + 0.384, abs=1e-9)
    # joint 6 at +90 deg in URDF: the hand points straight down ("aligned along the vertical")
    np.testing.assert_allclose(p["tcp_z"], [0, 0, -1], atol=1e-9)
    assert flange[2] < shoulder[2]


def test_thesis_border_cases(fk):
    # q2[2] = -100, q2[4] = 0: fully extended, vertically aligned (10 deg past vertical)
    p = fk([-90, -100, 0, 0, 0, 0, 0])
    arm = p["panda_joint6"] - p["panda_joint2"]
    assert np.degrees(np.arccos(arm[2] / np.linalg.norm(arm))) < 12.0
    # q2[2] = 0, q2[4] = 140: shoulder horizontal, elbow bends *downwards* by 140 deg
    p = fk([-90, 0, 0, 140, 0, 0, 0])
    upper = p["panda_joint4"] - p["panda_joint2"]
    fore = p["panda_joint6"] - p["panda_joint4"]
    assert abs(upper[2]) < 0.1  # upper arm still horizontal
    assert fore[2] < -0.2  # forearm goes down
    # q2[2] = 0, q2[4] = 0: same shape as the start pose, rotated by joint 1
    p0, p1 = fk([0, 0, 0, 0, 0, 0, 0]), fk([-90, 0, 0, 0, 0, 0, 0])
    assert p1["panda_joint6"][2] == pytest.approx(p0["panda_joint6"][2], abs=1e-12)
    # q2[2] = -100, q2[4] = 140: shoulder lifts the arm, the elbow bends it down
    p = fk([-90, -100, 0, 140, 0, 0, 0])
    assert p["panda_joint4"][2] > p["panda_joint2"][2] + 0.25
    assert p["panda_joint6"][2] < p["panda_joint4"][2]


def test_mapping_round_trip_and_values():
    q = np.array([10.0, -20, 30, 40, -50, 60, -70])
    np.testing.assert_allclose(urdf_to_thesis(thesis_to_urdf(q)), q, atol=1e-12)
    np.testing.assert_allclose(thesis_to_urdf([0] * 7), np.radians([0, 90, 0, 0, 0, 90, 0]))
    np.testing.assert_allclose(thesis_to_urdf([0, 0, 0, 140, 0, 0, 0])[3], np.radians(-140))
    with pytest.raises(ValueError):
        thesis_to_urdf([0, 0, 0])
