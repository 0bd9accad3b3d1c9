"""The compiled parts of a lock-step group give the rows of its Python parts bit for bit.

A lock-step group of the pick-and-place system (cosim.execution.lockstep) sets and steps its K energy-FMU
instances in C loops (cosim.master.native.rows), samples the trajectory and finishes the arm's outputs in
compiled row loops (models/panda_rows_c/id_rows.c) and reduces every point's objectives at once
(cosim.execution.lockstep_reduce).  Each must equal what it replaces exactly, and a failure inside a C loop
must still give every point the row of its single run.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cosim import build_system, load_spec
from cosim.execution import lockstep as lockstep_module
from cosim.execution.lockstep import LockstepRunner, instantiate, run_lockstep
from cosim.execution.lockstep_reduce import GROUP_REDUCTIONS, reduce_group
from cosim.execution.point import assignments_for
from cosim.master.native.rows import NativeRows
from cosim.master.observers import ObjectiveReducer
from cosim.parallel.isolation.point_runner import PointRunner
from cosim.units.protocol import UnitError
from tests.helpers.paths import REPO

FOLDER = REPO / "examples" / "pick_and_place"
Q22, Q24 = "traj.waypoints[9]", "traj.waypoints[11]"
POINTS = [(-100.0, 140.0), (20.0, 0.0), (0.0, 0.0), (-74.0, 85.0), (1.0, 76.0), (-45.0, 70.0)]


def _spec(tmp_path: Path, sampling: str = "step_midpoint", **experiment) -> Path:
    raw = json.loads((FOLDER / "spec.json").read_text())
    raw["units"]["traj"]["parameters"]["sampling"] = sampling
    raw["experiment"].update(experiment)
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(raw))
    return path


def _run(system, compiled: bool, monkeypatch) -> list:
    """The group's results with every compiled part on, or every one off (Python loops, numpy twins,
    point-by-point reductions)."""
    with monkeypatch.context() as m:
        if not compiled:
            m.setattr(lockstep_module, "_native_rows", lambda units: None)
            m.setattr(lockstep_module, "reduce_group", lambda *args: None)
            from cosim.models.panda_inverse_dynamics import PandaInverseDynamicsBatch
            from cosim.models.trajectory import TrajectoryGeneratorBatch
            m.setattr(PandaInverseDynamicsBatch, "_row_kernel", lambda self: None)
            m.setattr(TrajectoryGeneratorBatch, "_row_kernel", lambda self: None)
        batches = instantiate(system, len(POINTS))
        try:
            results = run_lockstep(system, [assignments_for(system, {Q22: a, Q24: b}) for a, b in POINTS], batches)
            used = (batches["energy"].native is not None, batches["traj"]._kernel is not None,
                    batches["robot"]._kernel is not None)
        finally:
            for batch in batches.values():
                batch.terminate()
    assert used == ((True,) * 3 if compiled else (False,) * 3)
    return results


@pytest.mark.parametrize("sampling, algorithm", [("step_midpoint", "gauss-seidel"), ("step_midpoint", "jacobi"),
                                                 ("instant", "gauss-seidel")])
def test_the_compiled_group_equals_the_python_group_bit_for_bit(tmp_path, monkeypatch, sampling, algorithm):
    system = build_system(load_spec(_spec(tmp_path, sampling, algorithm=algorithm)))
    compiled, python = _run(system, True, monkeypatch), _run(system, False, monkeypatch)
    assert len({r.steps for r in compiled}) > 3
    for c, p in zip(compiled, python):
        assert c.ok and p.ok
        assert (c.steps, c.end_time) == (p.steps, p.end_time)
        assert c.objectives.keys() == p.objectives.keys()
        for name in c.objectives:  # exactly: the same bits, -0.0 and NaN included
            assert np.array_equal(np.float64(c.objectives[name]).view(np.int64),
                                  np.float64(p.objectives[name]).view(np.int64)), name


def test_kernel_python_keeps_the_fmu_instances_in_python_loops(tmp_path):
    system = build_system(load_spec(_spec(tmp_path, kernel="python")))
    batches = instantiate(system, 2)
    try:
        assert batches["energy"].native is None
    finally:
        for batch in batches.values():
            batch.terminate()


def test_an_fmu_failing_inside_the_c_loop_gives_every_point_its_single_row(tmp_path):
    """fault_fmi2 mode 3: doStep returns fmi2Error at t >= 0.5 s for one point of the group."""
    raw = json.loads((FOLDER / "spec.json").read_text())
    raw["units"]["f"] = {"fmu": "builtin:fault_fmi2", "parameters": {"trigger_time": 0.5}}
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(raw))
    system = build_system(load_spec(path))
    points = [(f"p{i}", {Q22: a, Q24: b, "f.mode": 3 if i == 2 else 0}) for i, (a, b) in enumerate(POINTS)]
    batches = instantiate(system, len(points))
    try:
        assert isinstance(batches["f"].native, NativeRows)
        with pytest.raises(UnitError, match="fmi2DoStep"):
            run_lockstep(system, [assignments_for(system, values) for _, values in points], batches)
    finally:
        for batch in batches.values():
            batch.terminate()
    grouped = LockstepRunner(PointRunner(system))
    grouped.group_size = len(points)
    rows = list(grouped.rows(points))
    grouped.close()
    alone = [PointRunner(system).run(pid, values) for pid, values in points]
    assert [r.status for r in rows] == ["ok", "ok", "failed", "ok", "ok", "ok"]
    for g, a in zip(rows, alone):
        assert (g.status, g.message, g.objectives) == (a.status, a.message, a.objectives)
    assert "fmi2DoStep" in rows[2].message


def test_the_group_reductions_equal_the_point_by_point_reducer_bit_for_bit():
    """Random groups with NaN, infinities and signed zeros in the samples, points ending at any sample."""
    rng = np.random.default_rng(7)
    compared = 0
    for _ in range(300):
        n_columns, rows, samples = int(rng.integers(2, 10)), int(rng.integers(2, 8)), int(rng.integers(1, 50))
        columns = [f"c{i}" for i in range(n_columns)]
        objectives = []
        for j in range(int(rng.integers(1, 7))):
            k = int(rng.integers(1, min(3, n_columns) + 1))
            start = int(rng.integers(0, n_columns - k + 1))
            objectives.append((f"o{j}", sorted(GROUP_REDUCTIONS)[rng.integers(len(GROUP_REDUCTIONS))],
                               columns[start:start + k]))
        reducer = ObjectiveReducer(columns, objectives)
        data = rng.standard_normal((samples, rows + 1, n_columns)) * 10.0 ** rng.uniform(-3, 3, size=n_columns)
        pick = rng.random(data.shape)
        data[pick < 0.02], data[(pick > 0.02) & (pick < 0.03)] = -0.0, 0.0
        data[pick > 0.995], data[(pick > 0.99) & (pick < 0.992)] = np.nan, np.inf
        data[(pick > 0.985) & (pick < 0.987)] = -np.inf
        times = np.concatenate([[0.0], np.cumsum(rng.uniform(0.001, 0.02, samples - 1))])
        ends = rng.integers(0, samples, rows)
        group = reduce_group(reducer, times, data, ends)
        if len(reducer.columns) < 2:
            assert group is None  # numpy sums one column pairwise: reduced point by point
            continue
        assert group is not None
        for i in range(rows):
            reducer.load(times[:ends[i] + 1], data[:ends[i] + 1, i, :])
            with np.errstate(all="ignore"):
                alone = reducer.results()
            for name, value in alone.items():
                a, g = np.atleast_1d(value), np.atleast_1d(group[i][name])
                assert a.shape == g.shape and np.array_equal(a.view(np.int64), g.view(np.int64)), name
                compared += 1
    assert compared > 1000


def test_reductions_the_group_does_not_know_are_left_to_the_point_by_point_reducer():
    reducer = ObjectiveReducer(["a", "b"], [("m", "mean", ["a"]), ("x", "max", ["b"])])
    assert reduce_group(reducer, np.arange(3.0), np.zeros((3, 2, 2)), np.array([2, 1])) is None
    single = ObjectiveReducer(["a", "b"], [("x", "integral", ["a"])])  # one kept column
    assert reduce_group(single, np.arange(3.0), np.zeros((3, 2, 2)), np.array([2, 1])) is None
