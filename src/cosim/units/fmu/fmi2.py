"""FMI 2.0 co-simulation instances (through fmpy's FMU2Slave)."""

from __future__ import annotations

import ctypes
from functools import partial
from typing import Any, Callable

from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    fmi2LastSuccessfulTime,
    fmi2StepFinishedTYPE,
    fmi2Terminated,
)

from cosim.units.fmu.fmpy_internals import fmi2_allocator, instance_handle, library, with_cached_signatures
from cosim.units.fmu.instance import FmiInstance, TypeGroup, absent_function, load_library
from cosim.units.protocol import SimulationEnded


class Fmi2Unit(FmiInstance):
    """A live FMI 2.0 co-simulation instance.

    Each instance has its own FMU2Slave object: fmpy's ``freeInstance`` also
    unloads the shared library, so a slave object is never reused after it.
    """

    _c_types = {"Real": ctypes.c_double, "Integer": ctypes.c_int, "Enumeration": ctypes.c_int,
                "Boolean": ctypes.c_int, "String": ctypes.c_char_p}
    _vr_type = ctypes.c_uint
    _call_types = {"Enumeration": "Integer"}
    _prefix = "fmi2"
    _slave_class: Any = with_cached_signatures(FMU2Slave)
    _interface = "coSimulation"  # the attribute of fmpy's ModelDescription naming the interface used
    _state_calls = ("fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate")
    _serialize_calls = ("fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate")
    _fmpy_serialize = ("serializeFMUstate", "deSerializeFMUstate")

    def __init__(self, name: str, unit_type: Any):
        super().__init__(name, unit_type)
        md = unit_type.model_description()
        # The Model Exchange subclass (units/model_exchange.py) swaps the fmpy class and the interface.
        self._slave = load_library(unit_type, lambda: self._slave_class(
            guid=md.guid, unzipDirectory=unit_type.extracted_folder(),
            modelIdentifier=getattr(md, self._interface).modelIdentifier, instanceName=name))
        self._callbacks = fmi2CallbackFunctions()
        self._callbacks.logger = fmi2CallbackLoggerTYPE(
            lambda env, instance, status, category, message: self._record_log(status, category, message))
        calloc, free = fmi2_allocator()
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self._callbacks.stepFinished = fmi2StepFinishedTYPE()
        self._guard("fmi2Instantiate", lambda: self._slave.instantiate(callbacks=self._callbacks, loggingOn=False))
        self._component = instance_handle(self._slave)
        self._alive = True
        # The stepping loop calls the library's functions directly (fmpy has
        # set their ctypes signatures) and checks the status itself: fmpy's
        # wrappers cost more than the FMU's own work for small models.
        dll = library(self._slave)
        self._calls = {
            "Real": (dll.fmi2GetReal, dll.fmi2SetReal),
            "Integer": (dll.fmi2GetInteger, dll.fmi2SetInteger),
            "Enumeration": (dll.fmi2GetInteger, dll.fmi2SetInteger),
            "Boolean": (dll.fmi2GetBoolean, dll.fmi2SetBoolean),
            "String": (dll.fmi2GetString, dll.fmi2SetString),
        }
        # absent from a Model-Exchange-only FMU (its unit class integrates instead)
        self._do_step: Callable[..., int] = getattr(dll, "fmi2DoStep", absent_function("fmi2DoStep"))

    def _bind(self, group: TypeGroup) -> tuple[Callable[[], int], Callable[[], int]]:
        get, put = self._calls[group.fmi_type]
        args = (self._component, group.vrs, group.n_vrs, group.values)
        return partial(get, *args), partial(put, *args)

    _derivative_call_name = "fmi2GetDirectionalDerivative"

    def _derivative_call(self, unknowns: Any, knowns: Any, seed: Any, sensitivity: Any) -> Callable[[], int]:
        return partial(library(self._slave).fmi2GetDirectionalDerivative, self._component, unknowns, len(unknowns),
                       knowns, len(knowns), seed, sensitivity)

    def setup(self, start_time: float, stop_time: float | None) -> None:
        self.time = start_time
        self._guard("fmi2SetupExperiment",
                    lambda: self._slave.setupExperiment(startTime=start_time, stopTime=stop_time))

    def enter_initialization(self) -> None:
        self._guard(f"{self._prefix}EnterInitializationMode", self._slave.enterInitializationMode)

    def exit_initialization(self) -> None:
        self._guard(f"{self._prefix}ExitInitializationMode", self._slave.exitInitializationMode)

    def do_step(self, t: float, h: float, no_set_prior: int = 1) -> None:
        self.time = t
        self.generation += 1
        status = self._do_step(self._component, t, h, no_set_prior)
        if status > 1:
            self.step_outcome(status)

    def step_outcome(self, status: int) -> None:
        """Raise for fmi2DoStep's ``status`` above fmi2Warning: SimulationEnded for fmi2Discard with
        fmi2Terminated (the FMU ends the simulation), else the UnitError naming the status and the FMU's log."""
        if status == 2 and self._terminated():  # fmi2Discard + fmi2Terminated: the FMU ends the simulation
            end = self._guard("fmi2GetRealStatus", lambda: self._slave.getRealStatus(fmi2LastSuccessfulTime))
            raise SimulationEnded(self.name, float(end), "ended the simulation (fmi2DoStep: fmi2Discard, "
                                                         "fmi2Terminated)")
        if status > 1:
            raise self.fail_status("fmi2DoStep", status)

    def _terminated(self) -> bool:
        try:
            return bool(self._slave.getBooleanStatus(fmi2Terminated))
        except Exception:
            return False  # an FMU that cannot tell: the Discard is reported as a failure
