"""A system's connectors as a unit: the signals an SSP's system connectors carry, named as the system's tools
name them (``Root.sub.speed``), so that a spec can record them and reduce objectives over them.

A connector fed (through a chain of connections) by a component output carries that output scaled by the
chain's unit conversions and ``LinearTransformation``s: it is an *input* of this unit, fed by a connection with
that factor and offset, and holds what the connection gives it (recorded as every input is).  A connector
holding a bound value is a *parameter* of this unit, set to it.  The unit computes nothing: it steps in no time
and has no outputs, so it changes no other unit's values.

A spec (or :mod:`cosim.ssp`, which writes it) declares one as::

    "default.sub": {"connectors": "default.sub", "inputs": {"speed": "rad/s"}, "parameters": {"k": -0.5}}
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Mapping

from cosim.units.kind import UnitKind, UnitSpec
from cosim.units.protocol import UnitDescription, UnitType, Variable
from cosim.units.python.unit import PythonUnit

_TYPES = ((bool, "Boolean"), (int, "Integer"), (float, "Real"), (str, "String"))


class SystemConnectors(PythonUnit):
    """The connectors of one system: inputs that hold the values connected to them, parameters that hold constants."""

    def do_step(self, t: float, h: float) -> None:
        pass  # the inputs are set by the connections, the parameters before initialization: nothing to compute


class SystemConnectorsType(UnitType):
    """The picklable blueprint of a :class:`SystemConnectors`: the system's name, its fed connectors (name ->
    unit of measure, '' for none) and its constants (name -> value, which gives the type)."""

    def __init__(self, system: str, inputs: Mapping[str, str] | None = None, constants: Mapping[str, Any] | None = None):
        self.system = system
        self.inputs = dict(inputs or {})
        self.constants = dict(constants or {})
        self._class: type[SystemConnectors] | None = None

    def __getstate__(self) -> dict[str, Any]:
        return {"system": self.system, "inputs": self.inputs, "constants": self.constants, "_class": None}

    def _variables(self) -> tuple[Variable, ...]:
        variables = [Variable(name, "input", "Real", unit or None, 0.0, f"system connector {self.system}.{name}")
                     for name, unit in self.inputs.items()]
        for name, value in self.constants.items():
            kind = next((t for python, t in _TYPES if isinstance(value, python)), None)
            if kind is None:
                raise ValueError(f"the constant '{name}' of system '{self.system}' is {value!r}: a connector holds "
                                 "a number, a Boolean or a string")
            variables.append(Variable(name, "parameter", kind, None, value, f"system connector {self.system}.{name}",
                                      variability="fixed"))
        return tuple(variables)

    def _unit_class(self) -> type[SystemConnectors]:
        if self._class is None:
            self._class = type("SystemConnectors", (SystemConnectors,), {"variables": self._variables(),
                                                                         "__module__": __name__})
        return self._class

    def describe(self) -> UnitDescription:
        return replace(self._unit_class().describe_class(), kind="connectors", source=self.system,
                       description=f"the connectors of system '{self.system}'")

    def instantiate(self, name: str) -> SystemConnectors:
        return self._unit_class()(name)


def _create_connectors(spec: UnitSpec, folder: str) -> SystemConnectorsType:
    return SystemConnectorsType(spec.source, spec.options.get("inputs"), spec.parameters)


KIND = UnitKind("connectors", {
    "connectors": {"type": "string", "description": "The system whose connectors the unit holds (an SSP's "
                                                   "system, e.g. 'default.sub'): its inputs hold what is connected "
                                                   "to them, its parameters constants; it computes nothing. Written "
                                                   "by cosim for an SSP's system connectors."},
    "inputs": {"type": "object", "additionalProperties": {"type": "string"},
               "description": "connectors only: the connectors fed by a connection, each with its unit of measure "
                              "('' for none)."},
    "feeds": {"type": "object",
              "additionalProperties": {"type": "array", "items": {
                  "type": "object", "required": ["to"], "additionalProperties": False,
                  "properties": {"to": {"type": "string"}, "factor": {"type": "number"},
                                 "offset": {"type": "number"}}}},
              "description": "connectors only: the unit parameters each parameter connector sets (an SSP's "
                             "parameter connections): a value given to the connector by a design parameter or "
                             "--set sets each 'to' to factor x value + offset (default 1 and 0)."},
}, _create_connectors, example='"connectors": "default.sub"',
    description="the connectors of an SSP's system, as signals of their own")
