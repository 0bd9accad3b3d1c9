"""cosim optimize on real Dask: a problem with a known Pareto front, constraints, crashes, resume after kill -9."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from cosim.analysis.hypervolume import hypervolume, normalised_losses
from cosim.analysis.pareto import pareto_mask
from cosim.cli.main import main
from cosim.execution.point_row import PointRow
from cosim.studies.optimize import Optimization
from tests.helpers.paths import REPO
from tests.helpers.sweep_fixtures import kill_group
from tests.helpers.tools import python_unit


def bowls_spec(**optimize) -> dict:
    """TwoBowls over x in [-1, 3], y in [-2, 2]: the front is y = 0, 0 <= x <= 2, f2 = (2 - sqrt(f1))^2."""
    return {
        "name": "bowls",
        "units": {"b": {"python": python_unit("TwoBowls")}},
        "experiment": {"stop": 1.0, "step": 1.0},
        "objectives": {"f1": {"signal": "b.f1", "reduce": "final", "sense": "minimize"},
                       "f2": {"signal": "b.f2", "reduce": "final", "sense": "minimize"}},
        "design": {"parameters": {"b.x": {"min": -1.0, "max": 3.0}, "b.y": {"min": -2.0, "max": 2.0}}},
        "optimize": {"budget": 120, "batch": 8, "seed": 3, **optimize},
    }


def front_of(df: pd.DataFrame) -> np.ndarray:
    usable = (df["status"] == "ok") & df["feasible"]
    values = df.loc[usable, ["f1", "f2"]].to_numpy(float)
    return values[pareto_mask(values)]


def test_front_found_within_tolerance_and_output_constraint_respected(write_spec, tmp_path, local_cluster):
    spec = write_spec(bowls_spec(constraints=["f1 <= 2"]))
    run = Optimization(spec, tmp_path / "out", scheduler=local_cluster, quiet=True)
    counts = run.run()
    df = run.store.table()
    assert counts["ok"] == 120 and len(df) == 120 and df["point_id"].is_unique
    assert df["trial"].is_monotonic_increasing and set(df["sampler"]) == {"tpe"}
    # objectives and feasibility recomputed from the parameters, independently of the unit
    x, y = df["b.x"].to_numpy(), df["b.y"].to_numpy()
    np.testing.assert_allclose(df["f1"], x ** 2 + y ** 2, rtol=1e-12)
    np.testing.assert_array_equal(df["feasible"], x ** 2 + y ** 2 <= 2)
    assert (~df["feasible"]).any(), "the constraint never bit: the test would not see a violation"
    front = front_of(df)
    assert (front[:, 0] <= 2).all()
    # never beyond the true front; every front point near it and the front's hypervolume near the true one's,
    # in objectives scaled to [0, 1] over the true (constrained) front
    assert (front[:, 1] >= (2 - np.sqrt(front[:, 0])) ** 2 - 1e-9).all()
    f1 = np.linspace(0, 2, 4001)
    true = np.column_stack([f1, (2 - np.sqrt(f1)) ** 2])
    ideal, nadir = true.min(axis=0), true.max(axis=0)
    scale = dict(senses=["min", "min"], ideal=ideal, nadir=nadir)
    scaled_true = normalised_losses(true, **scale)
    distance = np.min(np.linalg.norm(normalised_losses(front, **scale)[:, None] - scaled_true[None], axis=2), axis=1)
    assert distance.max() < 0.05, distance
    found_hv = hypervolume(normalised_losses(front, **scale))
    true_hv = hypervolume(normalised_losses(true, **scale))
    assert found_hv >= 0.95 * true_hv, (found_hv, true_hv)
    # cosim pareto never lists an infeasible design
    assert main(["pareto", str(tmp_path / "out"), "--csv", str(tmp_path / "front.csv")]) == 0
    listed = pd.read_csv(tmp_path / "front.csv")
    assert len(listed) == len(front) and listed["feasible"].all()


def test_crashing_points_do_not_stop_the_optimisation(write_spec, tmp_path, local_cluster, capsys):
    spec_dict = bowls_spec(budget=24, seed=5)
    spec_dict["units"]["b"]["parameters"] = {"crash_above": 2.5}  # 1/8 of the x range kills the process
    spec = write_spec(spec_dict)
    code = main(["optimize", str(spec), "--out", str(tmp_path / "out"), "--scheduler", local_cluster])
    assert code == 1  # some evaluations not ok
    df = pd.read_parquet(tmp_path / "out" / "results.parquet")
    assert len(df) == 24 and df["point_id"].is_unique
    crashed = df["status"] == "crashed"
    assert crashed.any() and (df.loc[crashed, "b.x"] > 2.5).all() and (df.loc[~crashed, "b.x"] <= 2.5).all()
    assert (df.loc[crashed, "feasible"] == False).all()  # noqa: E712
    assert "crashed" in capsys.readouterr().err


def test_stepped_and_categorical_dimensions_never_evaluate_a_design_twice(write_spec, tmp_path, local_cluster):
    spec_dict = bowls_spec(budget=15, batch=4, sampler="random")
    spec_dict["design"]["parameters"] = {"b.x": {"values": [0.0, 0.5, 1.0, 1.5, 2.0]},
                                         "b.y": {"min": -1, "max": 1, "step": 1}}
    spec = write_spec(spec_dict)
    run = Optimization(spec, tmp_path / "out", scheduler=local_cluster, quiet=True)
    run.run()
    df = run.store.table()
    # 5 x 3 = 15 designs: the budget covers all of them exactly once, however often they were proposed
    assert len(df) == 15 and len(set(zip(df["b.x"], df["b.y"]))) == 15
    assert set(df["b.y"]) == {-1, 0, 1} and df["b.y"].dtype.kind == "i"
    assert df["trial"].max() >= 15  # random proposals repeat on 15 designs: some trials were answered from the table


@pytest.mark.parametrize("sampler", ["nsga2", "random", "qmc"])
def test_other_samplers_fill_the_budget(write_spec, tmp_path, local_cluster, sampler):
    spec = write_spec(bowls_spec(budget=24, batch=6, sampler=sampler))
    run = Optimization(spec, tmp_path / "out", scheduler=local_cluster, quiet=True)
    run.run()
    df = run.store.table()
    assert len(df) == 24 and set(df["sampler"]) == {sampler}
    # batches of at most 6 evaluations, in order (a design proposed again costs no evaluation)
    assert df["batch"].is_monotonic_increasing and df["batch"].value_counts().max() <= 6
    assert df["batch"].nunique() >= 4
    meta = json.loads((tmp_path / "out" / "metadata.json").read_text())
    assert meta["kind"] == "optimization" and meta["optimize"]["sampler"] == sampler


def _table_without_timing(path: Path) -> pd.DataFrame:
    df = pd.read_parquet(path)
    return df.drop(columns=["run_time", "worker"])


def _rows_stored(out) -> int:
    """Rows in the part files of ``out`` so far (a part is renamed into place whole)."""
    parts = list((out / "parts").glob("part-*.parquet")) if (out / "parts").is_dir() else []
    return sum(pq.ParquetFile(p).metadata.num_rows for p in parts)


def test_resume_after_kill_gives_the_table_of_an_uninterrupted_run(write_spec, tmp_path, local_cluster):
    spec = write_spec(bowls_spec(budget=64, batch=8, seed=11, constraints=["f1 <= 3"]))
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    # the client is killed (kill -9 of its process group); the cluster is the test's, as with --scheduler in use
    command = [sys.executable, "-m", "cosim.cli.main", "optimize", str(spec), "--scheduler", local_cluster]
    whole = subprocess.run(command + ["--out", str(tmp_path / "whole")], env=env, capture_output=True, text=True,
                           timeout=300)
    assert whole.returncode == 0, whole.stderr
    killed = tmp_path / "killed"
    proc = subprocess.Popen(command + ["--out", str(killed)], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while _rows_stored(killed) < 24:  # 3 of 8 batches stored (rows are stored as their points finish)
            assert proc.poll() is None and time.monotonic() < deadline, "the run ended before it could be killed"
            time.sleep(0.02)
    finally:
        kill_group(proc)  # SIGKILL
    assert proc.returncode == -signal.SIGKILL
    stored = len(pd.concat(pd.read_parquet(p) for p in (killed / "parts").glob("part-*.parquet")))
    assert 24 <= stored < 64
    resumed = subprocess.run(command + ["--out", str(killed), "--resume"], env=env, capture_output=True,
                             text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    assert f"{stored} evaluations stored" in resumed.stderr
    pd.testing.assert_frame_equal(_table_without_timing(killed / "results.parquet"),
                                  _table_without_timing(tmp_path / "whole" / "results.parquet"))
    meta = json.loads((killed / "metadata.json").read_text())
    assert len(meta["runs"]) == 2 and meta["counts"]["ok"] == 64


def test_bad_optimize_section_is_exit_2_naming_the_field(write_spec, tmp_path, capsys):
    spec = write_spec(bowls_spec(objectives={"energy": "minimize"}, constraints=["f1 + 1"]))
    assert main(["optimize", str(spec), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "$.optimize.objectives.energy" in err and "'energy' is not an objective" in err
    spec = write_spec(bowls_spec(constraints=["f1 + 1"]), "c.json")
    assert main(["optimize", str(spec), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "$.optimize.constraints[0]" in err and "not one comparison" in err
    spec = write_spec(bowls_spec(constraints=["f3 <= 1"]), "d.json")
    assert main(["optimize", str(spec), "--out", str(tmp_path / "o")]) == 2
    assert "unknown name(s) in 'f3 <= 1': f3" in capsys.readouterr().err
    spec = write_spec(bowls_spec(sampler="annealing"), "e.json")
    assert main(["validate", str(spec)]) == 2
    assert "$.optimize.sampler" in capsys.readouterr().err


def test_default_results_folder_is_named_after_the_spec(write_spec, tmp_path, local_cluster, monkeypatch):
    spec = write_spec(bowls_spec(budget=4, batch=4))
    monkeypatch.chdir(tmp_path)
    assert main(["optimize", str(spec), "--scheduler", local_cluster]) == 0
    assert len(pd.read_parquet(tmp_path / "results" / "bowls_optimize" / "results.parquet")) == 4


def test_objectives_from_the_command_line_drive_the_search_and_the_front(write_spec, tmp_path, local_cluster):
    spec = write_spec(bowls_spec(budget=16))
    out = tmp_path / "out"
    assert main(["optimize", str(spec), "--max", "f1", "--min", "f2", "--out", str(out),
                 "--scheduler", local_cluster]) == 0
    meta = json.loads((out / "metadata.json").read_text())
    assert meta["optimize"]["objectives"] == {"f1": "maximize", "f2": "minimize"}
    assert main(["pareto", str(out), "--csv", str(tmp_path / "front.csv")]) == 0  # senses from the metadata
    df = pd.read_parquet(out / "results.parquet")
    expected = pareto_mask(df[["f1", "f2"]].to_numpy(), ["max", "min"])
    assert sorted(pd.read_csv(tmp_path / "front.csv")["point_id"]) == sorted(df.loc[expected, "point_id"])


def staircase_area(points: np.ndarray, reference: float) -> float:
    """2-D hypervolume by the staircase: sort by the first loss, add each point's rectangle up to the last one."""
    pts = points[np.all(points < reference, axis=1)]
    pts = pts[np.argsort(pts[:, 0])]
    area, best_y = 0.0, reference
    for x, y in pts:
        if y < best_y:
            area += (reference - x) * (best_y - y)
            best_y = y
    return area


