"""The fmpy internals behind src/cosim/units/fmu/fmpy_internals.py still mean what cosim assumes.

Checked on real FMUs (built from fmus/linear_ode) with fmpy's own slave classes: the direct library calls
give what fmpy's public wrappers give, within the fmpy version range pyproject.toml declares.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import re
import shutil
import tempfile
import zipfile
from importlib import metadata

import pytest
from packaging.requirements import Requirement

from cosim.units.fmu import fmpy_internals
from tests.helpers.paths import REPO

ROOT = REPO


def declared_fmpy() -> Requirement:
    text = (ROOT / "pyproject.toml").read_text()
    return Requirement(re.search(r'"(fmpy[^"]*)"', text).group(1))


def test_the_installed_fmpy_is_in_the_declared_range():
    declared = declared_fmpy()
    assert declared == Requirement(fmpy_internals.FMPY_REQUIREMENT)
    assert declared.specifier.contains(metadata.version("fmpy"))


@pytest.fixture
def unzipped(built_fmu):
    folders = []

    def unzip(version: int) -> tuple[object, str]:
        from fmpy import read_model_description

        path = built_fmu("linear_ode", version)
        folder = tempfile.mkdtemp(prefix="cosim_fmpy_")
        folders.append(folder)
        with zipfile.ZipFile(path) as zf:
            zf.extractall(folder)
        return read_model_description(str(path)), folder

    yield unzip
    for folder in folders:
        shutil.rmtree(folder, ignore_errors=True)


@contextlib.contextmanager
def instantiated(slave_class, md, folder):
    """An instantiated fmpy slave of the unzipped FMU, freed afterwards."""
    slave = slave_class(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName="probe")
    slave.instantiate()
    try:
        yield slave
    finally:
        slave.freeInstance()


def test_fmi2_library_handle_and_allocator(unzipped):
    from fmpy.fmi2 import FMU2Slave

    md, folder = unzipped(2)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    with instantiated(FMU2Slave, md, folder) as slave:
        lib, handle = fmpy_internals.library(slave), fmpy_internals.instance_handle(slave)
        assert isinstance(lib, ctypes.CDLL) and handle
        assert lib.fmi2GetReal.restype is not None and lib.fmi2DoStep.argtypes  # signatures set by fmpy
        slave.setupExperiment(startTime=0.0)
        slave.setReal([vr["a"], vr["x0"]], [-2.0, 3.0])
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        assert lib.fmi2DoStep(handle, 0.0, 0.5, 1) == 0
        values = (ctypes.c_double * 1)()
        assert lib.fmi2GetReal(handle, (ctypes.c_uint * 1)(vr["y"]), 1, values) == 0
        assert values[0] == slave.getReal([vr["y"]])[0] == pytest.approx(3.0 * math.exp(-1.0), rel=1e-12)
        slave.terminate()
    calloc, free = fmpy_internals.fmi2_allocator()
    pointer = calloc(4, 8)
    assert pointer and all(b == 0 for b in ctypes.string_at(pointer, 32))  # calloc: zeroed memory
    free(pointer)


def test_fmi3_library_and_handle(unzipped):
    from fmpy.fmi3 import FMU3Slave

    md, folder = unzipped(3)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    with instantiated(FMU3Slave, md, folder) as slave:
        lib, handle = fmpy_internals.library(slave), fmpy_internals.instance_handle(slave)
        assert isinstance(lib, ctypes.CDLL) and handle and lib.fmi3GetFloat64.argtypes
        slave.setFloat64([vr["a"], vr["x0"]], [-2.0, 3.0])
        slave.enterInitializationMode(startTime=0.0)
        slave.exitInitializationMode()
        flags = [ctypes.c_bool() for _ in range(3)]
        last = ctypes.c_double()
        assert lib.fmi3DoStep(handle, 0.0, 0.5, True, *map(ctypes.byref, flags), ctypes.byref(last)) == 0
        values = (ctypes.c_double * 1)()
        assert lib.fmi3GetFloat64(handle, (ctypes.c_uint * 1)(vr["y"]), 1, values, 1) == 0
        assert values[0] == slave.getFloat64([vr["y"]])[0] == pytest.approx(3.0 * math.exp(-1.0), rel=1e-12)
        slave.terminate()


@pytest.mark.parametrize("version, fmpy_class", [(2, "fmpy.fmi2:FMU2Slave"), (3, "fmpy.fmi3:FMU3Slave"),
                                                 (2, "fmpy.fmi2:FMU2Model"), (3, "fmpy.fmi3:FMU3Model")])
def test_cached_signatures_are_the_ones_fmpy_declares_and_survive_the_library_being_unloaded(unzipped, version,
                                                                                           fmpy_class):
    import importlib

    module, name = fmpy_class.split(":")
    original = getattr(importlib.import_module(module), name)
    cached = fmpy_internals.with_cached_signatures(original)
    assert cached.__name__ == original.__name__  # fmpy picks the function prefix from the class name
    md, folder = unzipped(version)

    def declared(slave) -> dict:
        return {n: (f.__name__, f.argnames, f.argtypes, f.restype) for n, f in slave._functions.items()}

    def make(cls):
        return cls(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                   instanceName="probe")

    fmpy_slave = make(original)
    want = declared(fmpy_slave)
    assert len(want) > 30
    fmpy_slave.freeLibrary()
    for _ in range(3):  # the first builds the table, the next use it; each frees the library (unloaded between)
        slave = make(cached)
        assert declared(slave) == want
        for fname, (c_name, _, argtypes, restype) in want.items():
            function = getattr(slave.dll, c_name)  # declared on this instance's library, not an older one's
            assert function.argtypes == argtypes and function.restype == restype
        slave.freeLibrary()
