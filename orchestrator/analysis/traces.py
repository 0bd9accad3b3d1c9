"""Figures of one run's traces, and a stick-figure animation of the Panda arm.

:func:`trace_groups` picks what to show: joint angles (``*.q[i]``), joint
torques (``*.tau[i]``) and electric power (``*p_el*``, ``*p_total*``) when the
traces have them, else every recorded signal grouped by port.
:func:`arm_points` turns joint angles (URDF radians, 7 per sample) into the
3-D positions of the joints and the tool point with pinocchio's forward
kinematics of the model in :mod:`cosim.models.panda_model`.
"""

from __future__ import annotations

import re
import numpy as np
import pandas as pd
from matplotlib.figure import Figure

_ELEMENT = re.compile(r"^(.*)\[(\d+)\]$")


def _port(column: str) -> str:
    m = _ELEMENT.match(column)
    return m.group(1) if m else column


def joint_columns(traces: pd.DataFrame, port: str = "q", n: int = 7) -> list[str] | None:
    """The columns ``<unit>.<port>[1]``..``[n]`` of the first unit that has all of them, or None."""
    for c in traces.columns:
        m = _ELEMENT.match(str(c))
        if m and m.group(1).rsplit(".", 1)[-1] == port and m.group(2) == "1":
            names = [f"{m.group(1)}[{i}]" for i in range(1, n + 1)]
            if all(name in traces.columns for name in names):
                return names
    return None


def trace_groups(traces: pd.DataFrame) -> list[tuple[str, list[str]]]:
    """(title, columns) per panel: robot signals when present, else one panel per port (at most 8)."""
    groups: list[tuple[str, list[str]]] = []
    q, tau = joint_columns(traces, "q"), joint_columns(traces, "tau")
    if q:
        groups.append(("joint angles [rad]", q))
    if tau:
        groups.append(("joint torques [N m]", tau))
    power = [str(c) for c in traces.columns if re.search(r"(^|\.)(p_el|p_total)(\[\d+\])?$", str(c))]
    if power:
        groups.append(("electric power [W]", power))
    if groups:
        return groups
    ports: dict[str, list[str]] = {}
    for c in traces.columns:
        # only numbers and Booleans plot over time; String and Binary (hex) columns are left out
        if str(c) != "time" and (pd.api.types.is_numeric_dtype(traces[c]) or pd.api.types.is_bool_dtype(traces[c])):
            ports.setdefault(_port(str(c)), []).append(str(c))
    return [(name, cols) for name, cols in list(ports.items())[:8]]


def traces_figure(fig: Figure, traces: pd.DataFrame, title: str = "") -> list:
    """One panel per group of :func:`trace_groups` over time (fig cleared first); returns the axes."""
    fig.clear()
    groups = trace_groups(traces)
    t = traces["time"].to_numpy() if "time" in traces.columns else np.arange(len(traces))
    axes = []
    for k, (name, cols) in enumerate(groups):
        ax = fig.add_subplot(len(groups), 1, k + 1)
        for c in cols:
            ax.plot(t, traces[c].to_numpy(dtype=float), linewidth=1.0, label=c.rsplit(".", 1)[-1])
        ax.set_ylabel(name)
        if len(cols) <= 8:
            ax.legend(fontsize="x-small", ncol=min(len(cols), 4), loc="upper right")
        axes.append(ax)
    if axes:
        axes[-1].set_xlabel("time [s]")
        if title:
            axes[0].set_title(title)
    return axes


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


def arm_animation(fig: Figure, traces: pd.DataFrame, frames: int = 60):
    """A FuncAnimation of the arm over the run (``frames`` evenly spaced samples); None without q[1..7].

    Keep a reference to the returned animation, or it stops.
    """
    from matplotlib.animation import FuncAnimation

    q_cols = joint_columns(traces, "q")
    if not q_cols:
        return None
    idx = np.unique(np.linspace(0, len(traces) - 1, frames).round().astype(int))
    pts = arm_points(traces[q_cols].to_numpy(dtype=float)[idx])
    times = traces["time"].to_numpy()[idx] if "time" in traces.columns else idx
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
