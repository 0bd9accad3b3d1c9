"""Exact pruning, part 2: a real sweep on a local Dask cluster (worker child processes) with ``prune=True`` keeps
the front of the unpruned sweep design for design and value for value; pruned rows are data (status pruned, the
bound in the objective columns, pruned_by, pruned_at); a resume keeps them, a resume without pruning runs them."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cosim.analysis.pareto import pareto_mask
from cosim.errors import SpecError
from cosim.execution.prune import PruneSettings
from cosim.studies.pruning import FrontKeeper, maximin_first, pruning_order
from cosim.studies.sweep import Sweep
from tests.helpers.paths import REPO

EXAMPLE = REPO / "examples" / "drive_energy"
OBJECTIVES = ["energy_no_recuperation", "peak_power"]


@pytest.fixture(scope="module")
def spec_path(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("drive_sweep")
    raw = json.loads((EXAMPLE / "spec.json").read_text())
    raw["objectives"]["energy_no_recuperation"].update(monotone="non-decreasing", sense="minimize")
    raw["objectives"]["energy"].pop("sense")
    raw["design"]["parameters"]["energy.gear_ratio"] = {"min": 50, "max": 160, "step": 22, "unit": "1"}
    (folder / "spec.json").write_text(json.dumps(raw))
    shutil.copy(EXAMPLE / "drive_profile.py", folder)
    return folder / "spec.json"


def _front(table: pd.DataFrame) -> pd.DataFrame:
    ok = table[table["status"] == "ok"]
    front = ok[pareto_mask(ok[OBJECTIVES].to_numpy(), ["minimize"] * 2)]
    return front.set_index("point_id")[OBJECTIVES].sort_index()


@pytest.fixture(scope="module")
def studies(spec_path, tmp_path_factory):
    out = tmp_path_factory.mktemp("out")
    full = Sweep(spec_path, workers=2, out=out / "full", quiet=True).run()
    pruned = Sweep(spec_path, workers=2, out=out / "pruned", quiet=True, prune=True).run()
    return full, pruned, out


def test_the_pruned_sweep_keeps_the_front_exactly_and_prunes(studies):
    full, pruned, _ = studies
    assert (full["status"] == "ok").all()
    counts = pruned["status"].value_counts().to_dict()
    assert counts.get("pruned", 0) > 0 and set(counts) <= {"ok", "pruned"}
    a, b = _front(full), _front(pruned)
    assert list(a.index) == list(b.index)
    assert (a.to_numpy() == b.to_numpy()).all()  # value for value, bit for bit


def test_pruned_rows_hold_bounds_dominated_by_the_design_they_name(studies):
    full, pruned, out = studies
    rows = pruned[pruned["status"] == "pruned"]
    finals = full.set_index("point_id")
    front = _front(full)
    for _, row in rows.iterrows():
        by = row["pruned_by"]
        assert by in set(pruned.loc[pruned["status"] == "ok", "point_id"])
        bound = row[OBJECTIVES].to_numpy(dtype=float)
        dominating = finals.loc[by, OBJECTIVES].to_numpy(dtype=float)
        assert (dominating <= bound).all() and (dominating < bound).any()
        assert (bound <= finals.loc[row["point_id"], OBJECTIVES].to_numpy(dtype=float)).all()  # a bound
        assert 0 < row["pruned_at"] < 2.5
        assert ((front.to_numpy() <= bound).all(axis=1) & (front.to_numpy() < bound).any(axis=1)).any()
    meta = json.loads((out / "pruned" / "metadata.json").read_text())
    assert meta["pruning"]["objectives"] == [["peak_power", "minimize"], ["energy_no_recuperation", "minimize"]]
    assert "BOUNDS" in meta["pruning"]["pruned_rows"]
    assert meta["pruning"]["order"]["first"] == 8 and len(meta["pruning"]["order"]["first_ids"]) == 8


def test_resume_keeps_pruned_rows_and_resume_without_pruning_runs_them(studies, spec_path):
    full, pruned, out = studies
    again = Sweep(spec_path, workers=2, out=out / "pruned", quiet=True, resume=True, prune=True).run()
    assert (again["status"] == "pruned").sum() == (pruned["status"] == "pruned").sum()
    finished = Sweep(spec_path, workers=2, out=out / "pruned", quiet=True, resume=True).run()
    assert (finished["status"] == "ok").all()
    assert _front(finished).equals(_front(full))


def test_pruning_without_a_bounded_objective_is_refused(spec_path, tmp_path):
    with pytest.raises(SpecError, match="no objective pruned on is bounded"):
        Sweep(spec_path, workers=1, out=tmp_path / "x", quiet=True, prune=True,
              prune_objectives=[("energy", "minimize")])
    with pytest.raises(SpecError, match="not a comparison"):
        Sweep(spec_path, workers=1, out=tmp_path / "y", quiet=True, prune=True, prune_constraints=["a < b"])


def test_the_front_keeper_keeps_only_feasible_non_dominated_designs():
    keeper = FrontKeeper(PruneSettings((("a", "minimize"), ("b", "maximize")), (("c", "<=", 1.0),)))
    assert keeper.add("p", {"a": 1.0, "b": 1.0, "c": 0.0})
    assert not keeper.add("infeasible", {"a": 0.0, "b": 9.0, "c": 2.0})
    assert not keeper.add("worse", {"a": 2.0, "b": 0.5, "c": 0.0})
    assert not keeper.add("same", {"a": 1.0, "b": 1.0, "c": 0.0})
    assert keeper.add("better", {"a": 0.5, "b": 1.0, "c": 0.0})
    assert keeper.ids == ["better"] and keeper.values.tolist() == [[0.5, -1.0]]


def test_the_first_points_fill_the_space():
    class P:
        def __init__(self, i, x, y):
            self.id, self.values = str(i), {"x": x, "y": y}

    grid = [P(i, x, y) for i, (x, y) in enumerate((x, y) for x in range(11) for y in range(11))]
    first = maximin_first(grid, np.array([[p.values["x"], p.values["y"]] for p in grid], float), 5)
    picked = {(grid[i].values["x"], grid[i].values["y"]) for i in first}
    assert picked == {(5, 5), (0, 0), (0, 10), (10, 0), (10, 10)}  # the centre, then the corners
    ordered, note = pruning_order(grid)
    assert len(ordered) == 121 and len({p.id for p in ordered}) == 121 and note["first"] == 8
