"""The bin-picking study (examples/bin_picking): plant, planner unit, payload, execution check, spec grid."""

from __future__ import annotations

import numpy as np
import pytest

import cosim
from cosim.models.collision import CellCollision
from cosim.models.planner import COLLISION_PLANT, CartesianPlanner, PlantCollisionChecker
from cosim.models.plant import load_plant
from cosim.spec.design import DesignSpace
from cosim.spec.loader import load_spec
from tests.helpers.paths import REPO

SPEC = REPO / "examples" / "bin_picking" / "spec.json"


def plan(offset, variant):
    plant = load_plant("", variant)
    p = plant.in_base_frame(plant.unity_offset_to_world(offset))
    return CartesianPlanner(CellCollision(p.obstacles)).plan(p.waypoints, p.tcp_rotation)


def test_unity_offsets_move_the_robot_as_the_thesis_axes_say():
    plant = load_plant("", "simple")
    conveyor = {o.name: o for o in plant.obstacles}["conveyor_belt"].center
    box = {o.name: o for o in plant.obstacles}["box_bottom"].center
    moved = {o.name: o for o in plant.in_base_frame(plant.unity_offset_to_world((0.1, 0.2, 0.05))).obstacles}
    # x_U toward the conveyor (at -y_W): the cell moves +0.1 m in y_W, the conveyor 0.1 m closer;
    # y_U up: everything 0.2 m lower; z_U toward the box (at +x_W): the box 0.05 m closer
    assert moved["conveyor_belt"].center == pytest.approx(np.add(conveyor, (-0.05, 0.1, -0.2)))
    assert moved["box_bottom"].center == pytest.approx(np.add(box, (-0.05, 0.1, -0.2)))
    assert len(load_plant("", "complex").obstacles) == len(plant.obstacles) + 4
    with pytest.raises(ValueError, match="box variant"):
        load_plant("", "round")


def test_zero_offset_is_a_valid_placement_and_far_corners_are_not():
    # simple box at zero; the narrow box wants the robot 0.1 m further from the box (the forearm clears the lip)
    for offset, variant in (((0.0, 0.0, 0.0), "simple"), ((0.0, 0.0, -0.1), "complex")):
        path = plan(offset, variant)
        assert path.ok and len(path.stops) == 7, (variant, path.blocked_by)
        # 2 x 0.36 m into the box and out, 2 x 0.2 m at the conveyor, 2 x box<->conveyor
        between = np.linalg.norm(np.subtract((0.5, 0.0, 0.2), (0.2, -0.5, 0.1)))
        assert path.cartesian_distance == pytest.approx(2 * 0.36 + 2 * 0.2 + 2 * between, abs=0.01)
    far = plan((-0.4, -0.2, -0.4), "simple")
    assert far.fraction == 0.0 and "start pose" in far.blocked_by


def test_the_narrow_box_blocks_a_placement_the_simple_box_allows():
    assert plan((0.1, 0.0, 0.0), "simple").ok
    narrow = plan((0.1, 0.0, 0.0), "complex")
    assert narrow.code == COLLISION_PLANT and narrow.segment == 0  # on the way into the box
    assert narrow.blocked_link == "panda_link5" and narrow.blocked_by.endswith("box_lip_near")
    assert 0.1 < narrow.fraction < 1 / 6  # most of the first of six segments


def test_execution_checker_flags_an_arm_inside_the_box():
    unit = PlantCollisionChecker()
    unit.set_values({"box_variant": "simple", "check_period": 0.05})
    unit.setup(0.0, None)
    unit.enter_initialization()
    unit.exit_initialization()
    path = plan((0.0, 0.0, 0.0), "simple")
    unit.set_values({"q": path.q[path.stops[1]]})  # in the box, clear of its walls
    unit.do_step(0.0, 0.01)
    assert unit.get_values(["collision", "collided", "checks"]) == {"collision": False, "collided": False, "checks": 1}
    q = path.q[path.stops[1]].copy()
    q[1] += 0.3  # shoulder forward: the forearm swings into the box's near wall
    unit.set_values({"q": q})
    unit.do_step(0.01, 0.01)  # before the next check time: nothing checked
    assert unit.get_values(["checks"])["checks"] == 1
    unit.do_step(0.05, 0.01)
    out = unit.get_values(["collision", "collided", "first_contact"])
    assert out["collision"] and out["collided"] and out["first_contact"] == "panda_link5/box_wall_near"
    unit.set_values({"q": path.q[0]})
    unit.do_step(0.10, 0.01)
    assert unit.get_values(["collision", "collided"]) == {"collision": False, "collided": True}  # latched


