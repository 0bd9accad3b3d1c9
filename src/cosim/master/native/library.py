"""kernel.c compiled with gcc on first use into the FMU cache, and loaded with ctypes.

ctypes, not cffi: the kernel is one function over plain structs, and the FMI function pointers and instance
handles come from FMPy's ctypes objects already; cffi would add a dependency and a second FFI for no gain.
The library is compiled with ``-ffp-contract=off`` so ``factor * x + offset`` is rounded twice, as numpy does:
the kernel's values are the Python master's bit for bit.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import subprocess
import tempfile
from functools import lru_cache
from pathlib import Path
from typing import Callable

from cosim.errors import KernelUnavailable

SOURCE = Path(__file__).resolve().parent / "kernel.c"
CFLAGS = ("-shared", "-fPIC", "-O2", "-std=c99", "-ffp-contract=off", "-Wall", "-Wextra")
LIBRARY = "libcosim_kernel.so"


def _digest() -> str:
    h = hashlib.sha256(SOURCE.read_bytes())
    h.update(repr((CFLAGS, os.environ.get("CC", "gcc"))).encode())
    return h.hexdigest()


def library_path() -> Path:
    """Path of the compiled kernel, built on first use; safe when several processes build at once (each
    compiles into a temporary file renamed into place).  Raises KernelUnavailable."""
    from cosim.errors import FmuBuildError
    from cosim.fmus.build import c_compiler, cache_dir

    target = cache_dir() / f"native-kernel-{_digest()[:20]}" / LIBRARY
    if target.is_file():
        return target
    try:
        cc = c_compiler()
    except FmuBuildError as exc:
        raise KernelUnavailable(str(exc)) from None
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="build-kernel-", dir=target.parent) as tmp:
        partial = Path(tmp) / LIBRARY
        command = [cc, *CFLAGS, str(SOURCE), "-o", str(partial), "-lm"]
        result = subprocess.run(command, capture_output=True, text=True)
        if result.returncode != 0:
            raise KernelUnavailable(f"compiling the native kernel failed:\n{' '.join(command)}\n"
                                    f"{result.stderr.strip()}")
        os.replace(partial, target)
    return target


class KUnit(ctypes.Structure):
    _fields_ = [("version", ctypes.c_int), ("component", ctypes.c_void_p), ("do_step", ctypes.c_void_p),
                ("get", ctypes.c_void_p * 3), ("set", ctypes.c_void_p * 3),
                ("event", ctypes.c_void_p), ("terminate", ctypes.c_void_p), ("early", ctypes.c_void_p),
                ("last_time", ctypes.c_void_p),
                ("n_samples", ctypes.c_int), ("n_columns", ctypes.c_int), ("mode", ctypes.c_int),
                ("times", ctypes.c_void_p), ("values", ctypes.c_void_p), ("discrete", ctypes.c_void_p),
                ("current", ctypes.c_void_p), ("time", ctypes.c_void_p)]


PLAYER, STORE = 0, 1  # KUnit.version of a table player and of a store (system connectors); 2, 3: FMI
MODES = {"linear": 0, "hold": 1, "nearest": 2}


class KPort(ctypes.Structure):
    _fields_ = [("unit", ctypes.c_int), ("type", ctypes.c_int), ("n", ctypes.c_int),
                ("vrs", ctypes.POINTER(ctypes.c_uint)), ("n_vrs", ctypes.c_int), ("n_values", ctypes.c_int),
                ("pos", ctypes.POINTER(ctypes.c_int)), ("partial", ctypes.c_int)]


class KTransfer(ctypes.Structure):
    _fields_ = [("source", KPort), ("target", KPort), ("convert", ctypes.c_int),
                ("factor", ctypes.POINTER(ctypes.c_double)), ("offset", ctypes.POINTER(ctypes.c_double))]


class KProbe(ctypes.Structure):
    _fields_ = [("port", KPort), ("columns", ctypes.POINTER(ctypes.c_int))]


class Kernel(ctypes.Structure):
    _fields_ = [("n_units", ctypes.c_int), ("units", ctypes.POINTER(KUnit)), ("jacobi", ctypes.c_int),
                ("n_transfers", ctypes.c_int), ("transfers", ctypes.POINTER(KTransfer)),
                ("plan_start", ctypes.POINTER(ctypes.c_int)), ("plan", ctypes.POINTER(ctypes.c_int)),
                ("n_probes", ctypes.c_int), ("probes", ctypes.POINTER(KProbe)), ("n_columns", ctypes.c_int),
                ("stop_column", ctypes.c_int), ("start", ctypes.c_double), ("stop", ctypes.c_double),
                ("step", ctypes.c_double), ("grid_steps", ctypes.c_long)]


class KFail(ctypes.Structure):
    _fields_ = [("unit", ctypes.c_int), ("call", ctypes.c_int), ("type", ctypes.c_int), ("status", ctypes.c_int),
                ("t", ctypes.c_double), ("h", ctypes.c_double)]


RUN_DONE, RUN_STOPPED, RUN_FAILED, RUN_ENDED = 0, 1, 2, 3
CALL_DOSTEP, CALL_GET, CALL_SET = 0, 1, 2  # KFail.call


@lru_cache(maxsize=1)
def run_function() -> Callable[..., int]:  # restype c_int: ctypes gives a Python int
    """``cosim_kernel_run`` with its ctypes signature (the library built first if needed)."""
    lib = ctypes.CDLL(str(library_path()))
    run = lib.cosim_kernel_run
    run.argtypes = [ctypes.POINTER(Kernel), ctypes.c_double, ctypes.c_double, ctypes.c_long, ctypes.c_void_p,
                    ctypes.c_void_p, ctypes.POINTER(ctypes.c_long), ctypes.POINTER(ctypes.c_double),
                    ctypes.POINTER(KFail)]
    run.restype = ctypes.c_int
    return run


@lru_cache(maxsize=1)
def reduce_function() -> Callable[..., int]:
    """``cosim_reduce_all`` (kernel.c: the objective reducers over recorded rows) with its ctypes signature."""
    lib = ctypes.CDLL(str(library_path()))
    reduce = lib.cosim_reduce_all
    reduce.argtypes = [ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_long,
                       ctypes.c_int, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
    reduce.restype = ctypes.c_int
    return reduce


def available() -> str | None:
    """None when the kernel can be built and loaded here, else why not."""
    try:
        run_function()
    except (KernelUnavailable, OSError) as exc:
        return str(exc)
    return None
