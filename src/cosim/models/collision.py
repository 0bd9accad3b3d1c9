"""Collision geometry of the Panda and its cell, checked with coal through pinocchio.

Arm geometry
    The collision meshes of the ``example-robot-data`` URDF (the coarse
    ``meshes/collision/*.stl`` Franka ships for planning: one closed convex
    hull per link of 102-152 vertices, plus eight boxes for the fingers),
    each replaced by its convex hull (``coal.Convex``) so that coal uses GJK/EPA
    instead of a triangle BVH: the meshes are already convex, so the shape is
    the same, and a pair check costs a few microseconds.  We did not use
    capsules: the meshes are what MoveIt used with this robot, and fitting
    capsules would be a second, less faithful approximation.

Self-collision
    Pairs of links on the same or on neighbouring joints always touch at the
    joint and are never checked (MoveIt's "adjacent" pairs).  Additionally, a
    pair whose meshes already overlap in the ``READY_POSE`` would be disabled
    (MoveIt's "default" pairs); the list is computed, not hand-written, and
    available as :attr:`CellCollision.disabled_pairs`; with these meshes it is
    empty.  Note that link 5 and link 7 do overlap at ``q6 = 0`` (inside the
    joint range, which starts at -1 deg): that pose counts as a self-collision.

Plant geometry
    :class:`models.plant.Obstacle` boxes (``coal.Box``), fixed to the world
    (joint 0), given in the robot's base frame.

The fingers are locked closed, as in :mod:`cosim.models.panda_model`; the pendulum
payload is not part of the geometry (see ``examples/bin_picking/README.md``).
"""

from __future__ import annotations

import functools
import os

import coal
import numpy as np
import pinocchio as pin

from .panda_model import urdf_path

# Franka's "ready" pose; pairs overlapping here are disabled (MoveIt's "default" collisions)
READY_POSE = np.array([0.0, -np.pi / 4, 0.0, -3 * np.pi / 4, 0.0, np.pi / 2, np.pi / 4])


@functools.lru_cache(maxsize=1)
def _arm_geometry() -> tuple[pin.Model, pin.GeometryModel]:
    path = urdf_path()
    package_dir = path.split(os.sep + "example-robot-data" + os.sep)[0]  # resolves package://example-robot-data
    full = pin.buildModelFromUrdf(path)
    geom = pin.buildGeomFromUrdf(full, path, pin.GeometryType.COLLISION, package_dirs=[package_dir])
    lock = [full.getJointId(n) for n in ("panda_finger_joint1", "panda_finger_joint2")]
    model, geom = pin.buildReducedModel(full, geom, lock, pin.neutral(full))  # same reduction as panda_model
    for obj in geom.geometryObjects:
        if isinstance(obj.geometry, coal.BVHModelBase):
            obj.geometry.buildConvexHull(True, "Qt")
            obj.geometry = obj.geometry.convex
    return model, geom


def link_of(geometry_name: str) -> str:
    """``panda_link4_0`` -> ``panda_link4``; obstacle names are returned unchanged."""
    head, _, tail = geometry_name.rpartition("_")
    return head if tail.isdigit() and head.startswith("panda_") else geometry_name


class CellCollision:
    """The arm and a set of box obstacles in one pinocchio GeometryModel.

    ``obstacles``: :class:`models.plant.Obstacle` in the robot's base frame.
    ``margin`` (m): a pair closer than this counts as colliding (coal's security margin).
    """

    def __init__(self, obstacles=(), self_collision: bool = True, margin: float = 0.0):
        model, arm = _arm_geometry()
        self.model = model
        self.data = model.createData()
        self.geom = pin.GeometryModel(arm)  # a copy: obstacles are per instance
        self.n_arm = self.geom.ngeoms
        for o in obstacles:
            self.geom.addGeometryObject(pin.GeometryObject(
                o.name, 0, pin.SE3(np.eye(3), np.asarray(o.center, dtype=float)), coal.Box(*o.size)))
        arm_objs = list(self.geom.geometryObjects)[: self.n_arm]
        for i in range(self.n_arm):
            for k in range(self.n_arm, self.geom.ngeoms):
                self.geom.addCollisionPair(pin.CollisionPair(i, k))
        self.disabled_pairs: list[tuple[str, str]] = []
        if self_collision:
            self._add_self_pairs(arm_objs)
        self.gdata = pin.GeometryData(self.geom)
        for req in self.gdata.collisionRequests:
            req.security_margin = float(margin)
        self.names = [o.name for o in self.geom.geometryObjects]

    def _add_self_pairs(self, arm_objs) -> None:
        probe = pin.GeometryModel()
        for o in arm_objs:
            probe.addGeometryObject(o)
        candidates = [(i, j) for i in range(len(arm_objs)) for j in range(i + 1, len(arm_objs))
                      if abs(arm_objs[i].parentJoint - arm_objs[j].parentJoint) > 1]
        for i, j in candidates:
            probe.addCollisionPair(pin.CollisionPair(i, j))
        pdata = pin.GeometryData(probe)
        pin.computeCollisions(self.model, self.data, probe, pdata, READY_POSE, False)
        for p, (i, j) in enumerate(candidates):
            if pdata.collisionResults[p].isCollision():
                self.disabled_pairs.append((arm_objs[i].name, arm_objs[j].name))
            else:
                self.geom.addCollisionPair(pin.CollisionPair(i, j))

    def first_collision(self, q) -> tuple[str, str] | None:
        """The first colliding pair of geometry names at joint angles ``q`` (rad), or None."""
        if not pin.computeCollisions(self.model, self.data, self.geom, self.gdata, np.asarray(q, dtype=float), True):
            return None
        for p, res in enumerate(self.gdata.collisionResults):
            if res.isCollision():
                pair = self.geom.collisionPairs[p]
                return self.names[pair.first], self.names[pair.second]
        return None  # not reached: computeCollisions said there was one

    def min_distance(self, q) -> tuple[float, str, str]:
        """Smallest distance (m, negative if penetrating) over all checked pairs, and that pair's names."""
        pin.computeDistances(self.model, self.data, self.geom, self.gdata, np.asarray(q, dtype=float))
        d = np.array([r.min_distance for r in self.gdata.distanceResults])
        p = int(np.argmin(d))
        pair = self.geom.collisionPairs[p]
        return float(d[p]), self.names[pair.first], self.names[pair.second]

    def placements(self, q) -> list[pin.SE3]:
        """World placement of every geometry object at ``q`` (arm objects first, then obstacles)."""
        pin.updateGeometryPlacements(self.model, self.data, self.geom, self.gdata, np.asarray(q, dtype=float))
        return [pin.SE3(m) for m in self.gdata.oMg]
