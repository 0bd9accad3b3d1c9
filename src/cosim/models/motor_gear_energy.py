"""Electric power and energy of the Panda's 7 joint motors, as a Python unit.

The same model, with exactly the same ports, as the ``motor_gear_energy`` FMU
(``fmus/motor_gear_energy``, see ``fmus/README.md`` for the equations and the
choices at standstill and without recuperation), so a spec swaps one for the
other by changing one line::

    "energy": {"python": "models.motor_gear_energy:MotorGearEnergy"}
    "energy": {"fmu": "motor_gear_energy_fmi3.fmu"}

Bad parameters raise :class:`UnitError` when initialization ends; a NaN or
infinite input raises :class:`UnitError` when outputs are computed or a step
is taken.
"""

from __future__ import annotations

import math

import numpy as np

from cosim.units.protocol import UnitError, Variable
from cosim.units.python.unit import PythonUnit

N_JOINTS = 7
RAD_PER_S_TO_RPM = 60.0 / (2.0 * math.pi)

_ZEROS = (0.0,) * N_JOINTS


def _array(name: str, causality: str, start, unit: str | None, description: str, size: int = N_JOINTS, **kw) -> Variable:
    start = tuple(start) if isinstance(start, (list, tuple)) else (float(start),) * size
    return Variable(name, causality, "Real", unit=unit, start=start, description=description, shape=(size,), **kw)


class MotorGearEnergy(PythonUnit):
    """BLDC joint motors behind harmonic drives: electric power and energy (thesis 7.2.2)."""

    variables = (
        _array("tau", "input", 0.0, "N.m", "Joint-side torque"),
        _array("omega", "input", 0.0, "rad/s", "Joint angular velocity"),
        _array("gear_ratio", "parameter", 100.0, None, "Gear ratio R (> 0)", variability="fixed"),
        _array("r_terminal", "parameter", 0.22, "Ohm", "Terminal resistance R_T (>= 0)", variability="fixed"),
        _array("k_m", "parameter", 0.134, "N.m/A", "Torque constant k_M (> 0)", variability="fixed"),
        _array("eta_motor", "parameter", 0.92, None, "Motor efficiency in (0, 1]", variability="fixed"),
        _array("eta_gear_speed", "parameter", (500.0, 1000.0, 2000.0, 3000.0), "rpm",
               "Motor speeds of the gear-efficiency table (strictly increasing)", size=4, variability="fixed"),
        _array("eta_gear_value", "parameter", (0.75, 0.69, 0.63, 0.58), None,
               "Gear efficiencies at eta_gear_speed, in (0, 1]", size=4, variability="fixed"),
        Variable("recuperation", "parameter", "Boolean", start=True, variability="fixed",
                 description="false: the supply takes no power back, p_el = max(electric power, 0)"),
        _array("n_motor", "output", _ZEROS, "rpm", "Signed motor speed omega * 60/(2 pi) * R"),
        _array("eta_gear", "output", _ZEROS, None, "Gear efficiency at |n_motor|"),
        _array("tau_motor", "output", _ZEROS, "N.m", "Motor torque; standstill under load counts as motoring"),
        _array("i_motor", "output", _ZEROS, "A", "Motor current tau_motor / k_m"),
        _array("p_el", "output", _ZEROS, "W", "Electric power R_T i^2 + tau_motor * omega_motor"),
        _array("e_el", "output", _ZEROS, "J", "Electric energy so far (integral of p_el)"),
        Variable("p_total", "output", unit="W", start=0.0, description="Sum of p_el"),
        Variable("e_total", "output", unit="J", start=0.0, description="Sum of e_el"),
        Variable("e_total_no_recuperation", "output", unit="J", start=0.0,
                 description="Integral of the sum of max(p_el, 0)"),
    )
    feedthrough = {
        "n_motor": ("omega",),
        "eta_gear": ("omega",),
        "tau_motor": ("tau", "omega"),
        "i_motor": ("tau", "omega"),
        "p_el": ("tau", "omega"),
        "p_total": ("tau", "omega"),
    }

    def initialize(self) -> None:
        """Check the parameters (raises UnitError like the FMU's exitInitializationMode) and zero the energies."""
        self._check(self.gear_ratio, "gear_ratio", lambda x: np.isfinite(x) & (x > 0), "finite and > 0")
        self._check(self.r_terminal, "r_terminal", lambda x: np.isfinite(x) & (x >= 0), "finite and >= 0")
        self._check(self.k_m, "k_m", lambda x: np.isfinite(x) & (x > 0), "finite and > 0")
        self._check(self.eta_motor, "eta_motor", lambda x: (x > 0) & (x <= 1), "an efficiency in (0, 1]")
        self._check(self.eta_gear_value, "eta_gear_value", lambda x: (x > 0) & (x <= 1), "an efficiency in (0, 1]")
        speeds = np.asarray(self.eta_gear_speed, dtype=float)
        if not (np.all(np.isfinite(speeds)) and np.all(np.diff(speeds) > 0)):
            raise UnitError(self.name, f"parameter eta_gear_speed = {speeds.tolist()} must be finite and strictly increasing")
        self.e_el = np.zeros(N_JOINTS)
        self.e_total = 0.0
        self.e_total_no_recuperation = 0.0

    def _check(self, values, name: str, ok, what: str) -> None:
        values = np.asarray(values, dtype=float)
        bad = np.flatnonzero(~ok(values))
        if bad.size:
            i = int(bad[0])
            raise UnitError(self.name, f"parameter {name}[{i + 1}] = {values[i]:g} must be {what}")

    def compute_outputs(self) -> None:
        """Outputs from the current tau and omega (raises UnitError for NaN or infinite inputs)."""
        tau = np.asarray(self.tau, dtype=float)
        omega = np.asarray(self.omega, dtype=float)
        for name, x in (("tau", tau), ("omega", omega)):
            bad = np.flatnonzero(~np.isfinite(x))
            if bad.size:
                raise UnitError(self.name, f"input {name}[{bad[0] + 1}] = {x[bad[0]]} is not a finite number")
        ratio = np.asarray(self.gear_ratio, dtype=float)
        omega_motor = omega * ratio  # rad/s: mechanical power needs rad/s, not rpm
        self.n_motor = omega_motor * RAD_PER_S_TO_RPM
        self.eta_gear = np.interp(np.abs(self.n_motor), self.eta_gear_speed, self.eta_gear_value)
        eta = self.eta_gear * np.asarray(self.eta_motor, dtype=float)
        braking = tau * omega < 0.0  # standstill under load (omega = 0) is motoring
        self.tau_motor = np.where(braking, tau * eta / ratio, tau / (ratio * eta))
        self.i_motor = self.tau_motor / np.asarray(self.k_m, dtype=float)
        p = np.asarray(self.r_terminal, dtype=float) * self.i_motor**2 + self.tau_motor * omega_motor
        self.p_el = p if self.recuperation else np.maximum(p, 0.0)
        self.p_total = float(self.p_el.sum())

    def do_step(self, t: float, h: float) -> None:
        """Integrate the energies exactly for inputs held over [t, t + h]."""
        self.compute_outputs()
        self.e_el = self.e_el + self.p_el * h
        self.e_total = float(self.e_el.sum())
        self.e_total_no_recuperation += float(np.maximum(self.p_el, 0.0).sum()) * h
