"""Exact pruning from the command line: `cosim sweep --prune` exits 0 with pruned rows (a result, not a failure),
report, pareto and plot show them as their own class, `cosim run --point ID` runs a pruned design to its end."""

from __future__ import annotations

import json
import shutil

import pandas as pd
import pytest

from cosim.cli.main import main
from tests.helpers.paths import REPO

EXAMPLE = REPO / "examples" / "drive_energy"


@pytest.fixture(scope="module")
def pruned_study(tmp_path_factory):
    folder = tmp_path_factory.mktemp("drive_cli")
    raw = json.loads((EXAMPLE / "spec.json").read_text())
    raw["objectives"]["energy_no_recuperation"].update(monotone="non-decreasing", sense="minimize")
    raw["objectives"]["energy"].pop("sense")
    raw["design"]["parameters"]["energy.gear_ratio"] = {"min": 50, "max": 160, "step": 22, "unit": "1"}
    (folder / "spec.json").write_text(json.dumps(raw))
    shutil.copy(EXAMPLE / "drive_profile.py", folder)
    return folder


def test_sweep_prune_exits_0_and_says_what_pruned_rows_are(pruned_study, capsys):
    code = main(["sweep", str(pruned_study / "spec.json"), "--out", str(pruned_study / "out"), "--workers", "2",
                 "--prune"])
    out, err = capsys.readouterr()
    table = pd.read_parquet(pruned_study / "out" / "results.parquet")
    n = int((table["status"] == "pruned").sum())
    assert code == 0 and n > 0
    assert f"{n} pruned: proven off the front; their objective columns hold bounds" in out
    assert "pruned:" not in err  # not listed as a problem


def test_report_pareto_and_plot_show_pruned_rows_as_their_own_class(pruned_study, capsys, tmp_path):
    out = pruned_study / "out"
    n = int((pd.read_parquet(out / "results.parquet")["status"] == "pruned").sum())
    assert main(["report", str(out), "-o", str(tmp_path / "r.html")]) == 0
    html = (tmp_path / "r.html").read_text()
    assert f"{n} pruned row(s)" in html and "<em>bounds</em>" in html
    capsys.readouterr()
    assert main(["pareto", str(out)]) == 0
    assert f"{n} pruned rows: proven dominated while running" in capsys.readouterr().out
    assert main(["plot", str(out), "--x", "energy_no_recuperation", "--y", "peak_power", "-o",
                 str(tmp_path / "p.png")]) == 0
    said = capsys.readouterr().out
    assert f"({n} pruned rows among the greyed" in said


def test_run_point_runs_a_pruned_design_to_its_end(pruned_study, capsys, tmp_path):
    out = pruned_study / "out"
    table = pd.read_parquet(out / "results.parquet")
    row = table[table["status"] == "pruned"].iloc[0]
    code = main(["run", str(pruned_study / "spec.json"), "--point", row["point_id"], "--results", str(out),
                 "--out", str(tmp_path / "trace.csv")])
    said = capsys.readouterr().out
    assert code == 0, said
    trace = pd.read_csv(tmp_path / "trace.csv")
    assert trace["time"].iloc[-1] == pytest.approx(2.5)  # to its end, not to where it was pruned
    assert row["pruned_at"] < 2.5


def test_optimize_prune_tells_pruned_trials_to_optuna_as_pruned(pruned_study, tmp_path):
    import optuna

    from cosim.studies.optimize import Optimization

    storage = f"sqlite:///{tmp_path / 'optuna.db'}"
    counts = Optimization(pruned_study / "spec.json", tmp_path / "opt", budget=12, batch=4, sampler="nsga2", seed=3,
                       workers=2, quiet=True, prune=True, storage=storage, study_name="s").run()
    table = pd.read_parquet(tmp_path / "opt" / "results.parquet")
    assert sum(counts.values()) == len(table) == 12
    study = optuna.load_study(study_name="s", storage=storage)
    states = {t.user_attrs["point_id"]: t.state for t in study.trials}
    for _, row in table.iterrows():
        expected = optuna.trial.TrialState.PRUNED if row["status"] == "pruned" else optuna.trial.TrialState.COMPLETE
        assert states[row["point_id"]] == expected
    assert set(table["status"]) <= {"ok", "pruned"}
    assert (table["status"] == "pruned").sum() > 0, "batches after the first prune against its front"
