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
from tests.helpers.paths import REPO
from tests.studies.test_optimize import FormulaEvaluator, bowls_spec


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


# The points pause while the study folder's file "pause" exists: the runs must still be running while the
# others are refused; once that is checked the test removes it and the rest of the budget runs without sleeping
SLOW_UNIT = """
import os, time
from cosim import PythonUnit, Variable

class SlowSquare(PythonUnit):
    variables = (Variable("x", "parameter", start=0.0), Variable("pause", "parameter", start=0.0),
                 Variable("y", "output", start=0.0))

    def do_step(self, t, h):
        if os.path.exists(GATE):
            time.sleep(self.pause)
        self.y = self.x ** 2
"""


def _slow_spec(folder, budget: int, pause: float):
    (folder / "slow.py").write_text(SLOW_UNIT.replace("GATE", repr(str(folder / "pause"))))
    (folder / "pause").touch()
    spec = {"name": "slow", "units": {"s": {"python": "slow.py:SlowSquare", "parameters": {"pause": pause}}},
            "experiment": {"stop": 1.0, "step": 1.0},
            "objectives": {"y": {"signal": "s.y", "reduce": "final", "sense": "minimize"}},
            "design": {"parameters": {"s.x": {"min": -1.0, "max": 1.0}}},
            "optimize": {"budget": budget, "batch": 2, "seed": 4}}
    path = folder / "spec.json"
    path.write_text(json.dumps(spec))
    return path


def _optimize(spec, out, url, *more: str, wait: bool = True):
    command = [sys.executable, "-m", "cosim.cli.main", "optimize", str(spec), "--out", str(out), "--storage", url,
               "--study-name", "shared", "--workers", "1", "-q", *more]
    env = {"PYTHONPATH": str(REPO / "src"), "PATH": "/usr/bin:/bin", "HOME": str(out.parent)}
    if wait:
        return subprocess.run(command, capture_output=True, text=True, timeout=300, env=env)
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def _wait_for_lock(url: str, proc) -> None:
    """Until the running optimisation holds the study's lock (its lock study is in the storage)."""
    import time

    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            if "cosim-lock:shared" in optuna.get_all_study_names(url):
                return
        except Exception:  # noqa: BLE001 - the database not created yet
            pass
        time.sleep(0.05)
    raise AssertionError(f"the first run never took the lock (exit {proc.poll()}): {proc.communicate()[1][-2000:]}")


def _trials(url: str) -> tuple[list[int], list]:
    """The numbers and point ids of the study's trials, in order."""
    trials = optuna.load_study(study_name="shared", storage=url).trials
    return [t.number for t in trials], [t.user_attrs.get("point_id") for t in trials]


def _refused(done, url: str) -> None:
    assert done.returncode == 2, (done.returncode, done.stderr)
    assert "Traceback" not in done.stderr, done.stderr
    message = done.stderr.strip().splitlines()[-1]
    assert f"--storage {url}: the study 'shared' is in use by another cosim optimize (pid " in message, message
    assert "Wait for that run to finish, or give this one another --study-name" in message, message
    assert "optuna delete-study" in message and "'cosim-lock:shared'" in message, message


def _wait_for_trials(url: str, proc, count: int) -> None:
    import time

    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if len(_trials(url)[0]) >= count:
            return
        time.sleep(0.05)
    raise AssertionError(f"the run did not reach {count} trials (exit {proc.poll()})")