@pytest.fixture(scope="module")
def runs():
    """The zero-offset point with and without the pendulum (~3-5 s each on 2 busy cores)."""
    with_payload = cosim.run(str(SPEC), {"planner.offset_y": 0.0})
    without = cosim.run(str(SPEC), {"robot.pendulum_bob_mass": 0.0, "robot.pendulum_rod_mass": 0.0})
    assert with_payload.ok and without.ok, (with_payload.message, without.message)
    return with_payload, without


def test_zero_offset_point_end_to_end(runs):
    r, _ = runs
    o = r.objectives
    assert o["fraction_planned"] == 1.0 and o["planned_ok"] == 1.0 and o["collided"] == 0.0 and o["executed_ok"] == 1.0
    assert 3.0 < o["duration"] < 8.0 and r.end_time == pytest.approx(o["duration"], abs=0.0021)
    # the executed TCP path follows the planned one (blends cut corners a little)
    assert o["cartesian_distance"] == pytest.approx(o["planned_cartesian_distance"], rel=0.05)
    assert np.deg2rad(o["joint_distance"]) == pytest.approx(o["planned_joint_distance"], rel=0.05)
    assert 30.0 < o["e_total"] < 300.0
    assert o["tracking_error"] < 0.02


def test_payload_swings_and_changes_the_joint_torques(runs):
    with_payload, without = runs
    a, b = with_payload.traces, without.traces
    assert len(a) == len(b)
    swing = a["robot.pendulum_angle"].to_numpy()
    assert swing[0] == pytest.approx(0.0, abs=1e-9) and swing.max() > 0.2  # rad: it swings with the motion
    assert np.all(b["robot.pendulum_angle"].to_numpy() == 0.0)
    # it still swings after the arm stopped at a waypoint (free pendulum, no damping modelled)
    assert np.ptp(swing[-200:]) > 0.01
    for j in (2, 4):  # shoulder and elbow carry the 270 g: mean torque differs by its weight x lever
        d = a[f"robot.tau[{j}]"].to_numpy() - b[f"robot.tau[{j}]"].to_numpy()
        assert np.abs(d).max() > 0.5 and abs(d.mean()) > 0.3, j
    assert with_payload.objectives["e_total"] > without.objectives["e_total"]


def test_spec_grid_is_the_thesis_grid():
    space = DesignSpace.from_spec(load_spec(SPEC))
    assert len(space) == 12 * 9 * 12 * 2 == 2592


def _planner_unit(**values):
    from cosim.models.planner import BinPickingPlanner

    unit = BinPickingPlanner()
    unit.set_values(values)
    unit.setup(0.0, None)
    unit.enter_initialization()
    unit.exit_initialization()
    return unit


def test_planner_unit_plays_a_partial_plan_only_when_asked():
    blocked = {"box_variant": "complex", "offset_x": 0.1}
    rest = _planner_unit(**blocked, execute_partial=False)
    out = rest.get_values(["planned_ok", "fraction_planned", "blocked_code", "duration", "finished", "blocked_link"])
    assert out["planned_ok"] is False and out["blocked_code"] == COLLISION_PLANT and out["blocked_link"] == "panda_link5"
    assert out["fraction_planned"] == pytest.approx(0.162, abs=0.005)
    assert out["duration"] == 0.0 and out["finished"] is True
    partial = _planner_unit(**blocked, execute_partial=True)
    d = partial.get_values(["duration"])["duration"]
    assert 0.3 < d < 2.0  # the descent into the box, up to the lip, at rest at both ends
    partial.do_step(0.0, d + 0.01)
    q_end = np.array(partial.get_values(["q_ref"])["q_ref"])
    assert q_end == pytest.approx(partial.path.q[-1], abs=1e-12)


def test_planner_unit_plans_again_only_when_its_parameters_change():
    unit = _planner_unit()
    first = unit.path
    assert unit.get_values(["planning_time"])["planning_time"] > 0
    unit.reset()
    unit.setup(0.0, None)
    unit.enter_initialization()
    unit.exit_initialization()
    assert unit.path is first  # same parameters: the same plan, reused
    assert unit.get_values(["planning_time"])["planning_time"] > 0  # still reported
    unit.reset()
    unit.set_values({"offset_y": 0.1})
    unit.setup(0.0, None)
    unit.enter_initialization()
    unit.exit_initialization()
    assert unit.path is not first and unit.path.ok
    assert unit.path.tcp[0][2] == pytest.approx(first.tcp[0][2] - 0.1, abs=2e-4)  # robot 0.1 m higher
