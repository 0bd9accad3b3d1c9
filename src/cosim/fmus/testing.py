"""Drive one of our FMUs by variable name through FMPy (for tests and quick checks).

:class:`FmuInstance` hides the one difference between our FMI 2.0 and FMI 3.0
builds that matters to a caller: an array ``tau`` is one variable in FMI 3.0
and the scalars ``tau[1]`` .. ``tau[n]`` in FMI 2.0.  Values are read and
written by name; arrays as numpy arrays.  Value references come from the
FMU's own modelDescription.xml, so a test through this class also checks it.

Every message the FMU logs lands in ``messages`` as ``(status, text)``.
FMI calls that fail raise ``fmpy.fmi1.FMICallException`` (FMPy's behaviour).
"""

from __future__ import annotations

import re
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
from fmpy.fmi3 import FMU3Slave

_ELEMENT = re.compile(r"^(.+)\[(\d+)\]$")


class FmuInstance:
    """One extracted FMU with one slave object; instantiate it with :meth:`instantiate`.

    ``unzip_parent`` is where the temporary extraction folder is made (the
    system's temporary folder by default); :meth:`close` removes it.
    """

    def __init__(self, path: str | Path, unzip_parent: str | Path | None = None, instance_name: str = "test"):
        self.path = Path(path)
        self.md = read_model_description(str(self.path))
        self.fmi_version = int(self.md.fmiVersion[0])
        self.unzipdir = tempfile.mkdtemp(prefix="cosim-fmu-", dir=unzip_parent)
        extract(str(self.path), unzipdir=self.unzipdir)
        cls = FMU3Slave if self.fmi_version == 3 else FMU2Slave
        self.slave = cls(guid=self.md.guid, unzipDirectory=self.unzipdir,
                         modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=instance_name)
        self.messages: list[tuple[int, str]] = []
        self.variables: dict[str, tuple[str, list[int], bool]] = {}  # name -> (type, vrs, is_array)
        self._index_variables()
        self._log_callbacks: Any = None
        self.instantiated = False

    def _index_variables(self) -> None:
        for v in self.md.modelVariables:
            type_ = {"Float64": "Real", "Int32": "Integer"}.get(v.type, v.type)
            m = _ELEMENT.match(v.name)
            if self.fmi_version == 2 and m:
                base = m.group(1)
                _, vrs, _ = self.variables.setdefault(base, (type_, [], True))
                assert int(m.group(2)) == len(vrs) + 1, f"{v.name}: elements out of order"
                vrs.append(v.valueReference)
            else:
                size = int(v.dimensions[0].start) if getattr(v, "dimensions", None) else 1
                self.variables[v.name] = (type_, [v.valueReference] * size, bool(getattr(v, "dimensions", None)))

    # lifecycle -----------------------------------------------------------------

    def _log(self, status: int, message: bytes | str) -> None:
        text = message.decode() if isinstance(message, bytes) else str(message)
        self.messages.append((int(status), text.replace("%%", "%")))

    def instantiate(self, logging_on: bool = False) -> None:
        """Create the FMU instance (the library stays loaded across free/instantiate)."""
        if self.fmi_version == 3:
            self.slave.instantiate(loggingOn=logging_on,
                                   logMessage=lambda env, status, category, message: self._log(status, message))
        else:
            callbacks = fmi2CallbackFunctions()
            callbacks.logger = fmi2CallbackLoggerTYPE(
                lambda env, name, status, category, message: self._log(status, message))
            self._log_callbacks = callbacks  # keep the ctypes callback alive
            self.slave.instantiate(callbacks=callbacks, loggingOn=logging_on)
        self.instantiated = True

    def initialize(self, start_time: float = 0.0, **parameters: Any) -> None:
        """Set ``parameters`` by name, enter and exit initialization mode."""
        if self.fmi_version == 2:
            self.slave.setupExperiment(startTime=start_time)
        for name, value in parameters.items():
            self.set(name, value)
        self.slave.enterInitializationMode(**({"startTime": start_time} if self.fmi_version == 3 else {}))
        self.slave.exitInitializationMode()

    def step(self, t: float, h: float) -> None:
        self.slave.doStep(currentCommunicationPoint=t, communicationStepSize=h)

    def reset(self) -> None:
        self.slave.reset()

    def free_instance(self) -> None:
        """Terminate and free the instance but keep the library loaded.

        FMPy's ``freeInstance()`` also unloads the shared library, after which
        the slave object must not be used again; calling the raw FMI function
        keeps the library for the next ``instantiate``.
        """
        if not self.instantiated:
            return
        self.slave.terminate()
        if self.fmi_version == 3:
            self.slave.fmi3FreeInstance(self.slave.component)
        else:
            self.slave.fmi2FreeInstance(self.slave.component)
        self.instantiated = False

    def close(self) -> None:
        """Free the instance, unload the library and delete the extraction folder."""
        try:
            if self.instantiated:
                self.slave.terminate()
                self.slave.freeInstance()  # also unloads the library
                self.instantiated = False
            else:
                self.slave.freeLibrary()
        finally:
            shutil.rmtree(self.unzipdir, ignore_errors=True)

    def __enter__(self) -> "FmuInstance":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # values --------------------------------------------------------------------

    def set(self, name: str, value: Any) -> None:
        """Set a variable by name; an array takes a sequence (or one value for all elements)."""
        type_, vrs, is_array = self.variables[name]
        values = list(np.broadcast_to(np.asarray(value), (len(vrs),)).tolist()) if is_array else [value]
        s = self.slave
        if type_ == "Real":
            (s.setFloat64([vrs[0]], values) if self.fmi_version == 3 else s.setReal(vrs, values))
        elif type_ == "Integer":
            (s.setInt32([vrs[0]], values) if self.fmi_version == 3 else s.setInteger(vrs, values))
        elif type_ == "Boolean":
            (s.setBoolean([vrs[0]], values) if self.fmi_version == 3 else s.setBoolean(vrs, values))
        else:
            raise TypeError(f"{name}: type {type_} not supported here")

    def get(self, name: str) -> Any:
        """A variable's value: a float/int/bool, or a numpy array for arrays."""
        type_, vrs, is_array = self.variables[name]
        s = self.slave
        if self.fmi_version == 3:
            getter = {"Real": s.getFloat64, "Integer": s.getInt32, "Boolean": s.getBoolean}[type_]
            values = getter([vrs[0]], nValues=len(vrs))
        else:
            getter = {"Real": s.getReal, "Integer": s.getInteger, "Boolean": s.getBoolean}[type_]
            values = getter(vrs)
        return np.array(values) if is_array else values[0]
