"""Lifecycle of the motor_gear_energy FMU: long runs, reset, many instances, no leaks."""

from __future__ import annotations

import ctypes
import math
import os

import numpy as np
import psutil
import pytest
from fmpy.fmi3 import FMU3Slave

from cosim.fmus.build import ensure_built
from cosim.fmus.testing import FmuInstance

N = 7
H = 1e-3


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in
                ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")]


def heap_in_use() -> int | None:
    """Bytes malloc has handed out and not got back (glibc), None elsewhere.

    Resident memory alone misses small leaks that fill pages the heap already
    holds; glibc's own count does not.
    """
    try:
        mallinfo2 = ctypes.CDLL(None).mallinfo2
    except (OSError, AttributeError):
        return None
    mallinfo2.restype = _MallInfo2
    info = mallinfo2()
    return info.uordblks + info.hblkhd


def run(inst: FmuInstance, steps: int) -> tuple[float, float, np.ndarray]:
    """Drive the joints along sines (motoring and braking) and return the energies."""
    t = 0.0
    phase = np.arange(N)
    for k in range(steps):
        inst.set("tau", 30.0 * np.sin(2.0 * t + phase))
        inst.set("omega", 1.2 * np.cos(3.0 * t + phase))
        inst.step(t, H)
        t = (k + 1) * H
    return inst.get("e_total"), inst.get("e_total_no_recuperation"), inst.get("e_el")


@pytest.mark.parametrize("version", [2, 3])
def test_ten_thousand_steps_reset_and_run_again(version, tmp_path):
    with FmuInstance(ensure_built("motor_gear_energy", version), unzip_parent=tmp_path) as inst:
        inst.instantiate()
        inst.initialize()
        first = run(inst, 10_000)
        assert first[0] > 0 and first[0] < first[1]  # some energy recuperated
        inst.reset()
        assert inst.get("gear_ratio").tolist() == [100.0] * N  # start values are back
        inst.initialize()
        assert inst.get("e_total") == 0.0
        second = run(inst, 10_000)
        assert second[0] == first[0] and second[1] == first[1]
        assert np.array_equal(second[2], first[2])
        # Reset also restores parameters changed before the first run.
        inst.reset()
        inst.initialize(gear_ratio=50.0)
        inst.reset()
        inst.initialize()
        assert inst.get("gear_ratio").tolist() == [100.0] * N
    assert list(tmp_path.iterdir()) == []  # the extraction folder is gone


@pytest.mark.parametrize("version", [2, 3])
def test_thousand_instances_in_one_process(version, tmp_path):
    """One slave object, 1000 instantiate/terminate/freeInstance cycles: flat memory, nothing left behind."""
    process = psutil.Process(os.getpid())
    with FmuInstance(ensure_built("motor_gear_energy", version), unzip_parent=tmp_path) as inst:
        rss, heap = [], []
        for k in range(1000):
            inst.instantiate()
            inst.initialize(r_terminal=0.2 + k * 1e-4)
            inst.set("tau", np.full(N, 10.0))
            inst.set("omega", np.full(N, 0.5))
            inst.step(0.0, H)
            assert inst.get("e_total") > 0
            inst.free_instance()  # keeps the library loaded (FMPy's freeInstance would unload it)
            if k in (199, 999):
                rss.append(process.memory_info().rss)
                heap.append(heap_in_use())
        # A leaked instance (about 1 kB) per cycle would add ~800 kB over 800 cycles.
        assert rss[1] - rss[0] < 256 * 1024, f"resident memory grew by {(rss[1] - rss[0]) / 1024:.0f} kB"
        if heap[0] is not None:
            assert heap[1] - heap[0] < 64 * 1024, f"heap in use grew by {(heap[1] - heap[0]) / 1024:.0f} kB"
    assert list(tmp_path.iterdir()) == []


def test_instances_share_the_library_but_not_state(tmp_path):
    """canBeInstantiatedOnlyOncePerProcess=false: two live instances of one loaded library."""
    with FmuInstance(ensure_built("motor_gear_energy", 3), unzip_parent=tmp_path) as a:
        b_slave = FMU3Slave(guid=a.md.guid, unzipDirectory=a.unzipdir, modelIdentifier="motor_gear_energy",
                            instanceName="b")
        a.instantiate()
        b_slave.instantiate()
        a.initialize()
        b_slave.enterInitializationMode()
        vr = {name: vrs[0] for name, (_, vrs, _) in a.variables.items()}
        b_slave.setFloat64([vr["eta_motor"]], [0.5] * N)  # another motor in b
        b_slave.exitInitializationMode()
        a.set("tau", np.full(N, 10.0))
        a.set("omega", np.full(N, 0.1))
        b_slave.setFloat64([vr["tau"], vr["omega"]], [10.0] * N + [0.1] * N)
        p_a = a.get("p_el")
        p_b = np.array(b_slave.getFloat64([vr["p_el"]], nValues=N))
        assert np.all(p_b > p_a)  # the less efficient motor draws more
        assert a.get("eta_motor").tolist() == [0.92] * N
        b_slave.terminate()
        b_slave.fmi3FreeInstance(b_slave.component)  # leave the shared library loaded for a
        a.step(0.0, H)
        assert a.get("e_total") == pytest.approx(a.get("p_total") * H, rel=1e-12)
        assert math.isfinite(a.get("e_total"))