def test_one_hypervolume_in_the_scale_of_the_first_batch_never_decreases():
    """Issue 28: the progress line scaled by the current front (constant 1.21 on a converged grid, dropping
    between batches elsewhere) and disagreed with the report. Now one figure: the scale of the first batch's
    usable rows, fixed, reference 1.1; later rows beyond that batch's nadir add nothing, better ones add."""
    from cosim.analysis.hypervolume import hypervolume_history, progress_hypervolume

    values = np.array([[2.0, 2.0], [4.0, 1.0], [1.0, 4.0],   # batch 0: ideal (1, 1), nadir (4, 4)
                       [9.0, 9.0], [0.5, 3.0],               # batch 1: one far worse, one beyond the ideal
                       [3.0, 3.0], [1.0, 1.5]])              # batch 2: dominated, then a new best
    batches = np.array([0, 0, 0, 1, 1, 2, 2])
    usable = np.ones(7, dtype=bool)
    history = hypervolume_history(values, ["min", "min"], usable, batches)
    scale = {"ideal": np.array([1.0, 1.0]), "nadir": np.array([4.0, 4.0])}
    for i in range(7):  # after each row: the front so far, in the first batch's scale, by the staircase
        losses = normalised_losses(values[:i + 1], ["min", "min"], **scale)
        kept = losses[np.all(losses < 1.1, axis=1)]
        assert history[i] == pytest.approx(staircase_area(kept, 1.1) if len(kept) else 0.0, rel=1e-12)
    assert np.all(np.diff(history) >= 0.0) and history[3] == history[2] and history[5] == history[4]
    assert progress_hypervolume(values, ["min", "min"], usable, batches) == history[-1]


