"""The decision room's data layer: range filters, Pareto front of chosen objectives, weighted-sum and TOPSIS
rankings, selection, its export and re-run (cosim.analysis.filters, .ranking, .decision, .rerun.rerun_rows)."""

from __future__ import annotations

import io
import itertools
import math
import shlex

import numpy as np
import pandas as pd
import pytest

from cosim.analysis.decision import Decision
from cosim.analysis.ranking import rank_order, topsis, utilities, weighted_sum
from cosim.analysis.rerun import port_groups, rerun_rows
from cosim.analysis.table import AnalysisError, load_results
from cosim.cli.main import main
from tests.analysis.test_analysis_explorer import linear_ode_sweep
from tests.analysis.test_analysis_rerun import objectives_printed
from tests.analysis.test_analysis_table import make_sweep_table

# -- ranking, against the definitions written out loop by loop --------------------------------------------


def topsis_by_the_book(rows, senses, weights):
    """TOPSIS as Hwang and Yoon write it, one number at a time."""
    k = len(senses)
    total = sum(weights)
    w = [x / total for x in weights]
    norms = [math.sqrt(sum(r[j] ** 2 for r in rows)) for j in range(k)]
    v = [[r[j] / norms[j] * w[j] for j in range(k)] for r in rows]
    best = [(max if senses[j] == "max" else min)(row[j] for row in v) for j in range(k)]
    worst = [(min if senses[j] == "max" else max)(row[j] for row in v) for j in range(k)]
    out = []
    for row in v:
        d_plus = math.sqrt(sum((row[j] - best[j]) ** 2 for j in range(k)))
        d_minus = math.sqrt(sum((row[j] - worst[j]) ** 2 for j in range(k)))
        out.append(d_minus / (d_plus + d_minus))
    return out


def test_topsis_matches_the_definition_and_its_extremes():
    rng = np.random.default_rng(3)
    rows = rng.uniform(-5, 20, size=(40, 3))
    senses, weights = ["min", "max", "min"], [0.5, 2.0, 1.0]
    expected = topsis_by_the_book(rows.tolist(), senses, weights)
    assert topsis(rows, senses, weights) == pytest.approx(expected, rel=1e-12)
    # a row best in every objective is the ideal point (closeness 1); one worst in every objective scores 0
    two = np.array([[1.0, 9.0], [3.0, 4.0], [5.0, 1.0]])
    score = topsis(two, ["min", "max"], [1, 1])
    assert score[0] == pytest.approx(1.0) and score[2] == pytest.approx(0.0)
    # a missing value scores NaN and ranks last; the rest is scored among themselves
    with_nan = np.vstack([two, [[np.nan, 3.0]]])
    score = topsis(with_nan, ["min", "max"], [1, 1])
    assert math.isnan(score[3]) and list(rank_order(score)) == [0, 1, 2, 3]


def test_weighted_sum_is_the_weighted_mean_of_scaled_utilities():
    values = np.array([[10.0, 1.0], [20.0, 3.0], [30.0, 2.0], [np.nan, 1.0]])
    u = utilities(values, ["min", "max"])
    assert u[:3].tolist() == [[1.0, 0.0], [0.5, 1.0], [0.0, 0.5]] and np.isnan(u[3]).all()
    score = weighted_sum(values, ["min", "max"], [3.0, 1.0])
    assert score[:3] == pytest.approx([0.75, 0.625, 0.125]) and math.isnan(score[3])
    assert list(rank_order(weighted_sum(values, ["min", "max"], [1.0, 3.0]))) == [1, 2, 0, 3]


@pytest.mark.parametrize("weights, message", [([1, -1], ">= 0"), ([0, 0], "above 0"), ([1], "2 objective")])
def test_ranking_refuses_bad_weights(weights, message):
    with pytest.raises(ValueError, match=message):
        weighted_sum(np.ones((3, 2)), ["min", "min"], weights)


# -- the decision state over a sweep table ---------------------------------------------------------------


