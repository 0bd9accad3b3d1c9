"""The fast fidelity level of the Panda: perfect tracking, torques by inverse dynamics.

The robot follows its reference exactly (``q = q_ref``, ``qd = qd_ref``,
``qdd = qdd_ref``) and the joint torques are those the rigid-body model needs
for that motion, ``tau = RNEA(q_ref, qd_ref, qdd_ref)`` (pinocchio; thesis
eq. 7-8, which the thesis evaluated the same way).  No servo, no dynamics of
its own: outputs follow the inputs directly (declared as feed-through), so a
master that orders units by feed-through sees this instant's torques.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from cosim.units.python.batch import PythonBatchUnit
from cosim.units.python.unit import PythonUnit

from .panda_model import cached_model, ee_frame_id, limits_exceeded, payload_key, robot_variables
from .panda_rows import IdRowKernel, KernelsUnavailable


class PandaInverseDynamics(PythonUnit):
    """Panda arm, ideal tracking, torques from pinocchio's RNEA (ports: models.panda_model.robot_variables)."""

    variables = robot_variables()
    _refs = ("q_ref", "qd_ref", "qdd_ref")
    feedthrough = {
        "q": ("q_ref",),
        "qd": ("qd_ref",),
        "qdd": ("qdd_ref",),
        "tau": _refs,
        "ee_pos": ("q_ref",),
        "ee_path_length": ("q_ref",),
        "tracking_error": (),
        "tau_ratio": _refs,
        "limit_violated": _refs,
    }

    def initialize(self) -> None:
        self._ensure_model()
        self._path_done = None  # (length, TCP position) at the last communication point
        self.compute_outputs()
        self._path_done = (0.0, self.ee_pos.copy())
        self.ee_path_length = 0.0

    def _ensure_model(self) -> None:
        key = payload_key(self.payload_mass, self.payload_com, self.payload_inertia)
        if getattr(self, "_key", None) != key:  # the model is rebuilt only when the payload changes
            self._model = cached_model(*key)
            self._data = self._model.createData()
            self._ee = ee_frame_id(self._model)
            self._key = key

    def compute_outputs(self) -> None:
        if not hasattr(self, "_model"):  # a master may read outputs in initialization mode
            self._ensure_model()
        m, d = self._model, self._data
        self.q[:] = self.q_ref
        self.qd[:] = self.qd_ref
        self.qdd[:] = self.qdd_ref
        self.tau[:] = pin.rnea(m, d, self.q, self.qd, self.qdd)
        pin.forwardKinematics(m, d, self.q)  # rnea does not leave world placements in data
        self.ee_pos[:] = pin.updateFramePlacement(m, d, self._ee).translation
        done = getattr(self, "_path_done", None)
        if done is not None:  # the chord from the last communication point to now
            dx, dy, dz = (float(x) for x in self.ee_pos - done[1])
            # three squares added left to right, as the twin's (chord * chord).sum(axis=1) does; d.dot(d) went to
            # OpenBLAS's ddot, whose CPU-picked kernel may fuse or reorder it (one ulp off with AVX-512 kernels)
            self.ee_path_length = done[0] + math.sqrt(dx * dx + dy * dy + dz * dz)
        self.tracking_error = 0.0
        np.divide(np.abs(self.tau), self.tau_max, out=self.tau_ratio)
        self.limit_violated = limits_exceeded(self.q, self.qd, self.tau_ratio, self.q_min, self.q_max, self.qd_max)

    def do_step(self, t: float, h: float) -> None:
        """Commit the TCP path up to the current inputs; the rest is recomputed whenever inputs change.

        Under Gauss-Seidel the inputs at ``do_step(t, h)`` are the reference at
        ``t + h``, under Jacobi at ``t``; either way the chord from the last
        committed point to the current pose is added once, so the path length
        is the same sum of chords between communication points.
        """
        if self._outputs_stale:
            self._outputs_stale = False
            self.compute_outputs()
        self._path_done = (self.ee_path_length, self.ee_pos.copy())