def test_hypervolume_and_its_history_in_the_report(tmp_path):
    from cosim.analysis.hypervolume import hypervolume_history
    from cosim.analysis.report import build_report
    from cosim.analysis.table import load_results

    rng = np.random.default_rng(4)
    losses = rng.random((40, 2))
    assert hypervolume(losses) == pytest.approx(staircase_area(losses, 1.1), rel=1e-12)
    values = rng.random((30, 2)) * [10.0, 2.0] + [1.0, 5.0]
    usable = np.ones(30, dtype=bool)
    usable[[3, 17]] = False
    history = hypervolume_history(values, ["min", "max"], usable)
    assert np.all(np.diff(history) >= -1e-12)  # a front never loses hypervolume
    # without batch numbers the scale is that of all usable rows (issue 28: one fixed reference, not the front's)
    scaled = normalised_losses(values[usable], ["min", "max"])
    assert history[-1] == pytest.approx(staircase_area(scaled, 1.1), rel=1e-12)
    # an optimisation's table: the report plots that history
    df = pd.DataFrame({"point_id": [f"p{i}" for i in range(30)], "a": values[:, 0], "b": values[:, 1],
                       "trial": np.arange(30), "feasible": usable, "status": "ok"})
    (tmp_path / "o").mkdir()
    df.to_parquet(tmp_path / "o" / "results.parquet")
    meta = {"kind": "optimization", "optimize": {"objectives": {"a": "minimize", "b": "maximize"}, "sampler": "tpe"},
            "spec": {"objectives": {"a": {"signal": "u.a", "reduce": "final"}, "b": {"signal": "u.b", "reduce": "final"}}}}
    (tmp_path / "o" / "metadata.json").write_text(json.dumps(meta))
    page = build_report(load_results(tmp_path / "o"))
    assert "<h2>Optimisation</h2>" in page and f"final {history[-1]:.4f}" in page
    # issue 28: titled for what it is, settings as a reader writes them, no raw Python dicts, no empty header
    assert "<h1>Optimisation report: " in page and "Sweep report" not in page
    assert "a: minimize, b: maximize" in page and "{'a'" not in page and "<th class='l'></th>" not in page
    assert f"{int(pareto_mask(values[usable], ['min', 'max']).sum())} non-dominated of 28 ok, feasible rows" in page


