"""A robot cell as data: box-shaped obstacles, task waypoints, gripper orientation.

The plant file (JSON, e.g. ``models/bin_picking_plant.json``) describes the
cell in a world frame ``W``: the robot's base frame at zero offset,
right-handed, z up.  Moving the robot's base by an offset is the same as
moving every obstacle and waypoint by the opposite offset relative to the
robot (thesis section 7.3.3), which is what :meth:`Plant.in_base_frame` does.

Offsets in the thesis are Unity axes (left-handed, y up).  The file's
``unity_to_world`` matrix maps a Unity vector to ``W``; for the bin-picking
cell ``x_U -> -y_W`` (toward the conveyor), ``y_U -> z_W`` (up),
``z_U -> x_W`` (toward the box).
"""

from __future__ import annotations

import functools
import importlib.resources
import json
import math
import os
from dataclasses import dataclass

import numpy as np

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# The bin-picking cell ships with the units (package data), so an installed cosim plans without the repository.
DEFAULT_PLANT = str(importlib.resources.files(__package__).joinpath("bin_picking_plant.json"))


@dataclass(frozen=True)
class Obstacle:
    """An axis-aligned box: full extents ``size`` and ``center`` (m), in the frame it is given in."""

    name: str
    size: tuple[float, float, float]
    center: tuple[float, float, float]


@dataclass(frozen=True)
class Plant:
    """Obstacles, the task's Cartesian waypoints (TCP positions) and the TCP orientation, in one frame."""

    obstacles: tuple[Obstacle, ...]
    waypoints: np.ndarray  # (n, 3) TCP positions of the task, in order
    waypoint_names: tuple[str, ...]
    tcp_rotation: np.ndarray  # (3, 3) orientation of panda_hand_tcp held along the whole path
    unity_to_world: np.ndarray  # (3, 3)

    def in_base_frame(self, base_offset_world) -> "Plant":
        """The same plant seen from a robot base moved by ``base_offset_world`` (m, W axes)."""
        d = np.asarray(base_offset_world, dtype=float).reshape(3)
        obstacles = tuple(Obstacle(o.name, o.size, tuple(float(c) for c in np.asarray(o.center) - d)) for o in self.obstacles)
        return Plant(obstacles, self.waypoints - d, self.waypoint_names, self.tcp_rotation, self.unity_to_world)

    def unity_offset_to_world(self, offset_unity) -> np.ndarray:
        """A base offset in Unity axes (thesis x_pos, y_pos, z_pos) as a vector in W."""
        return self.unity_to_world @ np.asarray(offset_unity, dtype=float).reshape(3)


def tcp_down_rotation(yaw_deg: float) -> np.ndarray:
    """Rotation of ``panda_hand_tcp`` pointing down (z = -z_W) with its finger axis (y) at ``yaw_deg`` from x_W."""
    r0 = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # columns: x=(0,1,0) y=(1,0,0) z=(0,0,-1)
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ r0


def resolve_plant_path(path: str) -> str:
    """``""`` -> the bin-picking plant; a relative path -> against the working directory, else the repository.

    Raises FileNotFoundError if neither exists.
    """
    if not path:
        return DEFAULT_PLANT
    for candidate in (path, os.path.join(REPO_ROOT, path)):
        if os.path.isfile(candidate):
            return os.path.abspath(candidate)
    raise FileNotFoundError(f"plant file {path!r} not found (also not under {REPO_ROOT})")


def load_plant(path: str = "", box_variant: str = "simple") -> Plant:
    """Read a plant file with the obstacles of ``box_variant`` added (a fresh object; cached parsing).

    Raises FileNotFoundError, ValueError for an unknown variant or a malformed file.
    """
    return _load(resolve_plant_path(path), box_variant)


@functools.lru_cache(maxsize=16)
def _load(path: str, box_variant: str) -> Plant:
    with open(path, encoding="utf-8") as f:
        doc = json.load(f)
    variants = doc.get("box_variants", {})
    if box_variant not in variants:
        raise ValueError(f"box variant {box_variant!r} not in {path}: choose one of {sorted(variants)}")

    def obstacle(item) -> Obstacle:
        size, center = tuple(float(x) for x in item["size"]), tuple(float(x) for x in item["center"])
        if len(size) != 3 or len(center) != 3 or min(size) <= 0:
            raise ValueError(f"obstacle {item.get('name')!r} in {path}: size (3 values > 0) and center (3 values) needed")
        return Obstacle(str(item["name"]), size, center)

    obstacles = tuple(obstacle(o) for o in doc["obstacles"] + variants[box_variant])
    names = tuple(doc["task"])
    try:
        waypoints = np.array([doc["waypoints"][n] for n in names], dtype=float)
    except KeyError as e:
        raise ValueError(f"task waypoint {e} not defined in {path}") from None
    m = np.array(doc.get("unity_to_world", np.eye(3)), dtype=float)
    return Plant(obstacles, waypoints, names, tcp_down_rotation(float(doc.get("tcp_yaw_deg", 0.0))), m)
