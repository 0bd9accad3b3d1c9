"""Exact pruning inside a lock-step group (cosim.execution.lockstep_prune): rows proven off the front leave the
group, which steps on; every row not pruned is the row of the unpruned group bit for bit, every pruned row says
so, when, and holds a bound that the front member it names strictly dominates and its final value never beats."""

from __future__ import annotations

import json

import numpy as np
import pytest

import cosim.execution.lockstep_prune as lockstep_prune
from cosim import build_system, load_spec
from cosim.execution.lockstep import LockstepRunner, instantiate, run_lockstep
from cosim.execution.point import assignments_for
from cosim.execution.prune import PruneOrder
from cosim.parallel.isolation.point_runner import PointRunner
from cosim.studies.pruning import prune_settings
from tests.helpers.paths import REPO

FOLDER = REPO / "examples" / "pick_and_place"
Q22, Q24 = "traj.waypoints[9]", "traj.waypoints[11]"
OBJECTIVES = ("e_total_no_recuperation", "duration")
POINTS = [{Q22: float(a), Q24: float(b)} for a in np.linspace(-100, 20, 6) for b in (0.0, 35.0, 70.0, 140.0)]


@pytest.fixture(scope="module")
def system(tmp_path_factory):
    """spec_pruned.json's objectives, declarations and constraint at the inverse-dynamics level (spec.json's
    robot and step), which runs in lock-step groups."""
    raw = json.loads((FOLDER / "spec_pruned.json").read_text())
    level = json.loads((FOLDER / "spec.json").read_text())
    raw["units"]["robot"] = level["units"]["robot"]
    raw["experiment"]["step"] = level["experiment"]["step"]
    path = tmp_path_factory.mktemp("id") / "spec.json"
    path.write_text(json.dumps(raw))
    return build_system(load_spec(path))


@pytest.fixture(scope="module")
def unpruned(system):
    batches = instantiate(system, len(POINTS))
    try:
        return run_lockstep(system, [assignments_for(system, p) for p in POINTS], batches)
    finally:
        for batch in batches.values():
            batch.terminate()


def _order(system, unpruned):
    """A front of one finished feasible design (the least energy among the shortest), as a study sends it."""
    settings = prune_settings(system, None, ["peak_tau <= 1"])
    feasible = [r for r in unpruned if r.ok and r.objectives["peak_tau"] <= 1]
    shortest = min(r.objectives["duration"] for r in feasible)
    best = min((r for r in feasible if r.objectives["duration"] == shortest),
               key=lambda r: r.objectives["e_total_no_recuperation"])
    return PruneOrder(settings, ("front",), (tuple(best.objectives[n] for n in OBJECTIVES),)), best


def _check(rows, unpruned, front):
    """Rows of a pruned run against the unpruned group's: (how many pruned)."""
    pruned = 0
    for row, full in zip(rows, unpruned):
        if row.status == "ok":
            assert row.objectives == full.objectives  # bit for bit: == on floats, every objective
            continue
        assert row.status == "pruned", row.message
        pruned += 1
        assert row.message.startswith("pruned at t=") and "design front strictly dominates" in row.message
        at = float(row.message.split("t=")[1].split(":")[0])
        assert 0 < at < full.end_time
        bound = np.array([row.objectives[n] for n in OBJECTIVES])
        final = np.array([full.objectives[n] for n in OBJECTIVES])
        assert (front <= bound).all() and (front < bound).any()  # strictly dominated
        assert (bound <= final).all()  # a bound: the design could only get worse
        assert np.isnan(row.objectives["e_total"])  # unbounded objectives hold NaN, as in a single run
    return pruned


def test_rows_proven_off_the_front_leave_the_group_and_the_others_keep_their_results(system, unpruned,
                                                                                      monkeypatch):
    monkeypatch.setattr(lockstep_prune, "OVERHEAD_SHARE", 1e9)  # compare at every step: deterministic
    order, best = _order(system, unpruned)
    front = np.array(order.values[0])
    batches = instantiate(system, len(POINTS))
    try:
        rows = run_lockstep(system, [assignments_for(system, p) for p in POINTS], batches, order)
    finally:
        for batch in batches.values():
            batch.terminate()
    # every design whose final values the front member strictly dominates is pruned: it could not be missed
    dominated = [bool((front <= f).all() and (front < f).any())
                 for f in (np.array([r.objectives[n] for n in OBJECTIVES]) for r in unpruned)]
    assert [r.status == "pruned" for r in rows] == dominated
    assert _check(rows, unpruned, front) >= len(POINTS) // 2
    assert rows[unpruned.index(best)].status == "ok"
    # the rows left stopped early: their last samples come before the unpruned rows' ends
    assert all(r.steps < u.steps for r, u in zip(rows, unpruned) if r.status == "pruned")


def test_an_empty_front_and_no_constraint_prune_nothing_and_change_nothing(system, unpruned):
    settings = prune_settings(system, None, [])
    batches = instantiate(system, len(POINTS))
    try:
        rows = run_lockstep(system, [assignments_for(system, p) for p in POINTS], batches,
                            PruneOrder(settings, (), ()))
    finally:
        for batch in batches.values():
            batch.terminate()
    assert [r.objectives for r in rows] == [u.objectives for u in unpruned]


def test_the_runner_prunes_inside_its_groups(system, unpruned, monkeypatch):
    """LockstepRunner.rows with a front: the first points alone, then groups (announced), rows pruned inside."""
    monkeypatch.setattr(lockstep_prune, "OVERHEAD_SHARE", 1e9)
    monkeypatch.setenv("COSIM_LOCKSTEP_SECONDS", "1000")  # groups of the largest size however loaded the machine
    order, _ = _order(system, unpruned)
    runner = PointRunner(system)
    grouped = LockstepRunner(runner)
    announced: list[int] = []
    try:
        rows = list(grouped.rows([(f"p{i}", p) for i, p in enumerate(POINTS)], announce=announced.append,
                                 prune=order))
    finally:
        grouped.close()
        runner.close()
    assert announced == [len(POINTS) - 2]  # two points timed alone, the rest one group
    assert [r.point_id for r in rows] == [f"p{i}" for i in range(len(POINTS))]
    assert _check(rows, unpruned, np.array(order.values[0])) >= len(POINTS) // 2
    assert len({r.run_time for r in rows[2:]}) == 1  # one group: its time divided among its points
