"""Small in-memory Python units for testing the master algorithms themselves."""

from __future__ import annotations

import math

from cosim import PythonUnit, Variable


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


class MeasuredSource(PythonUnit):
    """Ramps in everyday units: speed = 600 + 30 t rpm, temp = 20 + t degC, length = 1000 t mm, torque = t N.m."""

    variables = (
        Variable("speed", "output", start=600.0, unit="rpm"),
        Variable("temp", "output", start=20.0, unit="degC"),
        Variable("length", "output", start=0.0, unit="mm"),
        Variable("torque", "output", start=0.0, unit="N.m"),
    )

    def do_step(self, t, h):
        t = t + h
        self.speed, self.temp, self.length, self.torque = 600.0 + 30.0 * t, 20.0 + t, 1000.0 * t + 0.1, t


class SiSink(PythonUnit):
    """Takes SI inputs (rad/s, K, m, A) and echoes them as outputs at the next step."""

    variables = (
        Variable("omega", "input", start=0.0, unit="rad/s"),
        Variable("temperature", "input", start=0.0, unit="K"),
        Variable("x", "input", start=0.0, unit="m"),
        Variable("current", "input", start=0.0, unit="A"),
        Variable("omega_seen", "output", start=0.0, unit="rad/s"),
        Variable("temperature_seen", "output", start=0.0, unit="K"),
        Variable("x_seen", "output", start=0.0, unit="m"),
    )

    def do_step(self, t, h):
        self.omega_seen, self.temperature_seen, self.x_seen = self.omega, self.temperature, self.x


class TwoBowls(PythonUnit):
    """A bi-objective test problem with a known Pareto front.

    f1 = x^2 + y^2 and f2 = (x - 2)^2 + y^2: the designs that cannot be improved
    in one objective without losing in the other are y = 0, 0 <= x <= 2, so the
    front is f2 = (2 - sqrt(f1))^2 for 0 <= f1 <= 4.  A design with
    x > crash_above kills its process (a crashing point).
    """

    variables = (
        Variable("x", "parameter", start=0.0),
        Variable("y", "parameter", start=0.0),
        Variable("crash_above", "parameter", start=math.inf),
        Variable("f1", "output", start=0.0),
        Variable("f2", "output", start=0.0),
    )

    def do_step(self, t, h):
        if self.x > self.crash_above:
            import os

            os._exit(3)
        self.f1 = self.x ** 2 + self.y ** 2
        self.f2 = (self.x - 2.0) ** 2 + self.y ** 2


class EndsAtHalf(PythonUnit):
    """Counts steps and ends the whole simulation at t = 0.5 (a Python unit's early stop)."""

    variables = (Variable("n", "output", type="Integer", start=0),)

    def do_step(self, t, h):
        from cosim.units.protocol import SimulationEnded

        self.n += 1
        if t + h >= 0.5 - 1e-12:
            raise SimulationEnded(self.name, t + h, "reached its end")


class TemperatureRise(PythonUnit):
    """A temperature difference in degC (FMI relativeQuantity): 2 degC after the first step."""

    variables = (Variable("rise", "output", start=0.0, unit="degC", relative_quantity=True),)

    def do_step(self, t, h):
        self.rise = 2.0


class Ishigami(PythonUnit):
    """y = sin(x1) + a sin(x2)^2 + b x3^4 sin(x1) (Ishigami & Homma 1990), and lin = 3 x1 + x2 (for Morris)."""

    variables = (
        Variable("x1", "parameter", start=0.0),
        Variable("x2", "parameter", start=0.0),
        Variable("x3", "parameter", start=0.0),
        Variable("a", "parameter", start=7.0),
        Variable("b", "parameter", start=0.1),
        Variable("y", "output", start=0.0),
        Variable("lin", "output", start=0.0),
    )

    def do_step(self, t, h):
        self.y = math.sin(self.x1) + self.a * math.sin(self.x2) ** 2 + self.b * self.x3 ** 4 * math.sin(self.x1)
        self.lin = 3.0 * self.x1 + self.x2


