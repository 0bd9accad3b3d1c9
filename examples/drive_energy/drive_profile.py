"""A recorded-looking joint drive profile for seven joints, as a Python unit.

Each joint follows a smooth speed profile with accelerating, cruising and
braking phases, and the joint torque is inertia times acceleration plus a
gravity-like offset, so the energy model sees motoring, braking and
standstill under load.  It stands in for a robot unit in this small example.
"""

from __future__ import annotations

import numpy as np

from cosim import PythonUnit, Variable


class DriveProfile(PythonUnit):
    """Joint speeds and torques of 7 joints over one motion of `duration` seconds."""

    variables = (
        Variable("duration", "parameter", unit="s", start=2.0, min=0.1, description="Length of the motion"),
        Variable("stroke", "parameter", unit="rad", start=1.5, description="Angle each joint travels"),
        Variable("inertia", "parameter", shape=(7,), unit="kg.m2",
                 start=(1.2, 1.5, 0.6, 0.5, 0.05, 0.05, 0.02), description="Joint-side inertia"),
        Variable("holding", "parameter", shape=(7,), unit="N.m",
                 start=(0.0, 25.0, 0.0, 12.0, 0.0, 1.0, 0.0), description="Torque held against gravity"),
        Variable("omega", "output", shape=(7,), unit="rad/s", start=(0.0,) * 7, description="Joint speed"),
        Variable("tau", "output", shape=(7,), unit="N.m", start=(0.0,) * 7, description="Joint torque"),
    )

    def initialize(self):
        self._set(self.start_time)

    def do_step(self, t, h):
        self._set(t + h)

    def _set(self, t):
        # a cycloidal motion: speed (1 - cos) shape, zero speed and acceleration at both ends
        phase = min(max(t / self.duration, 0.0), 1.0)
        speed = self.stroke / self.duration * (1.0 - np.cos(2.0 * np.pi * phase))
        accel = self.stroke / self.duration**2 * 2.0 * np.pi * np.sin(2.0 * np.pi * phase)
        self.omega[:] = speed
        self.tau[:] = self.inertia * accel + self.holding
