"""Cartesian planner (models/planner.py) and cell collision geometry (models/collision.py) on hand-made cases."""

from __future__ import annotations

import numpy as np
import pytest

from cosim.models.collision import READY_POSE, CellCollision
from cosim.models.panda_model import FRANKA_DOC_LIMITS as L
from cosim.models.planner import (
    COLLISION_PLANT,
    JOINT_JUMP,
    JOINT_LIMIT,
    OK,
    UNREACHABLE,
    CartesianPlanner,
    PlannerSettings,
    keyframes,
    time_parameterize,
)
from cosim.models.plant import Obstacle, tcp_down_rotation

DOWN = tcp_down_rotation(0.0)


@pytest.fixture(scope="module")
def free_planner():
    return CartesianPlanner(CellCollision(()))


def distance_to_line(p, a, b):
    a, b = np.asarray(a), np.asarray(b)
    u = (b - a) / np.linalg.norm(b - a)
    d = p - a
    return np.linalg.norm(d - np.outer(d @ u, u), axis=1)


def test_reachable_straight_segment_is_planned_whole_on_the_line(free_planner):
    a, b = (0.5, 0.0, 0.3), (0.5, 0.0, 0.1)
    path = free_planner.plan(np.array([a, b]), DOWN)
    assert path.ok and path.fraction == 1.0 and path.code == OK and path.blocked_by == ""
    assert len(path.q) == 21  # 0.2 m in 1 cm steps, plus the start
    assert distance_to_line(path.tcp, a, b).max() < 2e-4
    assert path.tcp[-1] == pytest.approx(b, abs=2e-4)
    assert path.cartesian_distance == pytest.approx(0.2, abs=1e-3)
    # gripper down at every sample
    for q in path.q:
        assert free_planner.tcp(q).rotation[:, 2] == pytest.approx([0, 0, -1], abs=2e-4)
    assert np.abs(np.diff(path.q, axis=0)).max() < 0.05
    assert np.all(path.q >= L.q_min) and np.all(path.q <= L.q_max)


def test_segment_into_an_obstacle_stops_before_it_and_names_the_link():
    block = Obstacle("block", (0.2, 0.2, 0.1), (0.5, 0.0, 0.0))  # top face at z = 0.05
    planner = CartesianPlanner(CellCollision([block]))
    path = planner.plan(np.array([(0.5, 0.0, 0.3), (0.5, 0.0, -0.05)]), DOWN)
    assert path.code == COLLISION_PLANT and not path.ok
    assert "block" in path.blocked_by and path.blocked_link in ("panda_leftfinger", "panda_rightfinger", "panda_hand")
    # the fingers end ~1 cm below the TCP: the last accepted TCP is within 1-2 cm above the face
    assert 0.05 < path.tcp[-1][2] < 0.075
    assert path.fraction == pytest.approx((0.3 - path.tcp[-1][2]) / 0.35, abs=0.03)
    assert 0.6 < path.fraction < 0.75


def test_segment_out_of_reach_stops_at_the_workspace_boundary(free_planner):
    path = free_planner.plan(np.array([(0.5, 0.0, 0.3), (1.2, 0.0, 0.3)]), DOWN)
    # beyond 0.78 m the gripper-down pose cannot be reached even with the joint limits removed
    assert path.code == UNREACHABLE and not path.ok and path.blocked_link == ""
    assert "out of reach" in path.blocked_by
    assert path.tcp[-1] == pytest.approx((0.78, 0.0, 0.3), abs=2e-4)
    assert path.fraction == pytest.approx(0.4)
    # the arm is stretched out: elbow (joint 4) near its stretched limit, not folded
    assert -1.0 < path.q[-1][3] < L.q_max[3]
    # a start pose out of reach plans nothing
    none = free_planner.plan(np.array([(1.3, 0.0, 0.3), (1.2, 0.0, 0.3)]), DOWN)
    assert none.fraction == 0.0 and none.code == UNREACHABLE and none.blocked_by.startswith("start pose out of reach")


def test_segment_toward_the_base_stops_at_the_elbow_limit(free_planner):
    path = free_planner.plan(np.array([(0.3, 0.0, 0.3), (0.05, 0.0, 0.3)]), DOWN)
    # reachable if the elbow could fold further than Franka's -3.0718 rad: a joint limit, named
    assert path.code == JOINT_LIMIT and path.blocked_link == "panda_joint4"
    assert path.blocked_by == "segment 1 at 44 %: joint limit of panda_joint4"
    assert path.q[-1][3] == pytest.approx(L.q_min[3], abs=0.1)
    assert path.fraction == pytest.approx(0.44)