class BowlsInProcess:
    """TwoBowls answered in this process (the Evaluator interface); designs with x > 2.5 fail."""

    def evaluate(self, points):
        rows = []
        for pid, values in points:
            x, y = values["b.x"], values["b.y"]
            if x > 2.5:
                rows.append(PointRow(pid, "failed", "x > 2.5", 0.0, {}, "test"))
            else:
                rows.append(PointRow(pid, "ok", "", 0.0, {"f1": x * x + y * y, "f2": (x - 2) ** 2 + y * y}, "test"))
        return rows


def test_progress_line_counts_failures_front_and_hypervolume(write_spec, tmp_path):
    import io

    spec = write_spec(bowls_spec(budget=24, batch=8, seed=7, sampler="random", constraints=["f1 <= 3"]))
    stream = io.StringIO()
    run = Optimization(spec, tmp_path / "out", progress=stream)
    run.run(evaluator=BowlsInProcess())
    df = run.store.table()
    last = stream.getvalue().strip().splitlines()[-1]
    # recomputed from the table: failures, the feasible front and its area (staircase, objectives scaled over
    # the feasible rows of the first batch, fixed for the whole run (issue 28), reference 1.1, rows beyond it
    # left out)
    failed = int((df["status"] != "ok").sum())
    ok = df[(df["status"] == "ok") & df["feasible"]]
    usable = ok[["f1", "f2"]].to_numpy(float)
    first = ok[ok["batch"] == ok["batch"].min()][["f1", "f2"]].to_numpy(float)
    front = usable[pareto_mask(usable)]
    scaled = (front - first.min(axis=0)) / (first.max(axis=0) - first.min(axis=0))
    scaled = scaled[np.all(scaled < 1.1, axis=1)]
    assert failed > 0 and len(usable) < len(df) - failed  # both a failure and an infeasible row were seen
    assert last.startswith(f"24/24 evaluations, {failed} not ok, front {len(front)}, "
                           f"hypervolume {staircase_area(scaled, 1.1):.4f}, "), last


