"""Small in-memory Python units for testing the master algorithms themselves."""

from __future__ import annotations

import math

from orchestrator import PythonUnit, Variable


class LinearOde(PythonUnit):
    """dx/dt = a*x + b*u, integrated exactly for u held over the step; y = x."""

    variables = (
        Variable("a", "parameter", start=-1.0),
        Variable("b", "parameter", start=1.0),
        Variable("x0", "parameter", start=1.0),
        Variable("u", "input", start=0.0),
        Variable("y", "output", start=1.0),
    )

    def initialize(self):
        self.y = self.x0

    def do_step(self, t, h):
        e = math.exp(self.a * h)
        self.y = e * self.y + ((e - 1.0) / self.a if self.a else h) * self.b * self.u


class Gain(PythonUnit):
    """y = k*u with direct feed-through."""

    variables = (
        Variable("k", "parameter", start=2.0),
        Variable("u", "input", start=0.0),
        Variable("y", "output", start=0.0),
    )
    feedthrough = {"y": ["u"]}

    def compute_outputs(self):
        self.y = self.k * self.u

    def do_step(self, t, h):
        self.compute_outputs()


class Clock(PythonUnit):
    """Outputs the time at the end of each step; 'done' becomes true at t >= t_end."""

    variables = (
        Variable("t_end", "parameter", start=1.0),
        Variable("time", "output", start=0.0, unit="s"),
        Variable("done", "output", type="Boolean", start=False),
        Variable("vec", "output", shape=(3,), start=(0.0, 0.0, 0.0)),
    )

    def initialize(self):
        self.time = self.start_time

    def do_step(self, t, h):
        self.time = t + h
        self.done = self.time >= self.t_end - 1e-12
        self.vec[:] = [self.time, 2 * self.time, -self.time]


class Failing(PythonUnit):
    """Raises at t >= fail_at."""

    variables = (
        Variable("fail_at", "parameter", start=0.5),
        Variable("y", "output", start=0.0),
    )

    def do_step(self, t, h):
        if t >= self.fail_at:
            raise RuntimeError("boom")
        self.y = t


class DriveProfile(PythonUnit):
    """Joint torques and speeds of 7 joints: sine profiles with motoring and braking phases."""

    variables = (
        Variable("tau", "output", shape=(7,), unit="N.m", start=(0.0,) * 7),
        Variable("omega", "output", shape=(7,), unit="rad/s", start=(0.0,) * 7),
    )

    def initialize(self):
        self._set(self.start_time)

    def do_step(self, t, h):
        self._set(t + h)

    def _set(self, t):
        import numpy as np

        j = np.arange(1, 8)
        self.omega[:] = 1.5 * np.sin(2.0 * t + j) / j
        self.tau[:] = 40.0 * np.cos(1.3 * t + 0.5 * j) / j + 5.0
