"""cosim_signals: a unit kind added to cosim from outside its package.

Installed (``pip install -e examples/plugin_unit_kind``), it lets a spec say::

    "units": {"source": {"signal": "square", "parameters": {"frequency": 2.0, "amplitude": 0.5}}}

and get a unit with one output ``y`` = amplitude * shape(frequency * t), where
shape is a sine, a square or a sawtooth wave of period 1.  cosim finds the
kind through the ``cosim.unit_kinds`` entry point this distribution declares
(see pyproject.toml); nothing in cosim names it.
"""

from __future__ import annotations

import math
from dataclasses import replace

from cosim import PythonUnit, Variable
from cosim.units.protocol import UnitDescription, UnitType
from cosim.units.registry import UnitKind

SHAPES = {
    "sine": lambda cycles: math.sin(2.0 * math.pi * cycles),
    "square": lambda cycles: 1.0 if cycles % 1.0 < 0.5 else -1.0,
    "sawtooth": lambda cycles: 2.0 * (cycles % 1.0) - 1.0,
}


class Waveform(PythonUnit):
    """A periodic signal: y = amplitude * shape(frequency * t)."""

    variables = (
        Variable("amplitude", "parameter", start=1.0),
        Variable("frequency", "parameter", start=1.0, unit="Hz"),
        Variable("y", "output", start=0.0),
    )

    def __init__(self, name: str, shape: str):
        self.shape = SHAPES[shape]  # set before the base class applies start values; kept across reset()
        super().__init__(name)

    def initialize(self) -> None:
        self.y = self.amplitude * self.shape(self.frequency * self.start_time)

    def do_step(self, t: float, h: float) -> None:
        self.y = self.amplitude * self.shape(self.frequency * (t + h))


class WaveformType(UnitType):
    """The picklable blueprint: only the shape's name travels to sweep workers."""

    def __init__(self, shape: str):
        self.shape = shape

    def describe(self) -> UnitDescription:
        return replace(Waveform.describe_class(), kind="signal", source=self.shape)

    def instantiate(self, name: str) -> Waveform:
        return Waveform(name, self.shape)


KIND = UnitKind(
    name="signal",
    fields={"signal": {"enum": sorted(SHAPES), "description": "cosim_signals: the shape of a periodic signal y."}},
    create=lambda unit_spec, folder: WaveformType(unit_spec.source),
    example='"signal": "sine"',
    description="a periodic test signal (plug-in cosim_signals)",
)
