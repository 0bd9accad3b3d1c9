"""Lock-step runs (cosim.execution.lockstep): K points through one stepping loop give the single runs' results.

The pick-and-place system has vectorised twins for its trajectory and robot
units and K instances of its energy FMU; every objective, the step count and
the end time of each point must equal those of the point run alone, bit for
bit, under both master algorithms; anything going wrong in a group must give
exactly the rows of single runs.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cosim import build_system, load_spec
from cosim.execution.lockstep import LockstepRunner, can_run_in_lockstep, instantiate, run_lockstep
from cosim.execution.point import assignments_for, run_point
from cosim.master.registry import ALGORITHMS
from cosim.parallel.isolation.point_runner import PointRunner
from cosim.units.python.batch import NotBatchable
from tests.helpers.paths import REPO

FOLDER = REPO / "examples" / "pick_and_place"
Q22, Q24 = "traj.waypoints[9]", "traj.waypoints[11]"
# corners (the longest and shortest runs), the thesis's cells and points inside: runs of 159 to 246 steps
POINTS = [(-100.0, 140.0), (20.0, 0.0), (0.0, 0.0), (-100.0, 0.0), (20.0, 140.0), (-74.0, 85.0), (1.0, 76.0),
          (-45.0, 70.0), (-60.0, 35.0)]


def _values(q22: float, q24: float) -> dict:
    return {Q22: q22, Q24: q24}


def _single(system, points):
    units = {name: su.unit_type.instantiate(name) for name, su in system.units.items()}
    try:
        results = []
        for point in points:
            results.append(run_point(system, _values(*point), units=units))
            for unit in units.values():
                unit.reset()
        return results
    finally:
        for unit in units.values():
            unit.terminate()


def _spec_with(tmp_path: Path, **experiment) -> Path:
    """spec.json with these experiment settings; a setting given as None is removed."""
    raw = json.loads((FOLDER / "spec.json").read_text())
    raw["experiment"].update(experiment)
    raw["experiment"] = {k: v for k, v in raw["experiment"].items() if v is not None}
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(raw))
    return path


@pytest.mark.parametrize("experiment", [{"algorithm": "gauss-seidel"}, {"algorithm": "jacobi"},
                                        {"algorithm": "jacobi-delayed"},
                                        {"stop": 1.2, "stop_when": None}],  # every point cut at the stop time
                         ids=["gauss-seidel", "jacobi", "jacobi-delayed", "no-stop-when"])
def test_lockstep_gives_every_point_the_results_of_its_single_run_bit_for_bit(tmp_path, experiment):
    """Also the energy FMU's outputs, which lock-step reads only at a point's last sample (final reductions).

    Exact (``==``), on any IEEE-754 machine: both sides do the same correctly rounded operations in the same
    order -- the same compiled FMU and pinocchio RNEA per row, numpy element-wise ufuncs, and the TCP path's
    chords as three squares added left to right (no BLAS: ``ndarray.dot`` picks an OpenBLAS kernel per CPU and
    was one ulp off on AVX-512 kernels, issue 28). Nothing here is compared to an ulp; the committed table below
    is (it predates a change of the chord sum's order), and the Exudyn twin to a tolerance (one Newton iteration
    for all arms, tests/models/test_panda_exudyn_lockstep.py).
    """
    system = build_system(load_spec(_spec_with(tmp_path, **experiment)))
    assert can_run_in_lockstep(system)
    batches = instantiate(system, len(POINTS))
    try:
        grouped = run_lockstep(system, [assignments_for(system, _values(*p)) for p in POINTS], batches)
    finally:
        for batch in batches.values():
            batch.terminate()
    alone = _single(system, POINTS)
    assert len({r.steps for r in alone}) > (3 if "stop_when" not in experiment else 0)  # ends at different steps
    for point, a, g in zip(POINTS, alone, grouped):
        assert g.ok and a.ok, (point, a.message, g.message)
        assert (g.steps, g.end_time) == (a.steps, a.end_time), point
        assert g.objectives == a.objectives, point  # every objective, exactly


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi", "jacobi-delayed"])
def test_a_group_steps_through_the_master_algorithm_object_a_single_run_uses(tmp_path, monkeypatch, algorithm):
    """No master algorithm of lock-step's own: the spec's class from cosim.master.registry, bound to the
    batches, steps the group once per communication point until its last point ends."""
    system = build_system(load_spec(_spec_with(tmp_path, algorithm=algorithm)))
    cls, calls = ALGORITHMS[algorithm], []
    step = cls.step
    monkeypatch.setattr(cls, "step", lambda self, t, h: (calls.append((type(self), t, h)), step(self, t, h))[1])
    batches = instantiate(system, 4)
    try:
        results = run_lockstep(system, [assignments_for(system, _values(*p)) for p in POINTS[:4]], batches)
    finally:
        for batch in batches.values():
            batch.terminate()
    exp = system.spec.experiment
    assert all(r.ok for r in results)
    assert len(calls) == max(r.steps for r in results) > min(r.steps for r in results)  # the longest point's
    assert {c[0] for c in calls} == {cls}
    assert [t for _, t, _ in calls] == [exp.start + k * exp.step for k in range(len(calls))]
    assert all(h == pytest.approx(exp.step, rel=1e-9) for _, _, h in calls)


def test_points_of_a_master_algorithm_that_cannot_step_batches_run_one_by_one(monkeypatch):
    """An algorithm that is not ``batchable`` (e.g. one that needs live units) never runs a lock-step group."""
    system = build_system(load_spec(FOLDER / "spec.json"))
    monkeypatch.setattr(ALGORITHMS[system.spec.experiment.algorithm], "batchable", False)
    assert not can_run_in_lockstep(system)
    batches = instantiate(system, 2)
    try:
        with pytest.raises(NotBatchable, match="gauss-seidel"):
            run_lockstep(system, [assignments_for(system, _values(*p)) for p in POINTS[:2]], batches)
    finally:
        for batch in batches.values():
            batch.terminate()
    points = [(f"p{i}", _values(*p)) for i, p in enumerate(POINTS[:4])]
    runner = LockstepRunner(PointRunner(system))
    rows = list(runner.rows(points))
    runner.close()
    assert runner.group_size == 1
    assert [r.objectives for r in rows] == [a.objectives for a in _single(system, POINTS[:4])]


def test_the_committed_coarse_table_re_runs_in_lockstep_within_one_ulp():
    """results_coarse.parquet (written before lock-step existed) against lock-step runs of a sample of its rows.

    Equal to 1e-12 relative: today's single runs differ from that table only in the last bit of
    cartesian_distance for a few points (a change in the order of its chord sum predates lock-step).
    """
    table = pd.read_parquet(FOLDER / "results_coarse.parquet")
    rows = table.iloc[::23]
    system = build_system(load_spec(FOLDER / "spec_coarse.json"))
    points = [(float(r[Q22]), float(r[Q24])) for _, r in rows.iterrows()]
    batches = instantiate(system, len(points))
    try:
        results = run_lockstep(system, [assignments_for(system, _values(*p)) for p in points], batches)
    finally:
        for batch in batches.values():
            batch.terminate()
    for (_, row), result in zip(rows.iterrows(), results):
        assert result.ok
        for name, value in result.objectives.items():
            assert np.isclose(value, row[name], rtol=1e-12, atol=0.0), (name, value, row[name])


def test_a_group_with_a_failing_point_gives_the_rows_of_single_runs():
    system = build_system(load_spec(FOLDER / "spec.json"))
    # k_m = 0 is inside the declared range [0, inf) but the FMU refuses it when initialization ends
    points = [(f"p{i}", {**_values(*p), "energy.k_m[2]": 0.0 if i == 3 else 0.134})
              for i, p in enumerate(POINTS[:6])]
    grouped = LockstepRunner(PointRunner(system))
    grouped.group_size = 6  # one group of all six points, no timing runs
    rows = list(grouped.rows(points))
    alone = [PointRunner(system).run(pid, values) for pid, values in points]
    grouped.close()
    assert [r.point_id for r in rows] == [pid for pid, _ in points]
    assert [r.status for r in rows] == ["ok", "ok", "ok", "failed", "ok", "ok"]
    for g, a in zip(rows, alone):
        assert (g.status, g.message, g.objectives) == (a.status, a.message, a.objectives)
    assert "k_m[2]" in rows[3].message


def test_rows_that_disagree_on_the_trajectory_sampling_run_one_by_one(tmp_path):
    system = build_system(load_spec(FOLDER / "spec.json"))
    points = [(f"p{i}", {**_values(*p), "traj.sampling": s})
              for i, (p, s) in enumerate(zip(POINTS[:4], ["step_midpoint", "instant"] * 2))]
    grouped = LockstepRunner(PointRunner(system))
    grouped.group_size = 4
    rows = list(grouped.rows(points))
    grouped.close()
    alone = [PointRunner(system).run(pid, values) for pid, values in points]
    assert [r.status for r in rows] == ["ok"] * 4
    assert [r.objectives for r in rows] == [a.objectives for a in alone]
    assert rows[0].objectives["e_total"] != rows[1].objectives["e_total"]  # the sampling mattered


def test_the_runner_times_two_points_alone_then_groups_the_rest():
    system = build_system(load_spec(FOLDER / "spec.json"))
    points = [(f"p{i}", _values(*p)) for i, p in enumerate(POINTS)]
    grouped = LockstepRunner(PointRunner(system))
    rows = list(grouped.rows(points))
    assert grouped.group_size is not None and grouped.group_size >= 2  # a point takes milliseconds
    assert [r.point_id for r in rows] == [pid for pid, _ in points]
    alone = _single(system, POINTS)
    assert [r.objectives for r in rows] == [a.objectives for a in alone]
    grouped.close()


def test_a_sweep_child_runs_its_points_in_lockstep_groups(monkeypatch):
    """Through the sweep's child process (cosim.parallel.isolation): rows of one group share their run time."""
    from cosim.parallel.isolation.payload import make_payload
    from cosim.parallel.isolation.runner import IsolatedRunner

    monkeypatch.setenv("COSIM_LOCKSTEP_SECONDS", "1000")  # groups of the largest size however loaded the machine

    system = build_system(load_spec(FOLDER / "spec_coarse.json"))
    table = pd.read_parquet(FOLDER / "results_coarse.parquet").iloc[:12]
    points = [(f"p{i}", {Q22: float(r[Q22]), Q24: float(r[Q24])}) for i, (_, r) in enumerate(table.iterrows())]
    runner = IsolatedRunner(make_payload(system))
    try:
        rows = runner.run(points, timeout=120)
    finally:
        runner.close()
    assert [r.status for r in rows] == ["ok"] * len(points)
    times = [r.run_time for r in rows]
    assert len(set(times[2:])) == 1  # one group: its time divided among its points
    for row, (_, expected) in zip(rows, table.iterrows()):
        assert np.isclose(row.objectives["e_total"], expected["e_total"], rtol=1e-12, atol=0.0)