def test_segment_that_needs_a_joint_jump_is_cut_there(free_planner):
    # low and outward toward the stretched, near-singular arm: the elbow (joint 4) must flip fast
    a, b = (0.4, -0.4, 0.0), (0.1, -0.9, -0.1)
    path = free_planner.plan(np.array([a, b]), DOWN)
    assert path.code == JOINT_JUMP and path.blocked_link == "panda_joint4"
    assert path.fraction == pytest.approx(0.7, abs=0.05)
    assert np.abs(np.diff(path.q, axis=0)).max() <= 0.2  # accepted steps stay under the threshold
    # without the threshold the same segment gets further, through that jump
    loose = CartesianPlanner(CellCollision(()), PlannerSettings(max_joint_step=10.0)).plan(np.array([a, b]), DOWN)
    assert loose.fraction > path.fraction
    assert np.abs(np.diff(loose.q, axis=0)).max() > 0.2
    # MoveIt's relative form cuts the loose path at that same jump
    rel = CartesianPlanner(CellCollision(()), PlannerSettings(max_joint_step=10.0, jump_threshold=5.0)).plan(
        np.array([a, b]), DOWN)
    assert rel.code == JOINT_JUMP and rel.fraction <= path.fraction + 0.02


def test_arm_geometry_distances_match_its_mesh_vertices():
    """A wall in front of the ready pose: coal's distance equals the nearest hull vertex's (the meshes are convex)."""
    cc = CellCollision(())
    placements = cc.placements(READY_POSE)
    front = -np.inf
    for obj, M in zip(cc.geom.geometryObjects, placements):
        g = obj.geometry
        pts = np.array(g.points()) if hasattr(g, "points") else None
        if pts is None:  # finger boxes: their corners
            h = np.array(g.halfSide)
            pts = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
        front = max(front, (pts @ M.rotation.T + M.translation)[:, 0].max())
    wall = Obstacle("wall", (0.1, 2.0, 2.0), (front + 0.1 + 0.05, 0.0, 0.5))  # near face 0.1 m ahead
    d, a, b = CellCollision([wall], self_collision=False).min_distance(READY_POSE)
    assert d == pytest.approx(0.1, abs=1e-6) and b == "wall"
    # moved into the arm by 2 cm: a collision, named
    hit = CellCollision([Obstacle("wall", (0.1, 2.0, 2.0), (front + 0.05 - 0.02, 0.0, 0.5))], self_collision=False)
    assert hit.first_collision(READY_POSE)[1] == "wall"


def test_self_collision_pairs_and_known_contact():
    cc = CellCollision(())
    assert cc.first_collision(READY_POSE) is None
    assert cc.disabled_pairs == []  # no "default" overlap in the ready pose with these meshes
    names = {cc.names[p.first] for p in cc.geom.collisionPairs} | {cc.names[p.second] for p in cc.geom.collisionPairs}
    assert "panda_link0_0" in names and "panda_hand_0" in names
    # q6 = 0 folds link 7 back onto link 5: the URDF meshes overlap there (q6 min is -1 deg)
    q = READY_POSE.copy()
    q[5] = 0.0
    assert cc.first_collision(q) == ("panda_link5_0", "panda_link7_0")


def test_time_parameterisation_stops_at_waypoints_within_limits(free_planner):
    wps = np.array([(0.5, 0.0, 0.3), (0.5, 0.0, 0.1), (0.5, 0.0, 0.3), (0.3, -0.4, 0.3)])
    path = free_planner.plan(wps, DOWN)
    assert path.ok and len(path.stops) == 4
    traj = time_parameterize(path, L.qd_max, L.qdd_max)
    t = np.linspace(0, traj.duration, 2001)
    q, qd, qdd = (np.array(x) for x in zip(*(traj.sample(float(x)) for x in t)))
    assert np.all(np.abs(qd) <= L.qd_max * (1 + 1e-9)) and np.all(np.abs(qdd) <= L.qdd_max * (1 + 1e-9))
    # at rest exactly on each reached waypoint
    for k, start in enumerate(traj.starts):
        qk, vk, _ = traj.sample(float(start))
        assert vk == pytest.approx(np.zeros(7), abs=1e-12)
        assert qk == pytest.approx(path.q[path.stops[k]], abs=1e-12)
    # the executed TCP path deviates from the straight segments by little (blends cut corners)
    tcp = np.array([free_planner.tcp(x).translation.copy() for x in q])
    assert distance_to_line(tcp[: len(t) // 8], wps[0], wps[1]).max() < 0.01
    # keyframes thin the dense path
    keep = keyframes(path.q[path.stops[0]:path.stops[1] + 1], 0.01)
    assert keep[0] == 0 and keep[-1] == path.stops[1] and len(keep) < path.stops[1]
