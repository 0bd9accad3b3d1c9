"""A joint path given as samples, for the energy-optimal timing (:mod:`models.optimal_timing`).

The optimal timing re-times a geometric path ``q(s)``.  With waypoints the
path is the parabolic blend's; :class:`SampledPath` is the other way to give
it: a table of joint positions along the path, e.g. a trajectory recorded by
``cosim run --out`` (the player's format: a ``time`` column and one column per
joint, ``traj.q_ref[1]`` .. ``traj.q_ref[7]``), or an array of samples.

The path parameter ``s`` is the samples' own time when they have one, else the
time a motion at the joint speed limits would need between samples (the
slowest joint at its limit, as eq. 7-6 of the parabolic blend), so ``s_dot = 1``
is the recorded timing or a motion near the speed limits.  Between samples the
path is scipy's cubic spline (not-a-knot): ``q``, ``q'`` and ``q''`` are
continuous, a straight line stays exactly straight.  Like the blend, the path
rests at its first sample before ``s = 0`` and at its last after the end.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

from .panda_model import N_JOINTS


@dataclass(frozen=True)
class SampledPath:
    """A path through joint-position samples ``waypoints`` (m x 7) at path parameters ``s`` (m,)."""

    waypoints: np.ndarray  # the samples (m, 7), URDF radians
    s: np.ndarray  # their path parameters, s[0] = 0, strictly increasing
    _spline: CubicSpline = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_spline", CubicSpline(self.s, self.waypoints, axis=0, bc_type="not-a-knot"))

    @classmethod
    def from_samples(cls, q, s=None, v_max=None) -> "SampledPath":
        """The path through ``q`` (m x 7, m >= 2) at parameters ``s`` (m, increasing; shifted to start at 0).

        Without ``s``: the time at the speed limits ``v_max`` (7) between samples.
        Consecutive identical samples are merged.  Raises ValueError for fewer than two
        distinct samples, wrong shapes, values that are not finite or ``s`` that does not increase.
        """
        q = np.asarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] != N_JOINTS:
            raise ValueError(f"path samples must be an m x {N_JOINTS} array, got shape {q.shape}")
        if not np.all(np.isfinite(q)):
            raise ValueError("path samples must be finite")
        start = 0.0  # the first sample's own path parameter, for messages
        keep = np.ones(len(q), dtype=bool)
        keep[1:] = np.any(q[1:] != q[:-1], axis=1)
        if s is None:
            if v_max is None:
                raise ValueError("give the samples' path parameters s or the speed limits v_max")
            q = q[keep]
            step = np.max(np.abs(np.diff(q, axis=0)) / np.asarray(v_max, dtype=float).reshape(N_JOINTS), axis=1)
            s = np.concatenate([[0.0], np.cumsum(step)])
        else:
            s = np.asarray(s, dtype=float).reshape(-1)
            if s.shape != (len(q),) or not np.all(np.isfinite(s)):
                raise ValueError(f"s must hold {len(q)} finite values, one per sample")
            q, s = q[keep], s[keep]  # a recording at rest repeats samples: the path is the same
            start = float(s[0])
            s = s - start
        if len(q) < 2:
            raise ValueError("a path needs at least two distinct samples")
        steps = np.diff(s)
        if np.any(steps == 0):
            # `cosim run --out` records an event as two rows at one time (before and after it): a jump of q the
            # spline cannot pass through, so it is refused rather than smoothed over
            at = float(s[1:][steps == 0][0] + start)
            raise ValueError(f"two different samples at path parameter (time) {at:g}, as a recorded event's rows "
                             "are: a path must pass each time once; keep one row per time (e.g. the last) or "
                             "record the path without the event")
        if np.any(steps < 0):
            raise ValueError("the samples' path parameters (times) must increase")
        return cls(waypoints=q, s=s)

    @classmethod
    def from_table(cls, path: str | Path, columns: str = "traj.q_ref") -> "SampledPath":
        """The path recorded in a table (Parquet or CSV, as ``cosim run --out`` writes and the player reads):
        its ``time`` column and the columns ``<columns>[1]`` .. ``<columns>[7]`` (URDF radians).

        Raises FileNotFoundError for a missing file, ValueError for a table without those columns
        (the message names the file and the columns it has) or with unusable samples.
        """
        from cosim.units.player import read_table

        frame = read_table(path)
        names = [f"{columns}[{j}]" for j in range(1, N_JOINTS + 1)]
        missing = [n for n in names if n not in frame.columns]
        if missing:
            raise ValueError(f"{path}: no column {missing[0]!r} (path_columns = {columns!r}); columns: "
                             f"{', '.join(map(str, frame.columns[:12]))}")
        try:
            return cls.from_samples(frame[names].to_numpy(dtype=float), s=frame["time"].to_numpy(dtype=float))
        except ValueError as error:
            raise ValueError(f"{path}: {error}") from None

    @property
    def duration(self) -> float:
        """The end of the path parameter (the samples' own duration when ``s`` is their time)."""
        return float(self.s[-1])

    @property
    def phase_start(self) -> np.ndarray:
        """One phase: the planning grid is uniform in ``s`` (q'' is continuous)."""
        return np.zeros(1)

    def sample(self, s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``q(s)``, ``q'(s)``, ``q''(s)``; at rest at the first sample before 0 and at the last after the end."""
        if s <= 0.0 or s >= self.s[-1]:
            z = np.zeros(N_JOINTS)
            return (self.waypoints[0] if s <= 0.0 else self.waypoints[-1]).copy(), z, z.copy()
        return self._spline(s), self._spline(s, 1), self._spline(s, 2)
