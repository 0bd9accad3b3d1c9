"""Results tables: loading with and without metadata, units and labels, --where filters, Pareto fronts."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cosim.analysis.pareto import pareto_mask
from cosim.analysis.table import AnalysisError, identifier, load_results
from cosim.cli.main import main
from tests.helpers.reference import pareto_naive

SPEC = {
    "name": "toy",
    "units": {},
    "objectives": {
        "energy": {"signal": "e.e", "reduce": "final", "unit": "J", "sense": "minimize"},
        "t_exec": {"signal": "c.t", "reduce": "final", "unit": "s", "sense": "minimize"},
        "e_el": {"signal": "e.e_el", "reduce": "final", "unit": "Ws"},
        "reach": {"signal": "c.r", "reduce": "max", "unit": "m"},
    },
    "design": {"parameters": {"traj.q_via[2]": {"min": -100, "max": 20, "step": 1, "unit": "deg"},
                              "traj.q_via[4]": {"min": 0, "max": 140, "step": 1, "unit": "deg"}}},
}


def make_sweep_table(folder: Path, n2: int = 13, n4: int = 15, metadata: bool = True, failed: int = 3) -> Path:
    """A sweep-like folder: a grid of two angles, smooth objectives, ``failed`` rows without values."""
    folder.mkdir(parents=True, exist_ok=True)
    q2, q4 = np.meshgrid(np.linspace(-100, 20, n2), np.linspace(0, 140, n4), indexing="ij")
    q2, q4 = q2.ravel(), q4.ravel()
    energy = 20 + 0.004 * (q2 - 0) ** 2 + 0.003 * q4 ** 2
    t_exec = 1.3 + 0.8 * np.exp(-((q2 + 50) ** 2 + (q4 - 70) ** 2) / 4000)
    df = pd.DataFrame({
        "point_id": [f"p{i:05d}" for i in range(len(q2))],
        "traj.q_via[2]": q2, "traj.q_via[4]": q4,
        "energy": energy, "t_exec": t_exec, "e_el[1]": energy * 0.3, "e_el[2]": energy * 0.5,
        "reach": 0.5 + q4 / 1000,
        "status": "ok", "message": "", "run_time": 0.1 + q4 / 1000, "worker": "w1",
    })
    for i in range(failed):
        row = 7 + 11 * i
        df.loc[row, ["energy", "t_exec", "e_el[1]", "e_el[2]", "reach"]] = np.nan
        df.loc[row, "status"] = "failed"
        df.loc[row, "message"] = "boom"
    df.to_parquet(folder / "results.parquet", index=False)
    if metadata:
        (folder / "metadata.json").write_text(json.dumps({"spec": SPEC, "spec_digest": "x" * 64,
                                                          "counts": {"ok": len(df) - failed, "failed": failed}}))
    return folder / "results.parquet"


def test_load_with_metadata_gives_units_senses_and_roles(tmp_path):
    table = load_results(make_sweep_table(tmp_path / "sweep").parent)
    assert len(table.df) == 13 * 15
    assert table.label("traj.q_via[2]") == "traj.q_via[2] [deg]"
    assert table.label("e_el[2]") == "e_el[2] [Ws]"
    assert table.label("run_time") == "run_time [s]"
    assert table.objective_senses() == {"energy": "min", "t_exec": "min"}
    assert table.objective_columns() == ["energy", "t_exec", "e_el[1]", "e_el[2]", "reach"]
    assert table.parameter_columns() == ["traj.q_via[2]", "traj.q_via[4]"]
    assert "status" not in table.numeric_columns() and "energy" in table.numeric_columns()
    assert table.ok_mask().sum() == 13 * 15 - 3


def test_any_table_without_metadata_or_as_csv(tmp_path):
    path = make_sweep_table(tmp_path / "bare", metadata=False)
    csv = tmp_path / "t.csv"
    pd.read_parquet(path).to_csv(csv, index=False)
    for source in (path, csv):
        table = load_results(source)
        assert table.spec is None and table.label("energy") == "energy"
        assert table.objective_senses() == {}
        assert np.isnan(table.values("energy")).sum() == 3


def test_where_maps_names_and_combines_columns(tmp_path):
    table = load_results(make_sweep_table(tmp_path / "s"))
    assert identifier("traj.q_via[2]") == "traj_q_via_2" and identifier("e_el[1]") == "e_el_1"
    q2, q4 = table.values("traj.q_via[2]"), table.values("traj.q_via[4]")
    mask = table.where("traj_q_via_2 > -50 and traj_q_via_4 <= 70 or e_el_1 > 1e9")
    assert np.array_equal(mask, (q2 > -50) & (q4 <= 70))
    chained = table.where("-50 < traj_q_via_2 <= 0")
    assert np.array_equal(chained, (q2 > -50) & (q2 <= 0))
    assert np.array_equal(table.where("not (traj_q_via_4 > 10)"), ~(q4 > 10))
    # the names as the table writes them
    assert np.array_equal(table.where("traj.q_via[2] > -50 and traj.q_via[4] <= 70 or e_el[1] > 1e9"), mask)
    assert np.array_equal(table.where("traj.q_via[2] < traj.q_via[4] - 100"), q2 < q4 - 100)
    with pytest.raises(AnalysisError, match=r"unknown name 'traj.q_via\[3\]'.*known: .*traj.q_via\[2\]"):
        table.where("traj.q_via[3] > 0")
    # a missing value never passes a comparison
    assert not table.where("energy > 0")[~table.ok_mask()].any()
    assert table.where(None).all()


@pytest.mark.parametrize("text, fragment", [
    ("enrgy < 3", "Did you mean 'energy'?"),
    ("energy <", "cannot parse"),
    ("__import__('os')", "unknown function"),
])
def test_where_mistakes_are_clear(tmp_path, text, fragment):
    table = load_results(make_sweep_table(tmp_path / "s"))
    with pytest.raises(AnalysisError, match=None) as err:
        table.where(text)
    assert fragment in str(err.value)


def test_unknown_column_and_missing_file_exit_2_without_traceback(tmp_path, capsys):
    path = make_sweep_table(tmp_path / "s")
    assert main(["plot", str(path), "--x", "energi", "--y", "t_exec", "-o", str(tmp_path / "f.png")]) == 2
    err = capsys.readouterr().err
    assert "no column 'energi'" in err and "Did you mean 'energy'?" in err and "Traceback" not in err
    assert main(["pareto", str(tmp_path / "nothing.parquet"), "--min", "energy"]) == 2
    assert "no such results table" in capsys.readouterr().err
    assert main(["plot", str(path), "--x", "energy", "--y", "t_exec", "-o", str(tmp_path / "f.jpg")]) == 2
    assert "use a .png, .svg or .pdf" in capsys.readouterr().err


# -- Pareto ---------------------------------------------------------------------

def test_pareto_hand_made_front_with_ties_and_nan():
    v = np.array([
        [1.0, 5.0],     # 0 front
        [2.0, 3.0],     # 1 front
        [2.0, 3.0],     # 2 tie with 1: front too
        [3.0, 3.0],     # 3 dominated by 1 (equal f2, worse f1)
        [4.0, 1.0],     # 4 front
        [np.nan, 0.0],  # 5 NaN: excluded, and does not dominate 4
        [0.5, np.nan],  # 6 NaN: excluded, and does not dominate 0
        [5.0, 1.0],     # 7 dominated by 4
        [1.0, 6.0],     # 8 dominated by 0 (equal f1)
        [6.0, 0.5],     # 9 front
    ])
    expected = np.array([1, 1, 1, 0, 1, 0, 0, 0, 0, 1], dtype=bool)
    assert np.array_equal(pareto_mask(v), expected)
    assert np.array_equal(pareto_naive(v), expected)
    # maximizing the negated values is the same problem
    assert np.array_equal(pareto_mask(-v, ["max", "max"]), expected)
    # a third objective that is constant changes nothing (general k path)
    v3 = np.column_stack([v, np.full(len(v), 7.0)])
    assert np.array_equal(pareto_mask(v3), expected)


def test_pareto_mixed_senses_and_one_objective():
    v = np.array([[1.0, 1.0], [2.0, 2.0], [2.0, 0.0], [np.nan, 9.0]])
    # minimize f1, maximize f2: row 1 (2,2) is dominated by nothing with f1<=2 and f2>=2 other than itself
    assert pareto_mask(v, ["min", "max"]).tolist() == [True, True, False, False]
    assert pareto_mask(v[:, :1]).tolist() == [True, False, False, False]
    assert pareto_mask(np.array([[3.0], [3.0], [4.0]])).tolist() == [True, True, False]
    with pytest.raises(ValueError, match="unknown sense"):
        pareto_mask(v, ["min", "up"])


@pytest.mark.parametrize("k", [2, 3, 4])
def test_pareto_matches_the_pairwise_reference_on_random_data_with_ties(k):
    rng = np.random.default_rng(k)
    v = rng.integers(0, 6, size=(300, k)).astype(float)  # few levels: many ties
    v[rng.random(300) < 0.05, 0] = np.nan
    assert np.array_equal(pareto_mask(v), pareto_naive(v))
    senses = ["min", "max"] * k
    assert np.array_equal(pareto_mask(v, senses[:k]), pareto_naive(v, senses[:k]))


def test_pareto_of_a_large_table():
    """Correct on 200k rows (its time is measured by benchmarks/analysis_speed.py, not asserted here)."""
    rng = np.random.default_rng(0)
    v = rng.random((200_000, 2))
    mask = pareto_mask(v)
    # spot check: no front point is dominated by any other point
    front = v[mask]
    for p in front[:20]:
        assert not np.any(np.all(v <= p, axis=1) & np.any(v < p, axis=1))
    v3 = rng.random((17_061, 3))
    mask3 = pareto_mask(v3)
    for p in v3[mask3][:20]:
        assert not np.any(np.all(v3 <= p, axis=1) & np.any(v3 < p, axis=1))


def test_pareto_cli_uses_spec_senses_table_and_csv(tmp_path, capsys):
    path = make_sweep_table(tmp_path / "s")
    table = load_results(path)
    ok = table.ok_mask()
    expected = pareto_naive(np.column_stack([table.values("energy"), table.values("t_exec")]))
    assert main(["pareto", str(path), "--csv", str(tmp_path / "front.csv")]) == 0
    out = capsys.readouterr().out
    assert f"Pareto front (min energy, min t_exec): {expected.sum()} of {ok.sum()} rows" in out
    front = pd.read_csv(tmp_path / "front.csv")
    assert sorted(front["point_id"]) == sorted(table.df["point_id"][expected])
    assert "traj.q_via[2]" in out.splitlines()[1]
    # --where narrows the rows considered; --max flips a sense
    assert main(["pareto", str(path), "--min", "energy", "--max", "reach", "--where", "traj_q_via_4 >= 70"]) == 0
    out = capsys.readouterr().out
    sub = (table.values("traj.q_via[4]") >= 70) & ok
    v = np.column_stack([table.values("energy"), table.values("reach")])
    v[~sub] = np.nan
    assert f"Pareto front (min energy, max reach): {pareto_naive(v, ['min', 'max']).sum()} of {sub.sum()} rows" in out


def test_pareto_without_senses_asks_for_objectives(tmp_path, capsys):
    path = make_sweep_table(tmp_path / "bare", metadata=False)
    assert main(["pareto", str(path)]) == 2
    assert "--min OBJ" in capsys.readouterr().err


def test_pareto_of_a_large_table_with_its_pivot_prefilter(monkeypatch):
    """Above PREFILTER_ABOVE rows the rows a few pivots dominate are dropped first: the front is the same as the
    pairwise reference's, ties, infinities, NaN and mixed senses included (the threshold lowered so the reference
    stays fast)."""
    from cosim.analysis import pareto

    monkeypatch.setattr(pareto, "PREFILTER_ABOVE", 50)
    rng = np.random.default_rng(4)
    for k, senses in ((2, ["min", "max"]), (3, ["min", "min", "max"])):
        v = rng.integers(0, 6, (400, k)).astype(float)
        v[::17, 0] = np.inf
        v[::23, -1] = np.nan
        v[5] = v[6]  # a tie
        expected = pareto_naive(v, senses)
        assert 0 < expected.sum() < len(v)
        assert np.array_equal(pareto_mask(v, senses), expected)