class PandaInverseDynamicsBatch(PythonBatchUnit):
    """:class:`PandaInverseDynamics` for K design points at once (lock-step runs, cosim.execution.lockstep).

    pinocchio has no batched RNEA, so it is called per active row, with the
    single unit's calls; the rest (path length, torque ratios, limit flags) is
    one compiled call for all rows (:class:`~cosim.models.panda_rows.IdRowKernel`,
    numpy's operations in numpy's order), or numpy on all rows where the
    library cannot be built here; either way row k's outputs equal a single
    unit's bit for bit.
    """

    def initialize(self) -> None:
        self._models = []
        keys: dict[tuple, tuple] = {}
        for k in range(self.rows):
            key = payload_key(self.payload_mass[k], self.payload_com[k], self.payload_inertia[k])
            if key not in keys:
                model = cached_model(*key)
                keys[key] = (model, model.createData(), ee_frame_id(model))
            self._models.append(keys[key])
        # row views, made once: the arrays are only ever written in place
        self._row_views = list(zip(self.q, self.qd, self.qdd))
        # the TCP path committed at the last communication point (do_step), written in place
        self._done_length, self._done_ee = np.zeros(self.rows), np.zeros((self.rows, 3))
        self._committed = False
        self._kernel = self._row_kernel()
        self._active_seen: np.ndarray | None = None
        self.compute_outputs()
        self._done_ee[:] = self.ee_pos
        self._committed = True
        self.ee_path_length[:] = 0.0

    def _row_kernel(self) -> IdRowKernel | None:
        arrays = {name: getattr(self, name) for name in ("q", "qd", "tau", "q_min", "q_max", "qd_max", "tau_max",
                                                         "ee_pos", "ee_path_length", "tracking_error", "tau_ratio",
                                                         "limit_violated")}
        try:
            return IdRowKernel(dict(arrays, done_length=self._done_length, done_ee=self._done_ee), self.rows)
        except (KernelsUnavailable, ValueError):  # no C compiler here, or an array not as the kernel takes it
            return None

    def compute_outputs(self) -> None:
        self.q[:] = self.q_ref
        self.qd[:] = self.qd_ref
        self.qdd[:] = self.qdd_ref
        q, qd, tau, ee, models, views = self.q, self.qd, self.tau, self.ee_pos, self._models, self._row_views
        rnea, kinematics, placement = pin.rnea, pin.forwardKinematics, pin.updateFramePlacement
        active = self.active
        for k in active.tolist():
            m, d, frame = models[k]
            q_k, qd_k, qdd_k = views[k]
            tau[k] = rnea(m, d, q_k, qd_k, qdd_k)
            kinematics(m, d, q_k)
            ee[k] = placement(m, d, frame).translation
        if self._kernel is not None:
            if active is not self._active_seen:  # lock-step sets a new array when rows end
                self._active_seen = active
                self._active_c = np.ascontiguousarray(active, dtype=np.int64)
                self._active_address = self._active_c.ctypes.data
            self._kernel.outputs(len(self._active_c), self._active_address, self._committed)
            return
        if self._committed:  # the chord from the last communication point to now, as the single unit
            chord = ee[active] - self._done_ee[active]
            # a row's 3 squares add left to right (numpy's own order for 3 elements, no BLAS), as in the single
            # unit, so the length is the same bit for bit on any machine
            self.ee_path_length[active] = self._done_length[active] + np.sqrt((chord * chord).sum(axis=1))
        self.tracking_error[:] = 0.0
        np.divide(np.abs(tau), self.tau_max, out=self.tau_ratio)
        self.limit_violated[:] = ((self.tau_ratio.max(axis=1) > 1.0) | ((q - self.q_min).min(axis=1) < 0.0)
                                  | ((self.q_max - q).min(axis=1) < 0.0)
                                  | ((np.abs(qd) - self.qd_max).max(axis=1) > 0.0))

    def do_step(self, t: float, h: float) -> None:
        if self._outputs_stale:
            self._outputs_stale = False
            self.compute_outputs()
        np.copyto(self._done_length, self.ee_path_length)
        np.copyto(self._done_ee, self.ee_pos)


PandaInverseDynamics.batch_class = PandaInverseDynamicsBatch
