"""The Panda robot units: Exudyn multibody with servo, and inverse dynamics (pinocchio)."""

import exudyn as exu
import numpy as np
import pinocchio as pin
import pytest

from cosim.models.panda_exudyn import PandaExudyn, build_kinematic_tree
from cosim.models.panda_inverse_dynamics import PandaInverseDynamics
from cosim.models.panda_model import FRANKA_DOC_LIMITS, cached_model, panda_model, thesis_to_urdf
from cosim.models.trajectory import plan_parabolic_blend

H = 1e-3


@pytest.fixture(scope="module")
def model():
    return panda_model()


def exudyn_forward_dynamics(mbs, solver, tree, q, qd, tau, kp=None, kd=None, q_off=None, qd_off=None):
    """qdd from Exudyn's own mass matrix and right-hand side at a given state."""
    sd = mbs.systemData
    sd.SetODE2Coordinates(q, configuration=exu.ConfigurationType.Current)
    sd.SetODE2Coordinates_t(qd, configuration=exu.ConfigurationType.Current)
    mbs.SetObjectParameter(tree, "jointForceVector", tau)
    for name, value in (("jointPControlVector", kp), ("jointDControlVector", kd),
                        ("jointPositionOffsetVector", q_off), ("jointVelocityOffsetVector", qd_off)):
        mbs.SetObjectParameter(tree, name, np.zeros(7) if value is None else value)
    solver.ComputeMassMatrix(mbs)
    M = solver.GetSystemMassMatrix()
    solver.ComputeODE2RHS(mbs)
    rhs = solver.GetSystemResidual()[:7]
    return np.linalg.solve(M, rhs)


def test_exudyn_forward_dynamics_equals_pinocchio_aba(model):
    data = model.createData()
    _, mbs, _, tree = build_kinematic_tree(model, np.zeros(7), np.zeros(7))
    solver = exu.MainSolverImplicitSecondOrder()
    settings = exu.SimulationSettings()
    settings.solution.file.write = False  # else Exudyn writes solution/ into the working directory
    solver.InitializeSolver(mbs, settings)
    rng = np.random.default_rng(42)
    for _ in range(20):
        q = pin.randomConfiguration(model)
        qd = rng.uniform(-2.0, 2.0, 7)
        tau = rng.uniform(-1.0, 1.0, 7) * FRANKA_DOC_LIMITS.tau_max
        a_exu = exudyn_forward_dynamics(mbs, solver, tree, q, qd, tau)
        a_pin = pin.aba(model, data, q, qd, tau)
        assert np.max(np.abs(a_exu - a_pin)) < 1e-9 * max(1.0, np.max(np.abs(a_pin)))
        # the built-in joint PD acts as kp (q_off - q) + kd (qd_off - qd): the servo relies on it
        kp, kd = rng.uniform(10, 600, 7), rng.uniform(1, 50, 7)
        q_off, qd_off = q + rng.normal(0, 0.01, 7), qd + rng.normal(0, 0.1, 7)
        a_exu = exudyn_forward_dynamics(mbs, solver, tree, q, qd, tau, kp, kd, q_off, qd_off)
        a_pin = pin.aba(model, data, q, qd, tau + kp * (q_off - q) + kd * (qd_off - qd))
        assert np.max(np.abs(a_exu - a_pin)) < 1e-9 * max(1.0, np.max(np.abs(a_pin)))


def pick_and_place():
    wp = thesis_to_urdf([[0, 0, 0, 0, 0, 0, 0], [-90, -45, 0, 70, 0, 0, 0], [-180, 0, 0, 0, 0, 0, 0]])
    return plan_parabolic_blend(wp, FRANKA_DOC_LIMITS.qd_max, FRANKA_DOC_LIMITS.qdd_max)


def run(unit, traj, extra_time=0.2, params=None):
    """Drive a robot unit along ``traj`` with 1 ms steps; returns arrays of outputs per step end."""
    unit.reset()
    if params:
        unit.set_values(params)
    q, qd, qdd = traj.sample(0.0)
    unit.set_values({"q_ref": q, "qd_ref": qd, "qdd_ref": qdd})
    unit.setup(0.0, None)
    unit.exit_initialization()
    names = ["q", "qd", "qdd", "tau", "ee_pos", "tracking_error"]
    out = {n: [] for n in names}
    n_steps = int(round((traj.duration + extra_time) / H))
    for k in range(n_steps):
        q, qd, qdd = traj.sample(k * H)
        unit.set_values({"q_ref": q, "qd_ref": qd, "qdd_ref": qdd})
        unit.do_step(k * H, H)
        for n, v in unit.get_values(names).items():
            out[n].append(v)
    unit.terminate()
    return {n: np.array(v) for n, v in out.items()}


