"""The pick-and-place study of examples/pick_and_place (thesis section 7.2.3, table 8-1).

Checks that the specs are valid and consistent, that the objectives the spec
computes agree with independent computations (from the recorded traces and
from a fine direct evaluation of the trajectory, pinocchio and the motor
equations), and that the two robot fidelity levels agree on energies and on
the ranking of designs.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import cosim
from cosim.execution.run import Execution
from cosim.models.panda_model import FRANKA_DOC_LIMITS, cached_model, ee_frame_id, thesis_to_urdf
from cosim.models.trajectory import plan_parabolic_blend
from cosim.spec.loader import load_spec, spec_from_dict
from cosim.system.builder import build_system
from tests.helpers.paths import REPO

FOLDER = REPO / "examples" / "pick_and_place"
SPEC = FOLDER / "spec.json"
Q22, Q24 = "traj.waypoints[9]", "traj.waypoints[11]"


def thesis_waypoints(q22: float, q24: float) -> np.ndarray:
    """q1, q2, q3 of thesis eq. 7-22/7-23 in thesis degrees."""
    return np.array([[0, 0, 0, 0, 0, 0, 0], [-90, q22, 0, q24, 0, 0, 0], [-180, 0, 0, 0, 0, 0, 0]], dtype=float)


def electric_power(tau: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Thesis eq. 7-13..7-19 with the constants of section 7.2.2 (rows: samples, columns: joints).

    Written here again, independently of models/ and fmus/, for the energy check.
    """
    R, r_t, k_m, eta_m = 100.0, 0.22, 0.134, 0.92
    n = np.abs(omega) * R * 60 / (2 * np.pi)
    eta = np.interp(n, [500, 1000, 2000, 3000], [0.75, 0.69, 0.63, 0.58]) * eta_m
    tau_m = np.where(tau * omega < 0, tau * eta / R, tau / (R * eta))  # standstill counts as motoring
    return r_t * (tau_m / k_m) ** 2 + tau_m * omega * R


def reference_objectives(q22: float, q24: float, dt: float = 1e-4) -> dict:
    """Energy, distances and duration of one design point, straight from the trajectory and RNEA on a fine grid."""
    traj = plan_parabolic_blend(thesis_to_urdf(thesis_waypoints(q22, q24)), FRANKA_DOC_LIMITS.qd_max,
                                FRANKA_DOC_LIMITS.qdd_max)
    t = np.arange(0.0, traj.duration, dt)
    t = np.append(t, traj.duration)
    q, qd, qdd = traj.sample_many(t)
    model = cached_model()
    data = model.createData()
    tau = np.array([pin.rnea(model, data, *x) for x in zip(q, qd, qdd)])
    frame = ee_frame_id(model)
    ee = []
    for x in q:
        pin.framesForwardKinematics(model, data, x)
        ee.append(data.oMf[frame].translation.copy())
    p = electric_power(tau, qd)
    return {
        "duration": traj.duration,
        "e_el": np.trapezoid(p, t, axis=0),
        "joint_distance": np.rad2deg(np.abs(np.diff(q, axis=0)).sum()),
        "cartesian_distance": float(np.linalg.norm(np.diff(np.array(ee), axis=0), axis=1).sum()),
        "peak_tau_ratio": np.max(np.abs(tau), axis=0) / FRANKA_DOC_LIMITS.tau_max,
    }


def test_specs_validate_and_variants_are_up_to_date():
    import importlib.util

    module_spec = importlib.util.spec_from_file_location("make_specs", FOLDER / "make_specs.py")
    make_specs = importlib.util.module_from_spec(module_spec)
    module_spec.loader.exec_module(make_specs)
    base = json.loads(SPEC.read_text())
    expected = {"spec_exudyn.json": make_specs.exudyn_level(base), "spec_coarse.json": make_specs.coarse(base),
                "spec_coarse_exudyn.json": make_specs.coarse(make_specs.exudyn_level(base)),
                "spec_datasheet.json": make_specs.datasheet_speeds(base),
                "spec_coarse_datasheet.json": make_specs.coarse(make_specs.datasheet_speeds(base))}
    for name, raw in expected.items():
        assert json.loads((FOLDER / name).read_text()) == raw, f"{name} is stale: run make_specs.py"
    for name in ["spec.json", *expected]:
        system = build_system(load_spec(FOLDER / name))
        assert list(system.order) == ["traj", "robot", "energy"]
    from cosim.spec.design import DesignSpace

    assert len(DesignSpace.from_spec(load_spec(SPEC))) == 121 * 141 == 17061
    assert len(DesignSpace.from_spec(load_spec(FOLDER / "spec_coarse.json"))) == 273
    from cosim.models.panda_model import DATASHEET_VELOCITY

    assert make_specs.DATASHEET_VELOCITY == pytest.approx(DATASHEET_VELOCITY, rel=1e-15)


