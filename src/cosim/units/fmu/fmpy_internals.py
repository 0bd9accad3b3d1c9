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

A fourth makes instances cheap to create: fmpy's slave object reads the ctypes
signature of each FMI function from its own Python methods' annotations
(``inspect.signature``, about 75 functions) at every instantiation, about
5 ms; a lock-step group of 32 points creates 32 instances of each FMU.  The
signatures depend only on the fmpy class, so :func:`with_cached_signatures`
reads them once per class and declares them on each new instance's library
(``_loadFunctions``, ``_functions``).

They are read only here.  ``tests/units/test_fmpy_internals.py`` checks them, on real
FMUs, against the fmpy version range pyproject.toml declares; a new fmpy that
moves them fails that test, not a user's run.
"""

from __future__ import annotations

from typing import Any

from fmpy.fmi2 import calloc as _calloc
from fmpy.fmi2 import free as _free

FMPY_REQUIREMENT = "fmpy>=0.3.32,<0.4"  # as in pyproject.toml (the test keeps the two equal)


_SIGNATURES: dict[type, list[tuple[str, str, list[str], list[Any], Any]]] = {}


def with_cached_signatures(slave_class: type[Any]) -> type[Any]:
    """``slave_class`` (an fmpy FMU2/FMU3 Slave or Model class) whose instances declare the FMI functions' ctypes
    signatures from a table made once per class, not by inspecting its methods again (module docstring).

    The functions, their names in the library and their signatures are exactly
    those fmpy's ``_loadFunctions`` sets; a function the library lacks raises
    AttributeError as it does there.
    """
    def _loadFunctions(self: Any) -> None:  # noqa: N802 (fmpy's name)
        table = _SIGNATURES.get(type(self))
        if table is None:
            slave_class._loadFunctions(self)
            _SIGNATURES[type(self)] = [(name, f.__name__, f.argnames, f.argtypes, f.restype)
                                       for name, f in self._functions.items()]
            return
        for name, c_name, argnames, argtypes, restype in table:
            c_fun = getattr(self.dll, c_name)
            c_fun.argnames, c_fun.argtypes, c_fun.restype = argnames, argtypes, restype
            self._functions[name] = c_fun

    # the same class name: fmpy picks the FMI version's function prefix from it
    return type(slave_class.__name__, (slave_class,), {"_loadFunctions": _loadFunctions,
                                                        "__module__": __name__})


def library(slave: Any) -> Any:
    """The instantiated FMU's shared library (``ctypes.CDLL``; fmpy has set the FMI functions' signatures)."""
    return slave.dll


def instance_handle(slave: Any) -> Any:
    """The FMI instance handle (``fmi2Component`` / ``fmi3Instance``) the library functions take first."""
    return slave.component


def fmi2_allocator() -> tuple[Any, Any]:
    """(calloc, free): the C functions fmpy passes to FMI 2.0 FMUs as allocateMemory / freeMemory."""
    return _calloc, _free
