"""FMI 3.0 co-simulation instances (through fmpy's FMU3Slave), arrays included."""

from __future__ import annotations

import ctypes
from functools import partial
from typing import Any, Callable, Sequence

from fmpy.fmi3 import FMU3Slave

from cosim.units.fmu.fmpy_internals import instance_handle, library, with_cached_signatures
from cosim.units.fmu.instance import FmiInstance, FmiSelection, TypeGroup, absent_function, load_library
from cosim.units.protocol import Selection, SimulationEnded


class Fmi3Unit(FmiInstance):
    """A live FMI 3.0 co-simulation instance.

    Array variables are read and written whole (FMI 3.0 transfers arrays as
    one value reference with ``nValues`` elements).
    """

    _c_types = {
        "Float64": ctypes.c_double, "Float32": ctypes.c_float,
        "Int8": ctypes.c_int8, "UInt8": ctypes.c_uint8, "Int16": ctypes.c_int16, "UInt16": ctypes.c_uint16,
        "Int32": ctypes.c_int32, "UInt32": ctypes.c_uint32, "Int64": ctypes.c_int64, "UInt64": ctypes.c_uint64,
        "Enumeration": ctypes.c_int64, "Boolean": ctypes.c_bool, "String": ctypes.c_char_p,
        "Binary": ctypes.POINTER(ctypes.c_uint8),
    }
    _vr_type = ctypes.c_uint
    _call_types = {"Enumeration": "Int64"}
    _prefix = "fmi3"
    _slave_class: Any = with_cached_signatures(FMU3Slave)
    _interface = "coSimulation"  # the attribute of fmpy's ModelDescription naming the interface used
    _state_calls = ("fmi3GetFMUState", "fmi3SetFMUState", "fmi3FreeFMUState")
    _serialize_calls = ("fmi3SerializeFMUState", "fmi3DeserializeFMUState")
    _fmpy_serialize = ("serializeFMUState", "deserializeFMUState")

    def __init__(self, name: str, unit_type: Any):
        super().__init__(name, unit_type)
        md = unit_type.model_description()
        # The Model Exchange subclass (units/model_exchange.py) swaps the fmpy class and the interface.
        self._slave = load_library(unit_type, lambda: self._slave_class(
            guid=md.guid, unzipDirectory=unit_type.extracted_folder(),
            modelIdentifier=getattr(md, self._interface).modelIdentifier, instanceName=name))
        self._guard(f"fmi3Instantiate{self._interface[0].upper()}{self._interface[1:]}",
                    lambda: self._slave.instantiate(logMessage=self._log_callback_py))
        self._component = instance_handle(self._slave)
        self._alive = True
        # Direct library calls in the stepping loop (see Fmi2Unit for why).
        dll = library(self._slave)
        self._calls = {t: (getattr(dll, f"fmi3Get{t if t != 'Enumeration' else 'Int64'}"),
                           getattr(dll, f"fmi3Set{t if t != 'Enumeration' else 'Int64'}"))
                       for t in self._c_types}
        # absent from a Model-Exchange-only FMU (its unit class integrates instead)
        self._do_step: Callable[..., int] = getattr(dll, "fmi3DoStep", absent_function("fmi3DoStep"))
        self._event = ctypes.c_bool()
        self._terminate = ctypes.c_bool()
        self._early = ctypes.c_bool()
        self._last_time = ctypes.c_double()
        self._event_ref, self._terminate_ref = ctypes.byref(self._event), ctypes.byref(self._terminate)
        self._early_ref, self._last_time_ref = ctypes.byref(self._early), ctypes.byref(self._last_time)

    def _log_callback_py(self, env: Any, status: int, category: bytes, message: bytes) -> None:
        self._record_log(status, category, message)

    def _bind(self, group: TypeGroup) -> tuple[Callable[[], int], Callable[[], int]]:
        get, put = self._calls[group.fmi_type]
        if group.fmi_type == "Binary":  # (..., valueSizes, values, nValues): sizes come before the values
            args: tuple[Any, ...] = (self._component, group.vrs, group.n_vrs, group.sizes, group.values,
                                     group.n_values)
        else:
            args = (self._component, group.vrs, group.n_vrs, group.values, group.n_values)
        return partial(get, *args), partial(put, *args)

    def select(self, refs: Sequence[Any]) -> FmiSelection:
        selection = super().select(refs)
        # decided once here, not at every set: set() is on the stepping loop's hot path
        structural = {v.name for v in self.description.variables if v.causality == "structuralParameter"}
        selection.structural = any(r.variable in structural for r in selection.refs)
        return selection

    def set(self, selection: Selection, values: Sequence[Any]) -> None:
        """Set values; structural parameters are set in Configuration Mode, as FMI 3.0 requires."""
        if not getattr(selection, "structural", True):
            return super().set(selection, values)
        self._guard("fmi3EnterConfigurationMode", self._slave.enterConfigurationMode)
        try:
            super().set(selection, values)
        except Exception:
            try:  # leave Configuration Mode if the FMU lets us, but report the set that failed
                self._slave.exitConfigurationMode()
            except Exception:
                pass
            raise
        self._guard("fmi3ExitConfigurationMode", self._slave.exitConfigurationMode)

    _derivative_call_name = "fmi3GetDirectionalDerivative"

    def _derivative_call(self, unknowns: Any, knowns: Any, seed: Any, sensitivity: Any) -> Callable[[], int]:
        return partial(library(self._slave).fmi3GetDirectionalDerivative, self._component, unknowns, len(unknowns),
                       knowns, len(knowns), seed, len(seed), sensitivity, len(sensitivity))

    def setup(self, start_time: float, stop_time: float | None) -> None:
        self.time = start_time
        self._start_time = start_time
        self._stop_time = stop_time

    def enter_initialization(self) -> None:
        self._guard(f"{self._prefix}EnterInitializationMode",
                    lambda: self._slave.enterInitializationMode(startTime=self._start_time, stopTime=self._stop_time))

    def exit_initialization(self) -> None:
        self._guard(f"{self._prefix}ExitInitializationMode", self._slave.exitInitializationMode)

    def do_step(self, t: float, h: float, no_set_prior: bool = True) -> None:
        self.time = t
        self.generation += 1
        status = self._do_step(self._component, t, h, no_set_prior, self._event_ref, self._terminate_ref,
                               self._early_ref, self._last_time_ref)
        if status > 1:
            raise self.fail_status("fmi3DoStep", status)
        if self._terminate.value or self._early.value:
            self._ended_or_returned_early(t, h)

    def _ended_or_returned_early(self, t: float, h: float) -> None:
        """terminateSimulation ends the run at lastSuccessfulTime (t + h unless it returned early);
        an early return without it cannot be followed by a fixed-step master."""
        end = self._last_time.value if self._early.value else t + h
        if self._terminate.value:
            raise SimulationEnded(self.name, end, "ended the simulation (fmi3DoStep: terminateSimulation)")
        raise self._error(f"fmi3DoStep returned early at t={end:g} (earlyReturn) although cosim instantiates "
                          "FMUs with earlyReturnAllowed=false; the master cannot continue a step cut short")