def test_objectives_agree_with_traces_and_an_independent_computation():
    q22, q24 = -45.0, 70.0
    result = cosim.run(str(SPEC), {Q22: q22, Q24: q24}, record=True)
    assert result.ok, result.message
    o, tr = result.objectives, result.traces
    ref = reference_objectives(q22, q24)

    assert o["duration"] == pytest.approx(ref["duration"], rel=1e-12)
    assert 0 <= o["overshoot"] < 0.01 and o["t_end"] == pytest.approx(o["duration"] + o["overshoot"])
    # energy: the 10 ms midpoint-sampled co-simulation against a 0.1 ms direct integral
    for j in (1, 2, 4):
        assert o[f"e_el[{j}]"] == pytest.approx(ref["e_el"][j - 1], rel=5e-3, abs=0.02), j
    assert o["e_total"] == pytest.approx(ref["e_el"].sum(), rel=2e-3)
    assert 60 < o["e_total"] < 120  # J; the thesis's whole grid spans 19.5 .. 110
    # the energy FMU integrates the power it reports: e_total = sum of p_total * h over the steps
    p = tr[[f"energy.p_el[{j}]" for j in range(1, 8)]].to_numpy().sum(axis=1)
    h = np.diff(tr["time"].to_numpy())
    assert tr["energy.e_total"].iloc[-1] == pytest.approx(float((p[1:] * h).sum()), rel=1e-9)

    # joint distance: integral of |qd| (the spec) against sum |dq| of the recorded angles and the fine reference
    q = tr[[f"robot.q[{j}]" for j in range(1, 8)]].to_numpy()
    assert o["joint_distance"] == pytest.approx(np.rad2deg(np.abs(np.diff(q, axis=0)).sum()), rel=2e-3)
    assert o["joint_distance"] == pytest.approx(ref["joint_distance"], rel=2e-3)
    assert o["joint_distance_rad[1]"] == pytest.approx(np.pi, rel=1e-6)  # joint 1 turns by 180 deg, monotonically
    assert o["avg_joint_velocity[1]"] == pytest.approx(180.0 / o["duration"], rel=1e-6)
    # Cartesian distance: the unit's path length is the sum of the recorded chords; close to the fine path
    ee = tr[["robot.ee_pos[1]", "robot.ee_pos[2]", "robot.ee_pos[3]"]].to_numpy()
    assert o["cartesian_distance"] == pytest.approx(np.linalg.norm(np.diff(ee, axis=0), axis=1).sum(), rel=1e-9)
    assert o["cartesian_distance"] == pytest.approx(ref["cartesian_distance"], rel=2e-3)
    # peak torque ratios from the recorded torques
    tau = tr[[f"robot.tau[{j}]" for j in range(1, 8)]].to_numpy()
    for j in range(1, 8):
        assert o[f"peak_tau_ratio[{j}]"] == pytest.approx(np.abs(tau[:, j - 1]).max() / FRANKA_DOC_LIMITS.tau_max[j - 1])
    assert o["peak_tau_ratio[2]"] == pytest.approx(ref["peak_tau_ratio"][1], rel=0.05)
    # the thesis's stretched start pose has URDF q4 = 0, above Franka's q4 limit of -4 deg: flagged
    assert o["q_highest[4]"] == pytest.approx(0.0, abs=1e-12) and o["limit_violated"] == 1.0
    assert o["tracking_error"] == 0.0


def run_points(spec_path: Path, points, robot: str | None = None, robot_unit: dict | None = None) -> list[dict]:
    """Objectives of ``points`` (q2[2], q2[4]) with units reused, optionally with another robot unit.

    ``robot`` replaces the robot's Python class, ``robot_unit`` its whole entry (e.g. an FMU).
    """
    raw = json.loads(spec_path.read_text())
    if robot is not None:
        raw["units"]["robot"]["python"] = robot
    if robot_unit is not None:
        raw["units"]["robot"] = robot_unit
    system = build_system(spec_from_dict(raw, spec_path))
    units = {n: su.unit_type.instantiate(n) for n, su in system.units.items()}
    out = []
    try:
        for q22, q24 in points:
            for unit in units.values():
                unit.reset()
            overrides = [system.assignment_for(Q22, q22), system.assignment_for(Q24, q24)]
            result = Execution(system, overrides, units=units).run()
            assert result.ok, result.message
            out.append(result.objectives)
    finally:
        for unit in units.values():
            unit.terminate()
    return out


