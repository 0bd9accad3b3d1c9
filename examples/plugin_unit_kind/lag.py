"""A first-order lag, tau * dx/dt = u - x, integrated exactly over each step (u held)."""

import math

from cosim import PythonUnit, Variable


class Lag(PythonUnit):
    variables = (Variable("tau", "parameter", start=1.0, unit="s"), Variable("u", "input"),
                 Variable("x", "output", start=0.0))

    def do_step(self, t, h):
        self.x = self.u + (self.x - self.u) * math.exp(-h / self.tau)
