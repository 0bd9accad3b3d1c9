"""Both steppers on one run: every run the native kernel takes in the test modules listed in TWIN_MODULES is run
again on the Python master, and the two must agree bit for bit (conftest's autouse fixture wraps
``Execution.run``).  So each qualifying test of the algorithms, transfers, recording and objectives checks the
kernel against the Python master with its own system, without being written twice."""

from __future__ import annotations

import copy
from dataclasses import replace
from typing import Any

import numpy as np

from cosim.system.kernel_choice import KernelChoice

# the modules whose runs are twinned (tests/master/test_native_kernel.py compares its own runs explicitly)
TWIN_MODULES = {"test_algorithms", "test_coupled_fmus", "test_record_events", "test_units_of_measure",
                "test_player_and_cli", "test_ssp_libcosim", "test_instance_reuse", "test_algebraic_loops",
                "test_fmi_conformance", "test_record_replay", "test_stop_races", "test_ssp_import"}

compared: list[str] = []  # the tests whose runs were twinned (a test can see that its run was)


def assert_identical(native: Any, python: Any) -> None:
    """Status, message, steps, end time, objectives (their bits, NaN included) and traces (values and dtypes)
    of two run results are equal."""
    assert (native.status, native.message, native.steps, native.end_time) == \
        (python.status, python.message, python.steps, python.end_time)
    assert list(native.objectives) == list(python.objectives)
    for name, value in native.objectives.items():
        assert np.float64(value).tobytes() == np.float64(python.objectives[name]).tobytes(), name
    if python.traces is None:
        assert native.traces is None
    else:
        assert native.traces.equals(python.traces)
        assert list(native.traces.dtypes) == list(python.traces.dtypes)


def twinned_run(original: Any, test_name: str) -> Any:
    """``Execution.run`` that runs a native run once more on the Python master and compares the two.  Runs given
    live units (the caller owns and resets them), extra observers (they may keep state) or an algorithm are not
    repeated: a second run would not start where the first did."""
    def run(self: Any) -> Any:
        result = original(self)
        if (self.system.kernel.kernel != "native" or self._given_units is not None or self.extra_observers
                or self.algorithm is not None or self.save_warm):
            return result
        twin = copy.copy(self)
        twin.system = replace(self.system, kernel=KernelChoice("python", "the twin run of a test"))
        assert_identical(result, original(twin))
        compared.append(test_name)
        return result
    return run
