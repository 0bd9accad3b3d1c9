"""`cosim report`: a self-contained page whose numbers come from the table; sensitivity measures."""

from __future__ import annotations

import base64
import re

import numpy as np
import pytest

from cosim.analysis.sensitivity import correlation_ratio, spearman
from cosim.analysis.table import load_results
from cosim.cli.main import main
from tests.analysis.test_analysis_table import make_sweep_table
from tests.helpers.reference import pareto_naive


def test_sensitivity_measures_on_known_relations():
    x = np.repeat(np.arange(-5.0, 6.0), 4)
    assert spearman(x, 3 * x + 1) == pytest.approx(1.0)
    assert spearman(x, -np.exp(x)) == pytest.approx(-1.0)
    assert abs(spearman(x, x ** 2)) < 1e-12          # a U-shape has no monotonic trend ...
    assert correlation_ratio(x, x ** 2) == pytest.approx(1.0)  # ... but x explains all of it
    rng = np.random.default_rng(1)
    assert correlation_ratio(x, rng.random(len(x))) < 0.5
    assert np.isnan(spearman(x, np.ones_like(x))) and np.isnan(correlation_ratio(x, np.ones_like(x)))
    # a continuous parameter is binned; y = bin-wise constant is still fully explained
    xc = rng.random(2000)
    assert correlation_ratio(xc, np.sin(6 * xc)) > 0.95


def test_report_holds_counts_extremes_front_influences_and_figures(tmp_path, capsys):
    path = make_sweep_table(tmp_path / "s")
    out = tmp_path / "out" / "report.html"
    assert main(["report", str(path), "-o", str(out)]) == 0
    assert str(out) in capsys.readouterr().out
    text = out.read_text()
    table = load_results(path)
    ok = table.ok_mask()
    # counts by status
    assert re.search(rf"<td class='l'>ok</td><td class=''>{ok.sum()}</td>", text)
    assert re.search(r"<td class='l'>failed</td><td class=''>3</td>", text)
    assert "boom" in text
    # energy's range and the design at its minimum
    e = table.values("energy")
    lo = int(np.nanargmin(e))
    row = re.search(r"<tr><td class='l'>energy</td><td class='l'>J</td><td class=''>([^<]+)</td><td class=''>([^<]+)</td>",
                    text)
    assert row and float(row.group(1)) == pytest.approx(np.nanmin(e), rel=1e-5)
    assert f"point_id={table.df['point_id'][lo]}" in row.group(2)
    # the Pareto front of the spec's objectives (energy, t_exec both minimized)
    front = pareto_naive(np.column_stack([e, table.values("t_exec")]))
    assert f"{front.sum()} non-dominated of {ok.sum()} ok rows" in text
    # reach depends on q4 only: rho = 1 and eta^2 = 1 for q4, eta^2 = 0 for q2
    reach_row = re.search(r"<td class='l'>reach</td><td class=''>([^<]+)</td><td class=''>([^<]+)</td>", text)
    rho2, eta2_q2 = (float(v) for v in reach_row.group(1).split(" / "))
    rho4, eta2_q4 = (float(v) for v in reach_row.group(2).split(" / "))
    assert rho4 == pytest.approx(1.0) and eta2_q4 == pytest.approx(1.0)
    assert abs(rho2) < 0.02 and eta2_q2 < 0.02  # not exactly 0: the 3 failed rows unbalance the grid
    # figures are embedded PNGs: one Pareto figure and one cloud per objective (5)
    images = re.findall(r"src='data:image/png;base64,([A-Za-z0-9+/=]+)'", text)
    assert len(images) == 1 + 5
    assert all(base64.b64decode(i)[:4] == b"\x89PNG" for i in images)
    assert "http" not in text.replace("http-equiv", "")  # nothing fetched from elsewhere


def test_report_without_metadata_still_works(tmp_path):
    path = make_sweep_table(tmp_path / "bare", metadata=False)
    out = tmp_path / "r.html"
    assert main(["report", str(path), "-o", str(out)]) == 0
    text = out.read_text()
    assert "no sweep metadata" in text and "The design parameters are unknown" in text
    # every numeric column but run_time is treated as an objective, with its range
    for column in ("traj.q_via[2]", "energy", "e_el[1]"):
        assert f"<td class='l'>{column}</td>" in text
    assert "<td class='l'>run_time</td>" not in text


def test_report_says_when_an_objective_is_the_same_for_every_design(tmp_path):
    """E.g. `limit_violated` = 1 in every row of the README's main job: a finding the page must state."""
    import pandas as pd

    path = make_sweep_table(tmp_path / "flag")
    df = pd.read_parquet(path)
    df["reach"] = np.where(df["status"] == "ok", 1.0, np.nan)  # a flag set for every ok design
    df.to_parquet(path, index=False)
    out = tmp_path / "r.html"
    assert main(["report", str(path), "-o", str(out)]) == 0
    text = out.read_text()
    ok = int((df["status"] == "ok").sum())
    assert f"<p class='warn'>The same in every ok row ({ok} rows): <code>reach</code> = 1.</p>" in text
    single = make_sweep_table(tmp_path / "one_sense")  # SPEC gives 'energy' and 't_exec' a sense: a front
    assert main(["report", str(single), "-o", str(out)]) == 0 and "Needs two or more" not in out.read_text()


def test_report_front_of_objectives_chosen_on_the_command_line(tmp_path, capsys):
    """`--min/--max` replace the spec's senses: the front is that of the chosen objectives, in their senses."""
    path = make_sweep_table(tmp_path / "s")
    table = load_results(path)
    out = tmp_path / "r.html"
    assert main(["report", str(path), "-o", str(out), "--min", "energy", "--max", "reach"]) == 0
    text = out.read_text()
    values = np.column_stack([table.values("energy"), -table.values("reach")])  # maximize reach = minimize -reach
    front = pareto_naive(values)
    assert f"{front.sum()} non-dominated of {table.ok_mask().sum()} ok rows for minimize energy, maximize reach" \
        in text
    assert front.sum() != pareto_naive(np.column_stack([table.values("energy"), table.values("t_exec")])).sum()
    assert main(["report", str(path), "-o", str(out), "--min", "nonsense"]) == 2
    assert "nonsense" in capsys.readouterr().err


def test_report_shows_paths_relative_or_by_their_last_two_names(tmp_path):
    """Issue 28.12: the page is mailed; an absolute path says where its author's home is, nothing a reader opens."""
    from cosim.analysis.report import shown_path

    assert shown_path(tmp_path / "a" / "spec.json", here=tmp_path) == "a/spec.json"
    assert shown_path("/home/someone/studies/arm/spec.json", here=tmp_path) == "arm/spec.json"
    assert shown_path("examples/arm/spec.json", here=tmp_path) == "examples/arm/spec.json"  # as the user typed it
    assert shown_path("/spec.json", here=tmp_path) == "spec.json"