@pytest.fixture(scope="module")
def exudyn_run():
    traj = pick_and_place()
    unit = PandaExudyn("robot")
    return traj, unit, run(unit, traj)


def test_exudyn_unit_tracks_pick_and_place(exudyn_run):
    traj, _, out = exudyn_run
    assert np.max(out["tracking_error"]) < 5e-3  # rad, with the default libfranka gains
    np.testing.assert_allclose(out["q"][-1], traj.waypoints[-1], atol=1e-3)  # it arrives
    np.testing.assert_allclose(out["qd"][-1], 0.0, atol=5e-3)  # settling, 0.2 s after the end
    assert np.max(np.abs(out["tau"][:, 1])) > 40.0  # the shoulder holds the stretched arm


def test_exudyn_applied_torque_equals_inverse_dynamics_of_actual_motion(exudyn_run, model):
    traj, _, out = exudyn_run
    data = model.createData()
    q, qd, qdd, tau = out["q"], out["qd"], out["qdd"], out["tau"]
    # exact: generalized-alpha satisfies the equations of motion at every step end,
    # so the applied torque equals RNEA of the end-of-step state and acceleration
    exact = np.array([pin.rnea(model, data, *x) for x in zip(q, qd, qdd)])
    assert np.max(np.abs(exact - tau)) < 1e-6
    # independent of Exudyn's acceleration: central differences of the velocity, within 2 %
    # of the torque range.  Where the reference acceleration jumps (blend <-> linear
    # phase) the true acceleration jumps too and a difference quotient across the
    # jump measures nothing, so samples within 2 steps of a phase switch are left out.
    qdd_num = (qd[2:] - qd[:-2]) / (2 * H)
    numeric = np.array([pin.rnea(model, data, *x) for x in zip(q[1:-1], qd[1:-1], qdd_num)])
    t_end = H * np.arange(2, len(q))  # output k (0-based) is at time (k + 1) H; k = 1 .. n-2
    switches = np.append(traj.phase_start, traj.duration)
    smooth = np.min(np.abs(t_end[:, None] - switches[None, :]), axis=1) > 2.5 * H
    assert smooth.mean() > 0.95  # almost every sample is checked
    torque_range = np.ptp(tau, axis=0).max()
    error = np.max(np.abs(numeric - tau[1:-1])[smooth])
    assert error < 0.02 * torque_range  # what the project asks for
    # much tighter in fact (measured 0.03 N.m of ~108); the feed-forward torque of the
    # reference alone would miss this by ~0.8 N.m, so the check sees the PD part too
    assert error < 0.0025 * torque_range


def test_exudyn_unit_reset_gives_the_same_run_and_gains_matter(exudyn_run):
    traj, unit, first = exudyn_run
    again = run(unit, traj, extra_time=0.0)
    n = len(again["q"])
    np.testing.assert_allclose(again["q"], first["q"][:n], atol=1e-12)
    soft = run(unit, traj, extra_time=0.0, params={"kp": np.full(7, 60.0), "kd": np.full(7, 5.0)})
    assert np.max(soft["tracking_error"]) > 2 * np.max(first["tracking_error"][:n])


def test_exudyn_unit_substeps_and_payload(model):
    traj = pick_and_place()
    unit = PandaExudyn("robot")
    fine = run(unit, traj, extra_time=0.0, params={"substep": 2.5e-4})
    coarse = run(unit, traj, extra_time=0.0)
    assert np.max(np.abs(fine["q"] - coarse["q"])) < 2e-3
    # a 270 g payload (the bin-picking pendulum's mass) at the TCP: shoulder needs more torque
    loaded = run(unit, traj, extra_time=0.0, params={"payload_mass": 0.27})
    assert np.max(np.abs(loaded["tau"][:, 1])) > np.max(np.abs(coarse["tau"][:, 1])) + 1.0
    assert np.max(loaded["tracking_error"]) < 5e-3


def test_inverse_dynamics_unit_is_rnea_and_fk(model):
    data = model.createData()
    unit = PandaInverseDynamics("robot")
    unit.setup(0.0, None)
    unit.exit_initialization()
    rng = np.random.default_rng(1)
    for k in range(10):
        q, qd, qdd = pin.randomConfiguration(model), rng.uniform(-2, 2, 7), rng.uniform(-10, 10, 7)
        unit.set_values({"q_ref": q, "qd_ref": qd, "qdd_ref": qdd})
        unit.do_step(k * H, H)
        out = unit.get_values(["q", "qd", "tau", "ee_pos", "tau_ratio", "tracking_error"])
        np.testing.assert_allclose(out["tau"], pin.rnea(model, data, q, qd, qdd), atol=1e-12)
        pin.framesForwardKinematics(model, data, q)
        np.testing.assert_allclose(out["ee_pos"], data.oMf[model.getFrameId("panda_hand_tcp")].translation, atol=1e-12)
        np.testing.assert_allclose(out["q"], q)
        np.testing.assert_allclose(out["tau_ratio"], np.abs(out["tau"]) / FRANKA_DOC_LIMITS.tau_max)
        assert out["tracking_error"] == 0.0