def test_fidelity_levels_agree_at_a_point_where_the_loaded_joints_move():
    (id_level,) = run_points(SPEC, [(-45.0, 70.0)])
    (servo,) = run_points(FOLDER / "spec_exudyn.json", [(-45.0, 70.0)])
    assert servo["e_total"] == pytest.approx(id_level["e_total"], rel=0.02)
    for j in (1, 2, 4):
        assert servo[f"e_el[{j}]"] == pytest.approx(id_level[f"e_el[{j}]"], rel=0.03), j
    assert servo["tracking_error"] < 1e-3  # rad
    assert servo["cartesian_distance"] == pytest.approx(id_level["cartesian_distance"], rel=5e-3)


def spearman(a, b) -> float:
    """Spearman rank correlation (no ties expected in energies)."""
    ra, rb = np.argsort(np.argsort(a)), np.argsort(np.argsort(b))
    return float(np.corrcoef(ra, rb)[0, 1])


def test_fidelity_levels_rank_a_tiny_grid_alike():
    points = [(q22, q24) for q22 in (-100.0, -50.0, 20.0) for q24 in (20.0, 140.0)]
    fast = [o["e_total"] for o in run_points(SPEC, points)]
    servo = [o["e_total"] for o in run_points(FOLDER / "spec_exudyn.json", points)]
    assert spearman(fast, servo) >= 0.9
    assert int(np.argmin(fast)) == int(np.argmin(servo))
    assert int(np.argmax(fast)) == int(np.argmax(servo))


def test_exudyn_follows_the_reference_of_the_step_end_under_gauss_seidel():
    """With ref_timing = step_end the servo tracks the true reference; read as step_start it runs a step ahead."""
    raw = json.loads((FOLDER / "spec_exudyn.json").read_text())
    assert raw["experiment"]["algorithm"] == "gauss-seidel" and raw["units"]["robot"]["parameters"]["ref_timing"] == "step_end"
    traj = plan_parabolic_blend(thesis_to_urdf(thesis_waypoints(-45.0, 70.0)), FRANKA_DOC_LIMITS.qd_max,
                                FRANKA_DOC_LIMITS.qdd_max)
    errors = {}
    for timing in ("step_end", "step_start"):
        raw["units"]["robot"]["parameters"]["ref_timing"] = timing
        system = build_system(spec_from_dict(raw, FOLDER / "spec_exudyn.json"))
        overrides = [system.assignment_for(Q22, -45.0), system.assignment_for(Q24, 70.0)]
        result = Execution(system, overrides, record=True).run()
        assert result.ok, result.message
        t = result.traces["time"].to_numpy()
        q1 = result.traces["robot.q[1]"].to_numpy()
        q_ref, qd_ref, _ = traj.sample_many(t)
        moving = np.abs(qd_ref[:, 0]) > 1.0  # rad/s
        # how far joint 1 is ahead of its true reference, along its motion
        errors[timing] = float(np.mean((q1 - q_ref[:, 0])[moving] * np.sign(qd_ref[moving, 0])))
    assert abs(errors["step_end"]) < 1e-4  # rad: on the reference (exact feed-forward, no lag)
    h = raw["experiment"]["step"]
    lead = errors["step_start"] - errors["step_end"]  # about one step ahead: ~qd * h, qd up to 2.175 rad/s
    assert 1.0 * h < lead < 1.5 * FRANKA_DOC_LIMITS.qd_max[0] * h


def test_trajectory_step_midpoint_sampling_reports_the_step_just_taken():
    from cosim.models.trajectory import TrajectoryGenerator
    from cosim.units.protocol import UnitError

    unit = TrajectoryGenerator("traj")
    unit.waypoints[:21] = thesis_waypoints(-45.0, 70.0).ravel()
    unit.n_waypoints, unit.convention, unit.sampling = 3, "thesis_deg", "step_midpoint"
    unit.setup(0.0, 3.0)
    unit.enter_initialization()
    unit.exit_initialization()
    plan = unit.trajectory
    np.testing.assert_array_equal(unit.q_ref, plan.sample(0.0)[0])  # the start is the start
    h, t = 0.01, 0.0
    blend_end = plan.blend_durations[0]  # joint accelerations jump here, inside the step [0.14, 0.15]
    while t < plan.duration + h:
        unit.do_step(t, h)
        q_mid, qd_mid, _ = plan.sample(t + h / 2)
        np.testing.assert_allclose(unit.q_ref, q_mid, atol=1e-12)
        np.testing.assert_allclose(unit.qd_ref, qd_mid, atol=1e-12)
        np.testing.assert_allclose(unit.qdd_ref, (plan.sample(t + h)[1] - plan.sample(t)[1]) / h, atol=1e-9)
        t += h
    assert unit.finished
    assert 0.1 < blend_end < 0.2
    unit.reset()
    unit.sampling = "halfway"
    with pytest.raises(UnitError, match="sampling"):
        unit.exit_initialization()
