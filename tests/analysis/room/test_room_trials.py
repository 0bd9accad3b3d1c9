"""The Study tab of an optimisation (cosim.analysis.room.trials, issue 39.2) without a browser: the history's
best-so-far, the parameter importances of a study rebuilt in memory, the contour's interpolation, each
against what it must be; the page's side is in test_room_browser.py."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from cosim.analysis.room import trials as T
from cosim.analysis.table import ResultsTable


def optimisation(tmp_path, n: int = 120, seed: int = 4) -> ResultsTable:
    """An optimisation's table: f = 3 (x - 0.2)^2 + 0.01 y, g = -x (maximised), w constant; trials shuffled in
    the table (as a batch's rows may be), one failed and one infeasible."""
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
    df = pd.DataFrame({"point_id": [f"p{k}" for k in range(n)], "x": x, "y": y, "w": 1.0,
                       "f": 3 * (x - 0.2) ** 2 + 0.01 * y, "g": -x, "trial": rng.permutation(n),
                       "batch": 0, "sampler": "tpe", "feasible": True, "status": "ok"})
    df.loc[5, "status"], df.loc[5, "f"] = "failed", np.nan
    df.loc[7, "feasible"] = False
    spec = {"objectives": {"f": {"sense": "minimize", "unit": "J"}, "g": {"sense": "maximize"}},
            "design": {"parameters": {"x": {"min": -1, "max": 1}, "y": {"min": -1, "max": 1},
                                      "w": {"values": [1.0]}}}}
    meta = {"kind": "optimization", "spec": spec, "optimize": {"objectives": {"f": "minimize", "g": "maximize"}}}
    return ResultsTable(df=df, path=tmp_path / "results.parquet", metadata=meta, spec=spec)


def test_history_is_each_trial_in_order_and_the_best_so_far(tmp_path):
    table = optimisation(tmp_path)
    assert T.is_optimisation(table)
    df = table.df.sort_values("trial")
    h = T.history(table, "f", "min")
    assert list(h["trial"]) == list(range(len(df)))
    usable = ((df["status"] == "ok") & df["feasible"]).to_numpy()
    assert list(h["usable"]) == list(usable)
    best, running = [], np.inf
    for v, u in zip(df["f"], usable):  # the best so far, one trial at a time
        running = min(running, v) if u else running
        best.append(running)
    assert h["best"] == pytest.approx(best)
    g = T.history(table, "g", "max")
    assert g["best"][-1] == pytest.approx(df.loc[usable, "g"].max())
    assert np.isnan(h["value"][~usable]).all()


def test_importances_come_from_optunas_fanova_on_the_table(tmp_path, monkeypatch):
    table = optimisation(tmp_path)
    names = T.parameters(table, table.numeric_columns())
    assert names == ["x", "y"]  # w never varies
    got = T.importances(table, names, {"f": "min", "g": "max"})
    for objective in ("f", "g"):
        assert sum(got[objective].values()) == pytest.approx(1.0)
        assert got[objective]["x"] > 0.9  # f and g hang on x; y moves f by 1 % of its range
    assert got == T.importances(table, names, {"f": "min", "g": "max"})  # seeded: the same figures each time
    assert T.importances(table, [], {"f": "min"}) == {"f": {}}
    # a larger table: a sample of MAX_IMPORTANCE_TRIALS trials, still x first
    big = optimisation(tmp_path, n=300)
    every = T.importances(big, ["x", "y"], {"f": "min"})["f"]
    monkeypatch.setattr(T, "MAX_IMPORTANCE_TRIALS", 100)
    sampled = T.importances(big, ["x", "y"], {"f": "min"})["f"]
    assert sampled["x"] > 0.9 and sampled != every


def test_the_contour_interpolates_linearly_between_the_trials():
    rng = np.random.default_rng(1)
    x, y = rng.uniform(0, 2, 300), rng.uniform(-1, 1, 300)
    grid = T.contour(x, y, 2 * x - 3 * y + 1, cells=20)  # a plane: linear interpolation is exact in the hull
    image = grid["image"]
    assert image.shape == (20, 20)
    cx = grid["x0"] + (np.arange(20) + 0.5) / 20 * grid["dw"]
    cy = grid["y0"] + (np.arange(20) + 0.5) / 20 * grid["dh"]
    gx, gy = np.meshgrid(cx, cy)  # row 0 is the bottom (the lowest y)
    inside = np.isfinite(image)
    assert inside.mean() > 0.8
    assert image[inside] == pytest.approx((2 * gx - 3 * gy + 1)[inside], abs=1e-9)
    assert np.isnan(T.contour(np.arange(3.0), np.arange(3.0), np.arange(3.0))["image"]).all()  # on a line