@pytest.mark.parametrize("mode, status, fragment", [(1, "crashed", "SIGSEGV"), (2, "timeout", "timeout of 5 s")])
def test_a_point_that_kills_or_hangs_its_lockstep_group_alone_gets_the_blame(tmp_path, monkeypatch, mode, status,
                                                                             fragment):
    """The child announces each group; when a group dies, its points run again one by one (cosim.parallel.isolation)."""
    from cosim.parallel.isolation.payload import make_payload
    from cosim.parallel.isolation.runner import IsolatedRunner

    monkeypatch.setenv("COSIM_LOCKSTEP_SECONDS", "1000")  # the culprit surely runs in a group (travels in the payload)

    raw = json.loads((FOLDER / "spec.json").read_text())
    raw["units"]["f"] = {"fmu": "builtin:fault_fmi2", "parameters": {"trigger_time": 0.5}}  # beside the arm
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(raw))
    system = build_system(load_spec(path))
    assert can_run_in_lockstep(system)
    culprit = 5  # the first two points run alone (timing), the rest in groups
    points = [(f"p{i}", {**_values(*p), "f.mode": mode if i == culprit else 0}) for i, p in enumerate(POINTS)]
    runner = IsolatedRunner(make_payload(system))
    try:
        rows = runner.run(points, timeout=5)
    finally:
        runner.close()
    assert [r.point_id for r in rows] == [pid for pid, _ in points]
    assert [r.status for r in rows] == ["ok"] * culprit + [status] + ["ok"] * (len(points) - culprit - 1)
    assert fragment in rows[culprit].message
    alone = _single(build_system(load_spec(FOLDER / "spec.json")), POINTS)
    for i, (row, single) in enumerate(zip(rows, alone)):
        if i != culprit:
            assert row.objectives == single.objectives
