"""The Panda arm's trace viewer for cosim: joint, torque and power panels and a stick-figure animation
(matplotlib, for the desktop window) and its link frames (for the browser's decision room).

Registered with cosim through the ``cosim.viewers`` entry point (pyproject.toml),
so the engine itself knows nothing about robots.  Joint angles are found as
``<unit>.q[1]`` .. ``[7]`` (URDF radians); the arm's joint and tool positions
come from pinocchio's forward kinematics of :mod:`cosim.models.panda_model`.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from cosim.analysis.viewers import LinkFrames, TraceViewer, rows_evenly_in_time, trace_times

_ELEMENT = re.compile(r"^(.*)\[(\d+)\]$")


def joint_columns(traces: Any, port: str = "q", n: int = 7) -> list[str] | None:
    """The columns ``<unit>.<port>[1]``..``[n]`` of the first unit that has all of them, or None."""
    for c in traces.columns:
        m = _ELEMENT.match(str(c))
        if m and m.group(1).rsplit(".", 1)[-1] == port and m.group(2) == "1":
            names = [f"{m.group(1)}[{i}]" for i in range(1, n + 1)]
            if all(name in traces.columns for name in names):
                return names
    return None


def panels(traces: Any) -> list[tuple[str, list[str]]] | None:
    """Joint angles, joint torques and electric power panels, when the traces have any of them."""
    groups: list[tuple[str, list[str]]] = []
    q, tau = joint_columns(traces, "q"), joint_columns(traces, "tau")
    if q:
        groups.append(("joint angles [rad]", q))
    if tau:
        groups.append(("joint torques [N m]", tau))
    power = [str(c) for c in traces.columns if re.search(r"(^|\.)(p_el|p_total)(\[\d+\])?$", str(c))]
    if power:
        groups.append(("electric power [W]", power))
    return groups or None


def arm_points(q: np.ndarray) -> np.ndarray:
    """Positions (samples, 9, 3): base, the 7 joints and the tool point, for joint angles q (samples, 7)."""
    import pinocchio as pin

    from cosim.models.panda_model import cached_model, ee_frame_id

    model = cached_model()
    data = model.createData()
    ee = ee_frame_id(model)
    q = np.atleast_2d(np.asarray(q, dtype=float))
    out = np.zeros((len(q), 9, 3))
    for k, qk in enumerate(q):
        pin.forwardKinematics(model, data, qk)
        for j in range(1, 8):
            out[k, j] = data.oMi[j].translation
        out[k, 8] = pin.updateFramePlacement(model, data, ee).translation
    return out


def arm_animation(fig: Any, traces: Any, frames: int = 60) -> Any:
    """A FuncAnimation of the arm over the run (``frames`` samples evenly spaced in time: at each frame's time the
    last row at or before it, so that a run with event rows, which repeat a time, is not slowed down where its
    events crowd); None without q[1..7].

    Keep a reference to the returned animation, or it stops.
    """
    from matplotlib.animation import FuncAnimation

    q_cols = joint_columns(traces, "q")
    if not q_cols:
        return None
    all_times = trace_times(traces)
    idx = rows_evenly_in_time(all_times, frames)
    pts = arm_points(traces[q_cols].to_numpy(dtype=float)[idx])
    times = all_times[idx]
    fig.clear()
    ax = fig.add_subplot(111, projection="3d")
    reach = float(np.abs(pts).max()) * 1.05
    ax.set_xlim(-reach, reach), ax.set_ylim(-reach, reach), ax.set_zlim(0, reach * 1.2)
    ax.set_box_aspect((1.0, 1.0, 0.6))  # equal metres on every axis
    ax.set_xlabel("x [m]"), ax.set_ylabel("y [m]"), ax.set_zlabel("z [m]")
    ax.plot(pts[:, 8, 0], pts[:, 8, 1], pts[:, 8, 2], color="tab:orange", linewidth=0.8, gid="tool-path")
    (line,) = ax.plot(*pts[0].T, "-o", color="tab:blue", linewidth=3, markersize=4, gid="arm")
    label = ax.set_title(f"t = {times[0]:.2f} s")

    def update(k: int):
        line.set_data_3d(*pts[k].T)
        label.set_text(f"t = {times[k]:.2f} s")
        return line, label

    return FuncAnimation(fig, update, frames=len(idx), interval=50, blit=False)


ARM_LINKS = ("base", *(f"joint {j}" for j in range(1, 8)), "tool")
ARM_SEGMENTS = tuple((k, k + 1) for k in range(8))  # a chain: base, joints 1..7, tool point


def link_frames(traces: Any) -> LinkFrames | None:
    """The arm's base, joints and tool point at every sample of ``traces`` (pinocchio's forward kinematics of
    q[1..7]), joined base to tool, with the tool's path; None without q[1..7]."""
    q_cols = joint_columns(traces, "q")
    if not q_cols:
        return None
    return LinkFrames(time=trace_times(traces), points=arm_points(traces[q_cols].to_numpy(dtype=float)),
                      segments=ARM_SEGMENTS, path=8, labels=ARM_LINKS)


VIEWER = TraceViewer("panda", panels, arm_animation, link_frames)
