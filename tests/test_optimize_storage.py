"""Issue 28.16: `cosim optimize --storage sqlite:///...` keeps the trials in an Optuna storage as well, so that
optuna-dashboard, optuna.load_study and Optuna's plots see the optimisation cosim ran.

Real Dask (the local_cluster fixture), a real SQLite file; every trial in the storage is checked against the
results table and against the objective's formula, the storage's Pareto front against cosim's.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import optuna
import pandas as pd
import pytest

from cosim.analysis.pareto import pareto_mask
from cosim.cli.main import main
from cosim.studies.optuna_storage import shown_url

from .test_optimize import REPO, FormulaEvaluator, bowls_spec


def stored_trials(url: str, name: str) -> pd.DataFrame:
    """The storage's finished trials as rows: point_id, status, b.x, b.y, f1, f2, feasible (from its constraint)."""
    study = optuna.load_study(study_name=name, storage=url)
    rows = []
    for t in study.get_trials(deepcopy=False):
        constraint = list(t.constraints.values() or [np.nan])[0]  # {"f1 <= 3": violation}
        rows.append({"point_id": t.user_attrs.get("point_id"), "status": t.user_attrs.get("status"),
                     "state": t.state.name, **t.params, "f1": (t.values or [np.nan])[0],
                     "f2": (t.values or [np.nan, np.nan])[1], "violation": constraint})
    return pd.DataFrame(rows), study


def test_the_storage_holds_every_trial_of_the_table_and_its_front(write_spec, tmp_path, local_cluster):
    spec = write_spec(bowls_spec(budget=24, batch=8, seed=5, constraints=["f1 <= 3"]))
    out, url = tmp_path / "out", f"sqlite:///{tmp_path / 'study.db'}"
    assert main(["optimize", str(spec), "--out", str(out), "--scheduler", local_cluster, "--storage", url,
                 "-q"]) == 0
    table = pd.read_parquet(out / "results.parquet")
    trials, study = stored_trials(url, str(out.resolve()))
    assert len(trials) == 24 and set(trials["state"]) == {"COMPLETE"} and trials["point_id"].is_unique
    assert study.metric_names == ["f1", "f2"] and study.user_attrs["cosim_results"] == str(out.resolve())
    merged = table.merge(trials, on="point_id", suffixes=("", "_optuna"))
    assert len(merged) == 24
    np.testing.assert_array_equal(merged["b.x_optuna"], merged["b.x"])
    np.testing.assert_array_equal(merged["b.y_optuna"], merged["b.y"])
    x, y = merged["b.x"].to_numpy(), merged["b.y"].to_numpy()
    np.testing.assert_allclose(merged["f1_optuna"], x ** 2 + y ** 2, rtol=1e-12)  # TwoBowls, by its formula
    np.testing.assert_allclose(merged["f2_optuna"], (x - 2) ** 2 + y ** 2, rtol=1e-12)
    np.testing.assert_allclose(merged["violation"], x ** 2 + y ** 2 - 3, rtol=1e-12, atol=1e-12)
    assert (merged["status_optuna"] == "ok").all()
    # Optuna's own Pareto front of the stored trials (feasible ones only) is cosim's front of the table
    feasible = table[table["feasible"]]
    front = set(feasible.loc[pareto_mask(feasible[["f1", "f2"]].to_numpy(float)), "point_id"])
    assert {t.user_attrs["point_id"] for t in study.best_trials} == front and front
    meta = json.loads((out / "metadata.json").read_text())
    assert meta["runs"][-1]["optuna_storage"] == {"url": url, "study_name": str(out.resolve())}


def test_a_resume_replays_the_whole_run_into_the_storage_once(write_spec, tmp_path):
    """Interrupted after 2 of 4 batches, resumed: the storage holds the 32 trials of the table, none twice."""
    spec = write_spec(bowls_spec(budget=32, batch=8, seed=9))
    out, url = tmp_path / "out", f"sqlite:///{tmp_path / 'study.db'}"
    from cosim.studies.optimize import Optimization

    with pytest.raises(KeyboardInterrupt):
        Optimization(spec, out, quiet=True, storage=url).run(evaluator=FormulaEvaluator(interrupt_at=3))
    assert len(stored_trials(url, str(out.resolve()))[0].query("state == 'COMPLETE'")) == 16
    Optimization(spec, out, quiet=True, resume=True, storage=url).run(evaluator=FormulaEvaluator())
    table = pd.read_parquet(out / "results.parquet")
    trials, _ = stored_trials(url, str(out.resolve()))
    assert len(table) == 32 and len(trials) == 32 and set(trials["state"]) == {"COMPLETE"}
    assert set(trials["point_id"]) == set(table["point_id"])
    by_id = table.set_index("point_id")
    np.testing.assert_array_equal(trials["f1"], by_id.loc[trials["point_id"], "f1"])


def test_storage_mistakes_are_one_line_and_exit_2(write_spec, tmp_path):
    spec = write_spec(bowls_spec(budget=8, batch=8, seed=1))
    env_cmd = [sys.executable, "-m", "cosim.cli.main", "optimize", str(spec)]
    env = {"PYTHONPATH": str(REPO / "src"), "PATH": "/usr/bin:/bin"}
    done = subprocess.run(env_cmd + ["--out", str(tmp_path / "a"), "--storage", "sqlite:////no/such/folder/x.db"],
                          capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert "--storage sqlite:////no/such/folder/x.db: cannot open it" in done.stderr
    assert "check that its folder exists" in done.stderr
    done = subprocess.run(env_cmd + ["--out", str(tmp_path / "b"), "--storage", "nosuchdb://x"],
                          capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 2 and "--storage nosuchdb://x: cannot open it" in done.stderr, done.stderr
    # a study of that name already in the storage: a fresh run does not mix its trials with another run's
    url = f"sqlite:///{tmp_path / 'study.db'}"
    optuna.create_study(storage=url, study_name="shared", directions=["minimize", "minimize"])
    done = subprocess.run(env_cmd + ["--out", str(tmp_path / "c"), "--storage", url, "--study-name", "shared"],
                          capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 2 and "already holds a study named 'shared'" in done.stderr, done.stderr
    assert "optuna delete-study" in done.stderr and "Traceback" not in done.stderr


def test_a_password_in_the_url_is_never_written():
    assert shown_url("postgresql://cosim:s3cret@db.example/studies") == "postgresql://cosim:***@db.example/studies"
    assert shown_url("sqlite:///study.db") == "sqlite:///study.db"
