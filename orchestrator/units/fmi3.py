"""FMI 3.0 co-simulation instances (through fmpy's FMU3Slave), arrays included."""

from __future__ import annotations

import ctypes
from functools import partial
from typing import Any, Callable

from fmpy.fmi3 import FMU3Slave

from .fmi_instance import FmiInstance, _TypeGroup


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
    }
    _vr_type = ctypes.c_uint
    _prefix = "fmi3"

    def __init__(self, name: str, unit_type: Any):
        super().__init__(name, unit_type)
        md = unit_type.model_description()
        self._slave = FMU3Slave(guid=md.guid, unzipDirectory=unit_type.extracted_folder(),
                                modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        self._guard("fmi3InstantiateCoSimulation", lambda: self._slave.instantiate(logMessage=self._log_callback_py))
        self._component = self._slave.component
        self._alive = True
        # Direct library calls in the stepping loop (see Fmi2Unit for why).
        dll = self._slave.dll
        self._calls = {t: (getattr(dll, f"fmi3Get{t if t != 'Enumeration' else 'Int64'}"),
                           getattr(dll, f"fmi3Set{t if t != 'Enumeration' else 'Int64'}"))
                       for t in self._c_types}
        self._do_step = dll.fmi3DoStep
        self._event = ctypes.c_bool()
        self._terminate = ctypes.c_bool()
        self._early = ctypes.c_bool()
        self._last_time = ctypes.c_double()
        self._event_ref, self._terminate_ref = ctypes.byref(self._event), ctypes.byref(self._terminate)
        self._early_ref, self._last_time_ref = ctypes.byref(self._early), ctypes.byref(self._last_time)

    def _log_callback_py(self, env: Any, status: int, category: bytes, message: bytes) -> None:
        self._record_log(status, category, message)

    def _bind(self, group: _TypeGroup) -> tuple[Callable[[], int], Callable[[], int]]:
        get, put = self._calls[group.fmi_type]
        args = (self._component, group.vrs, group.n_vrs, group.values, group.n_values)
        return partial(get, *args), partial(put, *args)

    def setup(self, start_time: float, stop_time: float | None) -> None:
        self.time = start_time
        self._start_time = start_time
        self._stop_time = stop_time

    def enter_initialization(self) -> None:
        self._guard(f"{self._prefix}EnterInitializationMode",
                    lambda: self._slave.enterInitializationMode(startTime=self._start_time, stopTime=self._stop_time))

    def exit_initialization(self) -> None:
        self._guard(f"{self._prefix}ExitInitializationMode", self._slave.exitInitializationMode)

    def do_step(self, t: float, h: float) -> None:
        self.time = t
        status = self._do_step(self._component, t, h, True, self._event_ref, self._terminate_ref,
                               self._early_ref, self._last_time_ref)
        if status > 1:
            raise self.fail_status("fmi3DoStep", status)
