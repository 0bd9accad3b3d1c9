"""The few fmpy internals cosim uses, in one place.

fmpy's public wrappers (``FMU2Slave.getReal`` ...) check arguments and build
ctypes arrays on every call, which costs more than a small FMU's own step.
So the stepping loop calls the FMU's library functions directly, with the
signatures fmpy has already declared on them, and checks the status itself
(see :mod:`.fmi2`, :mod:`.fmi3`).  That needs three things fmpy does not
document:

- ``slave.dll``: the FMU's shared library (a ``ctypes.CDLL``) after ``instantiate()``;
- ``slave.component``: the instance handle the FMI functions take first;
- ``fmpy.fmi2.calloc`` / ``fmpy.fmi2.free``: the C allocator fmpy hands to FMI 2.0 FMUs.

They are read only here.  ``tests/test_fmpy_internals.py`` checks them, on real
FMUs, against the fmpy version range pyproject.toml declares; a new fmpy that
moves them fails that test, not a user's run.
"""

from __future__ import annotations

from typing import Any

from fmpy.fmi2 import calloc as _calloc
from fmpy.fmi2 import free as _free

FMPY_REQUIREMENT = "fmpy>=0.3.32,<0.4"  # as in pyproject.toml (the test keeps the two equal)


def library(slave: Any) -> Any:
    """The instantiated FMU's shared library (``ctypes.CDLL``; fmpy has set the FMI functions' signatures)."""
    return slave.dll


def instance_handle(slave: Any) -> Any:
    """The FMI instance handle (``fmi2Component`` / ``fmi3Instance``) the library functions take first."""
    return slave.component


def fmi2_allocator() -> tuple[Any, Any]:
    """(calloc, free): the C functions fmpy passes to FMI 2.0 FMUs as allocateMemory / freeMemory."""
    return _calloc, _free
