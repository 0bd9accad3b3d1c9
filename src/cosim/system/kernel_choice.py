"""Which master steps a system: the native kernel (:mod:`cosim.master.native`) or the Python master.

The spec's ``experiment.kernel`` asks: ``python``; ``native``, refused (a problem at ``$.experiment.kernel``)
for a system the kernel cannot step; or ``auto`` (the default), the kernel wherever the system qualifies and it
can be built here, else the Python master with a note saying why.  Both give the same results bit for bit.

A system qualifies when every unit is an FMI 2.0 or 3.0 FMU run as co-simulation, a player (its table played
by the kernel) or system connectors (values the kernel holds), the algorithm is gauss-seidel (without algebraic
loops), jacobi (without direct feed-through) or jacobi-delayed, and every connection, recorded signal and
objective signal is Real (Float64), Integer (Int32) or Boolean, scalars or FMI 3.0 arrays, with no warm start.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Mapping, Sequence

from cosim.master.loops import Coupling
from cosim.spec.loader import Spec
from cosim.system.coupled_me import ModelExchangeCoupling
from cosim.system.parts import Connection, Signal, SystemUnit

_log = logging.getLogger(__name__)
_CARRIED = {"Real", "Float64", "Integer", "Enumeration", "Int32", "Boolean"}
_ALGORITHMS = ("gauss-seidel", "jacobi", "jacobi-delayed")
_AS_DATA = ("player", "connectors")  # units the kernel runs as data: a table it plays, values it holds


@dataclass(frozen=True)
class KernelChoice:
    """``kernel`` ("native" or "python") and, for python where native was possible to ask, ``reason``."""

    kernel: str = "python"
    reason: str = ""

    def describe(self) -> str:
        """One line for ``cosim inspect``: which kernel, and why not native."""
        return self.kernel + (f" ({self.reason})" if self.reason else "")


def why_not_native(spec: Spec, units: Mapping[str, SystemUnit], connections: Sequence[Connection],
                   coupling: Coupling, model_exchange: ModelExchangeCoupling, probes: Sequence[Signal]) -> str | None:
    """Why the native kernel cannot step this system, or None when it can (its build is not tried here)."""
    exp = spec.experiment
    if exp.algorithm not in _ALGORITHMS:
        return f"the '{exp.algorithm}' algorithm runs in Python only"
    if exp.warm_start is not None:
        return "a warm start runs in Python only"
    for name, unit in units.items():
        d = unit.description
        if d.kind in _AS_DATA:
            continue
        if d.kind != "fmu" or d.fmi_version not in ("2.0", "3.0"):
            return f"unit '{name}' is not an FMI 2.0/3.0 FMU, a player or system connectors ({d.kind})"
        if getattr(unit.unit_type, "interface", None) != "co-simulation":  # an FMU unit type's
            return f"unit '{name}' runs as model exchange"
    if model_exchange.groups:
        return "model-exchange units are integrated together"
    if exp.algorithm == "gauss-seidel" and coupling.loops:
        return "the system has algebraic loops"
    if exp.algorithm == "jacobi" and coupling.direct:
        return "jacobi propagates direct feed-through (jacobi-delayed or gauss-seidel can run natively)"
    for c in connections:
        for signal in (c.source, c.target):
            why = _not_carried(signal, units)
            if why:
                return f"connection {c.source.text} -> {c.target.text}: {why}"
        if c.transforms and (c.source.variable.fmi_type or c.source.variable.type) not in ("Real", "Float64"):
            return f"connection {c.source.text} -> {c.target.text}: a factor or offset on a non-Real value"
        if _code(c.source) != _code(c.target):
            return f"connection {c.source.text} -> {c.target.text} changes the value's type"
    for signal in probes:
        why = _not_carried(signal, units)
        if why:
            return f"signal {signal.text}: {why}"
    return None


def _code(signal: Signal) -> str:
    t = signal.variable.fmi_type or signal.variable.type
    return {"Float64": "Real", "Int32": "Integer", "Enumeration": "Integer"}.get(t, t)


def _not_carried(signal: Signal, units: Mapping[str, SystemUnit]) -> str | None:
    v = signal.variable
    fmi_type = v.fmi_type or v.type
    if fmi_type not in _CARRIED:
        return f"its type {fmi_type} is carried in Python only"
    unit = units.get(signal.unit)
    if fmi_type == "Enumeration" and unit is not None and unit.description.fmi_version == "3.0":
        return "an FMI 3.0 enumeration (Int64) is carried in Python only"
    if v.shape and unit is not None and unit.description.kind == "connectors":
        return "an array of system connectors is carried in Python only"
    return None


def kernel_choice(spec: Spec, why_not: str | None) -> KernelChoice:
    """The kernel for a spec asking ``experiment.kernel`` of a system the kernel cannot step for ``why_not``
    (None: it can).  For ``native`` the caller reports ``why_not`` as a problem; building the kernel is tried
    here (the first time: a few hundred milliseconds of gcc)."""
    wanted = spec.experiment.kernel
    if wanted == "python":
        return KernelChoice("python", "experiment.kernel is 'python'")
    if why_not is None:
        from cosim.master.native.library import available

        why_not = available()
    if why_not is None:
        return KernelChoice("native")
    if wanted == "auto":  # the one note saying why (cosim -v shows it; cosim inspect always does)
        _log.info("note: the Python master steps %s: %s", spec.path, why_not)
    return KernelChoice("python", why_not)