def test_filters_front_and_ranking_follow_each_other(tmp_path):
    table = load_results(make_sweep_table(tmp_path / "s"))
    d = Decision(table)
    assert d.objectives == [("energy", "min"), ("t_exec", "min")]
    energy, t_exec = table.values("energy"), table.values("t_exec")
    ok = table.ok_mask()
    assert d.candidates().sum() == ok.sum() == len(table.df) - 3

    def brute_front(rows):
        front = []
        for i in rows:
            dominated = any(energy[j] <= energy[i] and t_exec[j] <= t_exec[i]
                            and (energy[j] < energy[i] or t_exec[j] < t_exec[i]) for j in rows)
            if not dominated:
                front.append(i)
        return front

    assert list(np.flatnonzero(d.pareto())) == brute_front(np.flatnonzero(ok))
    # a filter narrows the candidates; the front is made of the remaining rows only
    q4 = table.values("traj.q_via[4]")
    d.filters.set_range("traj.q_via[4]", 50, 140)
    assert np.array_equal(d.candidates(), ok & (q4 >= 50))
    assert list(np.flatnonzero(d.pareto())) == brute_front(np.flatnonzero(ok & (q4 >= 50)))
    # the ranking: energy alone puts the lowest energy first; t_exec alone the fastest
    d.set_weight("t_exec", 0.0)
    best = d.ranking(3)
    rows = np.flatnonzero(d.candidates())
    assert best[0] == rows[np.argmin(energy[rows])]
    assert energy[best[0]] <= energy[best[1]] <= energy[best[2]]
    d.set_weight("t_exec", 1.0)
    d.set_weight("energy", 0.0)
    assert d.ranking(1)[0] == rows[np.argmin(t_exec[rows])]
    # TOPSIS with both weights agrees with the definition over the candidates
    d.set_weight("energy", 1.0)
    d.set_method("topsis")
    expected = topsis_by_the_book(np.column_stack([energy[rows], t_exec[rows]]).tolist(), ["min", "min"], [1, 1])
    assert d.scores()[rows] == pytest.approx(expected, rel=1e-12)
    assert np.isnan(np.delete(d.scores(), rows)).all()
    assert list(d.ranking()) == list(rows[np.argsort(-np.array(expected), kind="stable")])
    # the radar profile: 1 is the best candidate in that objective, a failed row has none
    profile = d.profile([int(rows[np.argmin(energy[rows])]), 7])
    assert profile[0, 0] == 1.0 and np.isnan(profile[1]).all()


def test_objective_choice_and_mistakes(tmp_path):
    table = load_results(make_sweep_table(tmp_path / "s"))
    d = Decision(table, [("reach", "max")])
    assert d.weights == {"reach": 1.0}
    reach = table.values("reach")
    assert set(np.flatnonzero(d.pareto())) == set(np.flatnonzero(table.ok_mask() & (reach == np.nanmax(reach))))
    with pytest.raises(AnalysisError, match="Did you mean 'reach'"):
        d.set_objectives([("raech", "max")])
    with pytest.raises(AnalysisError, match="neither"):
        d.set_objectives([("reach", "up")])
    with pytest.raises(AnalysisError, match="not one of the objectives"):
        d.set_weight("energy", 1)
    with pytest.raises(AnalysisError, match=">= 0"):
        d.set_weight("reach", -2)
    with pytest.raises(AnalysisError, match="unknown ranking method"):
        d.set_method("ahp")
    d.set_objectives([("energy", "min"), ("reach", "max")])
    assert d.weights == {"energy": 1.0, "reach": 1.0}
    d.set_weight("reach", 0)
    d.set_weight("energy", 0)
    assert np.isnan(d.scores()).all() and d.ranking().size == 0
    assert d.status_counts() == {"ok": len(table.df) - 3, "failed": 3}


def test_selection_exports_as_csv_and_as_run_commands_that_run(tmp_path, write_spec, capsys):
    table = load_results(linear_ode_sweep(tmp_path / "decay", write_spec))
    d = Decision(table)
    d.select([2, 0, 2])
    assert d.selection == [2, 0]
    back = pd.read_csv(io.StringIO(d.selection_csv()))
    assert back["point_id"].tolist() == ["pc", "pa"] and back["y_end"].tolist() == pytest.approx(np.exp([-0.5, -2]))
    with pytest.raises(IndexError):
        d.select([3])
    commands = d.run_commands()
    assert len(commands) == 2 and "--point pc" in commands[0]
    argv = shlex.split(commands[1])
    assert argv[:2] == ["cosim", "run"]
    assert main(argv[1:]) == 0
    assert objectives_printed(capsys.readouterr().out)["y_end"] == pytest.approx(np.exp(-2.0), rel=1e-5)
    traces = pd.read_parquet(tmp_path / "decay" / "points" / "pa.parquet")
    assert traces["ode.y"].iloc[-1] == pytest.approx(np.exp(-2.0), rel=1e-9)