def test_two_optimisers_on_one_storage_study_the_second_is_refused(tmp_path):
    """Issue 38.5: real `cosim optimize` processes, one SQLite file, one study: while one runs, a second (fresh or
    --resume, into another folder or the same) is refused; the study then holds the one run's trials only, each
    trial number once (two runs had written 28 trials, a table 13 rows for a budget of 12)."""
    import signal

    spec = _slow_spec(tmp_path, budget=10, pause=1.5)
    url = f"sqlite:///{tmp_path / 'study.db'}"
    first = _optimize(spec, tmp_path / "a", url, wait=False)
    try:
        _wait_for_lock(url, first)
        _refused(_optimize(spec, tmp_path / "b", url), url)  # a fresh run into another folder, same study
        assert first.poll() is None, "the first run ended before the second was refused: make its points slower"
        _wait_for_trials(url, first, 2)
        first.send_signal(signal.SIGINT)  # interrupted: to be resumed below
    finally:
        _, err = first.communicate(timeout=300)
    assert first.returncode == 130, err
    assert not (tmp_path / "b" / "results.parquet").exists()
    assert optuna.get_all_study_names(url) == ["shared"]  # the lock went with the run
    resumed = _optimize(spec, tmp_path / "a", url, "--resume", wait=False)
    try:
        _wait_for_lock(url, resumed)
        _refused(_optimize(spec, tmp_path / "b", url, "--resume"), url)  # another folder's resume, same study
        same = _optimize(spec, tmp_path / "a", url, "--resume")  # the same folder's: refused by the folder lock
        assert same.returncode == 2 and "is in use by another cosim optimize (pid" in same.stderr, same.stderr
        assert "Traceback" not in same.stderr
        assert resumed.poll() is None, "the resumed run ended before the others were refused"
        (tmp_path / "pause").unlink()  # refused while it ran: the rest of its budget needs no pause
    finally:
        _, err = resumed.communicate(timeout=300)
    assert resumed.returncode == 0, err
    numbers, ids = _trials(url)
    table = pd.read_parquet(tmp_path / "a" / "results.parquet")
    assert len(table) == 10 and numbers == list(range(10)) and sorted(ids) == sorted(table["point_id"])
    assert not (tmp_path / "b" / "results.parquet").exists()


def test_a_killed_optimiser_leaves_its_study_to_the_next_run(tmp_path):
    """kill -9 leaves the lock in the storage: on the same host the next run sees its holder gone and takes it."""
    import signal
    import time

    spec = _slow_spec(tmp_path, budget=8, pause=0.4)
    url = f"sqlite:///{tmp_path / 'study.db'}"
    first = _optimize(spec, tmp_path / "a", url, wait=False)
    _wait_for_lock(url, first)
    time.sleep(1.0)
    first.kill()
    first.communicate(timeout=60)
    assert first.returncode == -signal.SIGKILL
    assert "cosim-lock:shared" in optuna.get_all_study_names(url)  # left behind
    (tmp_path / "pause").unlink()  # the next run only has to take the lock and finish the budget
    done = _optimize(spec, tmp_path / "a", url, "--resume")
    assert done.returncode == 0, done.stderr
    assert optuna.get_all_study_names(url) == ["shared"]
    numbers, ids = _trials(url)
    assert numbers == list(range(8)) and sorted(ids) == sorted(pd.read_parquet(tmp_path / "a" / "results.parquet")
                                                                ["point_id"])


OPEN_AT = """
import sys, time
from cosim.studies.optuna_storage import open_storage_study
time.sleep(max(0.0, float(sys.argv[2]) - time.time()))  # both processes open at the same moment
open_storage_study(sys.argv[1], sys.argv[3], ["minimize"], ["y"], None, False, sys.argv[3])
print("opened")
"""


def test_two_runs_creating_one_new_database_both_open_it(tmp_path):
    """Two processes creating the tables of one new SQLite file at the same moment: the loser's UNIQUE-constraint
    failure was reported as a bad URL ("cannot open it ... give a database URL Optuna can open"); both open it now
    (3 new files, 2 processes each)."""
    import time

    env = {"PYTHONPATH": str(REPO / "src"), "PATH": "/usr/bin:/bin"}
    for k in range(3):
        url = f"sqlite:///{tmp_path / f'new{k}.db'}"
        at = str(time.time() + 2.0)
        runs = [subprocess.Popen([sys.executable, "-c", OPEN_AT, url, at, f"s{j}"], stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True, env=env) for j in range(2)]
        outcomes = [(p.wait(timeout=120), p.stdout.read(), p.stderr.read()[-1500:]) for p in runs]
        assert [(code, said.strip()) for code, said, _ in outcomes] == [(0, "opened")] * 2, outcomes
        assert sorted(optuna.get_all_study_names(url)) == ["s0", "s1"]
