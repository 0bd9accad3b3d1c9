"""cosim's inverse-dynamics pick-and-place point agrees with the hand-written vectorised evaluation.

``benchmarks/pick_and_place_reference.py`` computes a point of
``examples/pick_and_place/spec.json`` without co-simulation (numpy over the
time grid, pinocchio per sample, the energy model in numpy): it is the
yardstick of issue 16's speed target, so it must compute the same thing.
Every objective of the spec is compared, for points at the grid's corners, the
thesis's cells and one inside, to 1e-9 relative (they agree to ~1e-13: the two
differ only in the order of floating-point operations).
"""

from __future__ import annotations

import importlib.util
import math

import pytest

from cosim import build_system, load_spec
from cosim.execution.point import run_point
from tests.helpers.paths import REPO

ROOT = REPO
RELATIVE_TOLERANCE = 1e-9


def _reference():
    spec = importlib.util.spec_from_file_location("pick_and_place_reference",
                                                  ROOT / "benchmarks" / "pick_and_place_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("q22, q24", [(-100.0, 140.0), (20.0, 0.0), (0.0, 0.0), (-74.0, 85.0), (-45.0, 70.0)])
def test_reference_evaluation_agrees_with_cosim(q22, q24):
    system = build_system(load_spec(ROOT / "examples" / "pick_and_place" / "spec.json"))
    result = run_point(system, {"traj.waypoints[9]": q22, "traj.waypoints[11]": q24})
    assert result.ok, result.message
    expected = _reference().evaluate_point(q22, q24)
    assert set(expected) == set(result.objectives)  # the same outputs, every objective of the spec
    for name, value in expected.items():
        assert math.isclose(result.objectives[name], value, rel_tol=RELATIVE_TOLERANCE, abs_tol=1e-12), name
    assert expected["e_total"] > 10.0 and expected["cartesian_distance"] > 0.5  # a real motion, not zeros