class Algebraic(PythonUnit):
    """y = c0 + c1*u + c2*u^2 + c3*u^3 + a*cos(u) + w, direct feed-through from u and w (as the `algebraic` FMU)."""

    variables = (
        Variable("c0", "parameter", start=0.0),
        Variable("c1", "parameter", start=1.0),
        Variable("c2", "parameter", start=0.0),
        Variable("c3", "parameter", start=0.0),
        Variable("a", "parameter", start=0.0),
        Variable("u", "input", start=0.0),
        Variable("w", "input", start=0.0),
        Variable("y", "output", start=0.0),
    )
    feedthrough = {"y": ["u", "w"]}

    def compute_outputs(self):
        self.y = self.c0 + self.c1 * self.u + self.c2 * self.u ** 2 + self.c3 * self.u ** 3 + self.a * math.cos(self.u) + self.w

    def do_step(self, t, h):
        self.compute_outputs()


class Saturation(PythonUnit):
    """y = min(max(u, lo), hi), direct feed-through (a limiter)."""

    variables = (
        Variable("lo", "parameter", start=-1.0),
        Variable("hi", "parameter", start=1.0),
        Variable("u", "input", start=0.0),
        Variable("y", "output", start=0.0),
    )
    feedthrough = {"y": ["u"]}

    def compute_outputs(self):
        self.y = min(max(self.u, self.lo), self.hi)

    def do_step(self, t, h):
        self.compute_outputs()


class Counter(PythonUnit):
    """An Integer output n = n_in + 1 that depends directly on its Integer input (a loop that cannot be solved)."""

    variables = (
        Variable("n_in", "input", type="Integer", start=0),
        Variable("n", "output", type="Integer", start=0),
    )
    feedthrough = {"n": ["n_in"]}

    def compute_outputs(self):
        self.n = self.n_in + 1

    def do_step(self, t, h):
        self.compute_outputs()


class RestorableLinearOde(LinearOde):
    """LinearOde whose state can be saved and restored (get_state/set_state), counting the steps it keeps:
    a state kept outside its variables, so a test sees that a restore brings it back too."""

    def initialize(self):
        super().initialize()
        self.steps_kept = 0

    def do_step(self, t, h):
        super().do_step(t, h)
        self.steps_kept += 1

    def get_state(self):
        return self.steps_kept

    def set_state(self, state):
        self.steps_kept = state


class Sleeper(PythonUnit):
    """Sleeps ``delay`` seconds per step (a point whose cost depends on its design); y = gain * t."""

    variables = (
        Variable("delay", "parameter", start=0.0),
        Variable("gain", "parameter", start=1.0),
        Variable("y", "output", start=0.0),
    )

    def do_step(self, t, h):
        import time

        time.sleep(self.delay)
        self.y = self.gain * (t + h)


class TunableLinearOde(RestorableLinearOde):
    """RestorableLinearOde whose a and b may change between steps (variability tunable, as a warm start needs);
    every instance's do_step calls are counted in ``calls`` (class-wide), so a test measures the work done."""

    variables = (
        Variable("a", "parameter", start=-1.0, variability="tunable"),
        Variable("b", "parameter", start=1.0, variability="tunable"),
        Variable("x0", "parameter", start=1.0),
        Variable("u", "input", start=0.0),
        Variable("y", "output", start=1.0),
    )
    calls = 0

    def do_step(self, t, h):
        super().do_step(t, h)
        TunableLinearOde.calls += 1


class UnpicklableState(RestorableLinearOde):
    """A restorable unit whose saved state cannot be pickled (a lambda): it cannot be serialized for a warm start."""

    def get_state(self):
        return lambda: self.steps_kept

    def set_state(self, state):
        self.steps_kept = state()


class RestorableEndsAtHalf(EndsAtHalf):
    """EndsAtHalf with a restorable state (all of it in its variables)."""

    def get_state(self):
        return None

    def set_state(self, state):
        pass
