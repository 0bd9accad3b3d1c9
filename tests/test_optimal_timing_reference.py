"""The energy-optimal timing planner returns the timings it returned before its speed work.

tests/data/optimal_timing_reference.json holds the planner's outputs (duration, grid energy, the timing
b = s_dot^2 on its grid) for 6 pick-and-place designs x 4 modes, written by
tests/data/make_optimal_timing_reference.py at the revision named in the file, before the passes were
cut short (session 2).  Stated tolerance: duration and energy to 1e-6 relative, b to 1e-5 absolute (b is
about 0.2 .. 1); IPOPT's own tolerance is 1e-8.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from .data.make_optimal_timing_reference import MODES, plan

REFERENCE = json.loads((Path(__file__).parent / "data" / "optimal_timing_reference.json").read_text())


@pytest.mark.parametrize("row", REFERENCE["rows"], ids=lambda r: f"{r['design']}-{r['mode']}")
def test_planner_returns_the_reference_timing(row):
    assert row["mode"] in MODES
    blend, timing = plan(tuple(row["design"]), row["mode"])
    assert blend.duration == pytest.approx(row["blend_duration"], rel=1e-12)
    assert timing.s == pytest.approx(np.array(row["s"]), abs=1e-12)
    assert timing.duration == pytest.approx(row["duration"], rel=1e-6)
    assert timing.planned_energy == pytest.approx(row["planned_energy"], rel=1e-6)
    assert np.max(np.abs(timing.b - np.array(row["b"]))) <= 1e-5