def test_a_discrete_space_whose_optimum_is_found_early_ends_with_every_design_run_once(write_spec, tmp_path,
                                                                                      local_cluster, capsys):
    # 5 x 3 = 15 designs and a budget of 200: TPE finds the front (y = 0, x in 0..2) and then proposes designs
    # already evaluated; the search switches to the designs not yet run and stops when there are none left
    spec_dict = bowls_spec(budget=200, batch=4, seed=2)
    spec_dict["design"]["parameters"] = {"b.x": {"min": -1, "max": 3, "step": 1},
                                         "b.y": {"values": [-1.0, 0.0, 1.0]}}
    spec = write_spec(spec_dict)
    code = main(["optimize", str(spec), "--out", str(tmp_path / "out"), "--scheduler", local_cluster])
    assert code == 0
    err = capsys.readouterr().err
    df = pd.read_parquet(tmp_path / "out" / "results.parquet")
    designs = set(zip(df["b.x"], df["b.y"]))
    assert len(df) == 15 and designs == {(x, y) for x in range(-1, 4) for y in (-1.0, 0.0, 1.0)}
    assert "brought no design not yet evaluated (tpe proposes designs already evaluated)" in err
    assert "stopped: every design of the space is evaluated (15 designs; the budget of 200 is not spent)" in err
    assert set(df["sampler"]) <= {"tpe", "random"} and (df["sampler"] == "tpe").any()
    np.testing.assert_allclose(df["f1"], df["b.x"] ** 2 + df["b.y"] ** 2, rtol=1e-12)


class FormulaEvaluator:
    """TwoBowls answered from its formula, without Dask (as benchmarks answer from a table); raises
    KeyboardInterrupt at call ``interrupt_at`` (Ctrl-C in the middle of a run)."""

    def __init__(self, interrupt_at: int | None = None):
        self.calls, self.interrupt_at, self.asked = 0, interrupt_at, []

    def evaluate(self, points):
        self.calls += 1
        self.asked.append([pid for pid, _ in points])
        if self.calls == self.interrupt_at:
            raise KeyboardInterrupt
        return [PointRow(pid, "ok", "", 0.0, {"f1": v["b.x"] ** 2 + v["b.y"] ** 2,
                                              "f2": (v["b.x"] - 2) ** 2 + v["b.y"] ** 2}) for pid, v in points]


def test_the_switch_happens_at_the_same_batch_on_resume_and_proposals_stay_few(write_spec, tmp_path):
    spec_dict = bowls_spec(budget=300, batch=4, seed=4)
    spec_dict["design"]["parameters"] = {"b.x": {"min": -1.0, "max": 3.0, "step": 0.5},
                                         "b.y": {"min": -2, "max": 2, "step": 1}}
    spec_dict["design"]["constraint"] = "b.x + b.y <= 3"
    spec = write_spec(spec_dict)
    run, whole = Optimization(spec, tmp_path / "whole", quiet=True), FormulaEvaluator()
    run.run(evaluator=whole)
    df = run.store.table()
    allowed = {(x / 2, y) for x in range(-2, 7) for y in range(-2, 3) if x / 2 + y <= 3}
    assert len(df) == len(allowed) and set(zip(df["b.x"], df["b.y"])) == allowed and df["point_id"].is_unique
    assert run.stop_reason.startswith("stopped: every design of the space is evaluated")
    switch = df.index[df["sampler"] == "random"][0]
    assert switch > 0 and (df["sampler"][switch:] == "random").all()
    # proposals: one per evaluation, the designs outside the constraint and the repeats TPE asked before the
    # switch, and no more than one batch of repeats after it (the 20x budget cap would allow 6000)
    assert run.trials_asked <= len(allowed) + df.loc[switch - 1, "trial"] + 4
    # interrupted after the switch and resumed: the same table, the same switch
    interrupted = tmp_path / "cut"
    first_random = next(i for i, ids in enumerate(whole.asked, start=1) if df.loc[switch, "point_id"] in ids)
    assert first_random < whole.calls  # a random batch stored before the cut, another after it
    with pytest.raises(KeyboardInterrupt):
        Optimization(spec, interrupted, quiet=True).run(evaluator=FormulaEvaluator(interrupt_at=first_random + 1))
    resumed = Optimization(spec, interrupted, resume=True, quiet=True)
    resumed.run(evaluator=FormulaEvaluator())
    again = resumed.store.table()
    assert len(again) == len(df)
    pd.testing.assert_frame_equal(again.drop(columns=["run_time", "worker"], errors="ignore"),
                                  df.drop(columns=["run_time", "worker"], errors="ignore"))