def test_payload_adds_the_expected_holding_torque():
    # stretched-out arm (thesis zero pose), at rest: a point mass at the TCP needs
    # m g times its horizontal distance from joint 2's axis, extra, on joint 2
    q = thesis_to_urdf([0] * 7)
    plain, loaded = PandaInverseDynamics("a"), PandaInverseDynamics("b")
    loaded.set_values({"payload_mass": 0.27})
    for u in (plain, loaded):
        u.set_values({"q_ref": q})
        u.setup(0.0, None)
        u.exit_initialization()
    d_tau = np.array(loaded.get_values(["tau"])["tau"]) - np.array(plain.get_values(["tau"])["tau"])
    lever = plain.get_values(["ee_pos"])["ee_pos"][0]  # joint 2's axis passes through x = 0
    assert abs(d_tau[1]) == pytest.approx(0.27 * 9.81 * lever, rel=1e-9)
    assert cached_model(0.27, (0.0, 0.0, 0.0), (0.0,) * 6).inertias[7].mass == pytest.approx(
        cached_model().inertias[7].mass + 0.27)


def test_units_share_ports():
    a = {(v.name, v.causality, v.shape, v.unit) for v in PandaInverseDynamics.variables}
    b = {(v.name, v.causality, v.shape, v.unit) for v in PandaExudyn.variables}
    assert a <= b
    assert {"tau", "q", "qd", "ee_pos"} <= {v.name for v in PandaExudyn.variables if v.causality == "output"}


def test_exudyn_pendulum_payload_hangs_and_swings():
    """The bin-picking load: 250 g bob + 20 g rod on a spherical joint at the TCP."""
    pendulum = {"pendulum_bob_mass": 0.25, "pendulum_rod_mass": 0.02, "pendulum_length": 0.2}
    q_hold = thesis_to_urdf([0] * 7)  # stretched out: the largest static lever
    hold = plan_parabolic_blend(np.array([q_hold]), FRANKA_DOC_LIMITS.qd_max, FRANKA_DOC_LIMITS.qdd_max)
    unit = PandaExudyn("robot")
    out = run(unit, hold, extra_time=1.5, params=pendulum)
    # at rest the pendulum just hangs (swinging a little: the arm sagged under the load
    # its servo did not expect, and nothing damps the swing), the arm carries 0.27 kg at the TCP
    assert unit.get_values(["pendulum_angle"])["pendulum_angle"] < 0.02
    rigid = PandaInverseDynamics("rigid")
    rigid.set_values({"payload_mass": 0.27, "q_ref": out["q"][-1]})
    rigid.setup(0.0, None)
    rigid.exit_initialization()
    np.testing.assert_allclose(out["tau"][-1], rigid.get_values(["tau"])["tau"], atol=0.01)
    # on the pick-and-place motion it swings, and the servo (unaware of it) still tracks
    moving = run(unit, pick_and_place(), extra_time=0.0, params=pendulum)
    assert unit.get_values(["pendulum_angle"])["pendulum_angle"] > 0.1
    assert np.max(moving["tracking_error"]) < 0.03
    # without the pendulum the next run is the plain arm again (no leftover body)
    plain = run(unit, pick_and_place(), extra_time=0.0)
    assert unit.get_values(["pendulum_angle"])["pendulum_angle"] == 0.0
    assert np.max(plain["tracking_error"]) < 5e-3


def test_exudyn_unit_starts_on_the_reference_seen_at_the_first_step(exudyn_run):
    """A master that hands over the reference only after initialization still gets a clean start."""
    traj, unit, first = exudyn_run
    unit.reset()
    unit.setup(0.0, None)
    unit.exit_initialization()  # q_ref is still the start value (mid-range), not the trajectory
    for k in range(50):
        q, qd, qdd = traj.sample(k * H)
        unit.set_values({"q_ref": q, "qd_ref": qd, "qdd_ref": qdd})
        unit.do_step(k * H, H)
    np.testing.assert_allclose(unit.get_values(["q"])["q"], first["q"][49], atol=1e-12)
