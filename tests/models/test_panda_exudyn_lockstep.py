"""PandaExudyn in lock-step (its twin PandaExudynBatch): K points in one Exudyn system give each point's results.

The K kinematic trees share one Newton iteration, so a row equals its single run
only to the Newton tolerance, not bit for bit: the bounds are those stated in
``tests/models/test_panda_exudyn_reference.py`` (objectives relative 1e-6 plus absolute
1e-8; limit flags exact).  Measured: within 3e-9 relative.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cosim import build_system, load_spec
from cosim.execution.lockstep import can_run_in_lockstep, instantiate, run_lockstep
from cosim.execution.point import assignments_for
from cosim.models.panda_exudyn import PandaExudyn, PandaExudynBatch
from cosim.units.python.batch import NotBatchable
from tests.helpers.paths import REPO

ROOT = REPO
FOLDER = ROOT / "examples" / "pick_and_place"
REFERENCE = json.loads((ROOT / "tests" / "data" / "panda_exudyn_reference.json").read_text())
RTOL, ATOL = 1e-6, 1e-8  # tests/models/test_panda_exudyn_reference.py
Q22, Q24 = "traj.waypoints[9]", "traj.waypoints[11]"


def _lockstep(spec: Path, points):
    system = build_system(load_spec(spec))
    assert can_run_in_lockstep(system)
    batches = instantiate(system, len(points))
    try:
        assert isinstance(batches["robot"], PandaExudynBatch)
        return run_lockstep(system, [assignments_for(system, {Q22: a, Q24: b}) for a, b in points], batches)
    finally:
        for batch in batches.values():
            batch.terminate()


def _assert_close(objectives: dict, expected: dict, where) -> None:
    assert objectives.keys() >= expected.keys()
    for name, value in expected.items():
        if name == "limit_violated":
            assert objectives[name] == value, where
        else:
            assert objectives[name] == pytest.approx(value, rel=RTOL, abs=ATOL), (where, name)


def test_lockstep_rows_match_the_reference_written_before_the_speed_work():
    """The five study points of the reference (different durations: rows end at different steps)."""
    points = [tuple(row["point"]) for row in REFERENCE["study"]]
    results = _lockstep(FOLDER / "spec_exudyn.json", points)
    assert len({r.steps for r in results}) > 1
    for result, row in zip(results, REFERENCE["study"]):
        assert result.ok, result.message
        _assert_close(result.objectives, row["objectives"], row["point"])


def test_the_committed_coarse_exudyn_table_re_runs_in_lockstep_within_the_tolerance():
    """results_coarse_exudyn.parquet (single runs, written before issue 16) against lock-step runs of some rows."""
    table = pd.read_parquet(FOLDER / "results_coarse_exudyn.parquet")
    rows = table.iloc[::25]
    points = [(float(r[Q22]), float(r[Q24])) for _, r in rows.iterrows()]
    results = _lockstep(FOLDER / "spec_coarse_exudyn.json", points)
    for (_, row), result in zip(rows.iterrows(), results):
        assert result.ok, result.message
        expected = {name: row[name] for name in result.objectives if name in row.index}
        assert len(expected) == len(result.objectives)
        _assert_close(result.objectives, expected, (row[Q22], row[Q24]))


def _twin(rows: int, **values) -> PandaExudynBatch:
    twin = PandaExudynBatch(PandaExudyn, "robot", rows)
    for name, value in values.items():
        getattr(twin, name)[:] = value
    twin.setup(0.0, None)
    return twin


@pytest.mark.parametrize("values", [
    {"ref_timing": "step_start"},  # the unit's default: the reference moves within the step
    {"ref_timing": "step_end", "ref_phase": 0.5},
    {"ref_timing": "step_end", "ref_phase": 1.0, "pendulum_bob_mass": 0.25},  # constraints
], ids=["step_start", "ref_phase", "pendulum"])
def test_other_configurations_are_not_batchable_and_run_one_by_one(values):
    twin = _twin(2, **values)
    with pytest.raises(NotBatchable):
        twin.exit_initialization()


def test_several_solver_steps_per_communication_step_are_not_batchable():
    twin = _twin(2, ref_timing="step_end", ref_phase=1.0, substep=1e-3)
    twin.exit_initialization()
    twin.do_step(0.0, 1e-3)  # one solver step: fine
    with pytest.raises(NotBatchable):
        twin.do_step(1e-3, 2e-3)
    twin.terminate()


def test_a_row_starts_on_its_reference_and_holds_still_at_rest():
    """Two rows at rest in different poses: each stays there (gravity is fed forward), outputs per row."""
    poses = np.array([[0.0, -0.3, 0.0, -2.0, 0.0, 1.7, 0.8], [0.5, 0.2, -0.3, -1.5, 0.4, 2.0, -0.5]])
    twin = _twin(2, ref_timing="step_end", ref_phase=1.0, substep=2e-3)
    twin.q_ref[:] = poses
    twin.exit_initialization()
    for k in range(50):
        twin.do_step(k * 2e-3, 2e-3)
    np.testing.assert_allclose(twin.q, poses, atol=1e-9)
    np.testing.assert_allclose(twin.qd, 0.0, atol=1e-8)
    assert np.all(twin.tracking_error < 1e-9)
    single = PandaExudyn("robot")
    single.set_values({"ref_timing": "step_end", "ref_phase": 1.0, "substep": 2e-3, "q_ref": poses[1]})
    single.setup(0.0, None)
    single.exit_initialization()
    np.testing.assert_allclose(twin.tau[1], single.tau, rtol=1e-9, atol=1e-9)  # the holding torque of that pose
    np.testing.assert_allclose(twin.ee_pos[1], single.ee_pos, atol=1e-12)
    twin.terminate()


def test_without_a_c_compiler_the_twin_refuses_and_the_points_run_one_by_one(tmp_path, monkeypatch):
    """The twin's per-step arithmetic is C compiled at first use (models/panda_rows.py); the single unit needs none."""
    from cosim.models import panda_rows

    monkeypatch.setattr(panda_rows, "_LIBRARY", [])  # as in a fresh process
    monkeypatch.setenv("COSIM_FMU_CACHE", str(tmp_path))  # nothing built yet
    monkeypatch.setenv("CC", str(tmp_path / "no-such-compiler"))
    twin = _twin(2, ref_timing="step_end", ref_phase=1.0, substep=2e-3)
    with pytest.raises(NotBatchable, match="Panda row kernels cannot be built: no C compiler"):
        twin.exit_initialization()
    twin.terminate()