def test_rerun_rows_records_the_specs_signals(tmp_path, write_spec):
    table = load_results(linear_ode_sweep(tmp_path / "decay", write_spec))
    runs = rerun_rows(table, [0, 2])
    assert [r.point_id for r in runs] == ["pa", "pc"]
    for run, a in zip(runs, (-2.0, -0.5)):
        assert run.values == {"ode.a": a} and run.result.status == "ok"
        traces = run.result.traces
        assert list(traces.columns) == ["time", "ode.y"]  # the spec's record list, not every output
        assert traces["ode.y"].to_numpy() == pytest.approx(np.exp(a * traces["time"].to_numpy()), rel=1e-9)
    assert port_groups(["time", "arm.q[1]", "arm.q[2]", "gear.p", "arm.q[3]"]) == \
        [("arm.q", ["arm.q[1]", "arm.q[2]", "arm.q[3]"]), ("gear.p", ["gear.p"])]


def test_rerun_rows_records_every_output_when_the_spec_records_nothing(tmp_path, write_spec):
    path = linear_ode_sweep(tmp_path / "decay", write_spec)
    import json

    meta = json.loads((path.parent / "metadata.json").read_text())
    meta["spec"]["record"] = []
    write_spec(meta["spec"])
    (path.parent / "metadata.json").write_text(json.dumps(meta))
    runs = rerun_rows(load_results(path), [1])
    assert "ode.y" in runs[0].result.traces.columns
    assert runs[0].result.traces["ode.y"].iloc[-1] == pytest.approx(np.exp(-1.0), rel=1e-9)


def test_filters_are_the_explorers(tmp_path):
    from cosim.analysis.explorer import ExplorerState

    table = load_results(make_sweep_table(tmp_path / "s"))
    state, d = ExplorerState(table), Decision(table)
    for lo, hi in itertools.product((-100, -40), (0, 20)):
        state.set_range("traj.q_via[2]", lo, hi)
        d.filters.set_range("traj.q_via[2]", lo, hi)
        assert np.array_equal(state.active(), d.active())


def test_the_room_ranks_on_every_objective_with_a_sense_also_after_an_optimisation(tmp_path):
    """Issue 39.2: an optimisation of one objective whose spec states three with a sense ranks on the three
    (its front and report stay the optimisation's own); a spec objective without a sense is not ranked on."""
    from cosim.analysis.table import ResultsTable

    df = pd.DataFrame({"point_id": ["a", "b", "c"], "x": [1.0, 2.0, 3.0], "cost": [3.0, 2.0, 1.0],
                       "reach[1]": [1.0, 5.0, 2.0], "reach[2]": [0.0, 1.0, 0.5], "mass": [9.0, 8.0, 7.0],
                       "status": "ok"})
    spec = {"objectives": {"cost": {"sense": "minimize"}, "reach": {"sense": "maximize"}, "mass": {"unit": "kg"}},
            "design": {"parameters": {"x": {"min": 0, "max": 4}}}}
    table = ResultsTable(df=df, path=tmp_path / "results.parquet", spec=spec,
                         metadata={"kind": "optimization", "spec": spec,
                                   "optimize": {"objectives": {"cost": "minimize"}}})
    assert table.objective_senses() == {"cost": "min"}
    assert table.sensed_objectives() == {"cost": "min", "reach[1]": "max", "reach[2]": "max"}
    assert Decision(table).objectives == [("cost", "min"), ("reach[1]", "max"), ("reach[2]", "max")]
    table.choose_objectives([("mass", "min")])  # the reader's choice replaces them all
    assert Decision(table).objectives == [("mass", "min")]
