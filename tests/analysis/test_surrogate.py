"""`cosim surrogate`: surrogates fitted on known functions predict new designs, rank the parameters that matter,
locate the failures, survive the trip through models.json, and the command refuses bad input with exit 2."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from cosim.analysis.surrogate import fit_table, read, write
from cosim.analysis.surrogate.fit import fit_gp, fit_objective, q_squared
from cosim.analysis.table import load_results
from cosim.cli.main import main

PARAMETERS = ["u.a", "u.b", "u.c"]  # u.c has no effect on any objective


def smooth(x):
    return np.sin(3 * x[:, 0]) + x[:, 1] ** 2


def quadratic(x):
    return 1 + 2 * x[:, 0] - 3 * x[:, 0] * x[:, 1] + x[:, 1] ** 2


def make_study(folder, n=60, seed=3):
    """A results folder as a sweep writes it: parameters a in [0,1], b in [0,2], c in [-1,1]; designs with
    a > 0.85 failed (no objective values)."""
    rng = np.random.default_rng(seed)
    x = rng.random((n, 3)) * [1, 2, 2] - [0, 0, 1]
    failed = x[:, 0] > 0.85
    df = pd.DataFrame(x, columns=PARAMETERS)
    df["smooth"] = np.where(failed, np.nan, smooth(x))
    df["quadratic"] = np.where(failed, np.nan, quadratic(x))
    df["status"] = np.where(failed, "failed", "ok")
    folder.mkdir(parents=True)
    df.to_parquet(folder / "results.parquet")
    spec = {"name": "known", "objectives": {"smooth": {"signal": "u.y", "reduce": "final"},
                                            "quadratic": {"signal": "u.z", "reduce": "final"}},
            "design": {"parameters": {p: {"values": [0, 1]} for p in PARAMETERS}}}
    (folder / "metadata.json").write_text(json.dumps({"spec": spec}))
    return folder, x, failed


def test_gp_numbers_reproduce_scikit_learn_and_predict_new_designs():
    from sklearn.gaussian_process import GaussianProcessRegressor

    rng = np.random.default_rng(0)
    x = rng.random((50, 3)) * [1, 2, 2] - [0, 0, 1]
    model = fit_gp(x, smooth(x), "matern52")
    fresh = rng.random((200, 3)) * [1, 2, 2] - [0, 0, 1]
    assert q_squared(smooth(fresh), model.predict(fresh)[0]) > 0.99
    # the stored numbers are scikit-learn's predictor: refit with the fitted kernel, same mean and std
    from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

    kernel = ConstantKernel(model.constant) * Matern(model.length_scales, nu=2.5) + WhiteKernel(model.noise)
    z = model.scaling.inputs(x)
    gp = GaussianProcessRegressor(kernel, alpha=0.0, optimizer=None).fit(
        z, (smooth(x) - model.scaling.y_mean) / model.scaling.y_scale)
    mean, std = gp.predict(model.scaling.inputs(fresh), return_std=True)
    ours = model.predict(fresh)
    # (to 1e-7: the refit's kernel parameters went through sklearn's log/exp once more, and K is near singular)
    np.testing.assert_allclose(ours[0], mean * model.scaling.y_scale + model.scaling.y_mean, rtol=1e-7, atol=1e-9)
    # a small std is the root of a difference of two near-equal numbers: compared in absolute terms
    np.testing.assert_allclose(ours[1], std * model.scaling.y_scale, rtol=1e-6, atol=1e-7)
    # uncertain far from the designs, sure at them
    assert model.predict(x[:5])[1].max() < 0.2 * model.predict(np.array([[3.0, 5.0, 4.0]]))[1][0]


def test_auto_recovers_a_quadratic_and_reports_what_it_tried():
    rng = np.random.default_rng(1)
    x = rng.random((40, 3))
    result = fit_objective(x, quadratic(x), "poly")
    assert result.candidate == "poly 2" or result.q2 > 0.999999
    assert result.q2 > 0.99999
    fresh = rng.random((30, 3))
    np.testing.assert_allclose(result.model.predict(fresh)[0], quadratic(fresh), atol=1e-4)
    assert set(result.tried) <= {f"poly {d}" for d in range(1, 7)} and result.tried["poly 1"] < 0.99
    auto = fit_objective(x, quadratic(x), "auto")
    assert {"gp matern32", "gp matern52", "poly 2"} <= set(auto.tried)
    assert auto.q2 == max(auto.tried.values())


def test_table_surrogates_rank_locate_failures_and_round_trip(tmp_path):
    folder, x, failed = make_study(tmp_path / "study")
    surrogates = fit_table(load_results(folder), method="auto")
    assert surrogates.parameters == PARAMETERS and list(surrogates.objectives) == ["smooth", "quadratic"]
    for name, f in (("smooth", smooth), ("quadratic", quadratic)):
        s = surrogates.objectives[name]
        assert s.rows == int((~failed).sum())
        assert s.fitted.q2 > 0.99
        ranking = {i.parameter: i for i in s.ranking}
        assert ranking["u.c"].total < 0.01 and s.ranking[-1].parameter == "u.c"
    # smooth: b^2 over [0, 2] varies more than sin(3a) over the fitted a range: b ranks first
    assert surrogates.objectives["smooth"].ranking[0].parameter == "u.b"
    fails = surrogates.failures
    assert fails is not None and fails.failed == int(failed.sum()) and fails.balanced_accuracy > 0.85
    p = fails.probability(np.array([[0.98, 1.0, 0.0], [0.1, 1.0, 0.0]]))
    assert p[0] > 0.8 and p[1] < 0.2
    stored = write(surrogates, folder / "surrogate")
    again = read(stored)
    designs = pd.DataFrame(np.random.default_rng(5).random((20, 3)), columns=PARAMETERS)
    pd.testing.assert_frame_equal(surrogates.predict(designs), again.predict(designs), check_exact=True)
    summary = pd.read_csv(stored / "summary.csv")
    assert list(summary["objective"]) == ["smooth", "quadratic"]
    assert summary["q2"].tolist() == pytest.approx([s.fitted.q2 for s in surrogates.objectives.values()])
    for row, s in zip(summary.to_dict("records"), surrogates.objectives.values()):
        for i in s.ranking:  # each parameter's Q²: Q² x its total index
            assert row[f"Q2[{i.parameter}]"] == pytest.approx(s.fitted.q2 * i.total, abs=1e-12)


def test_command_fits_predicts_and_refuses_bad_input(tmp_path, capsys):
    folder, _, _ = make_study(tmp_path / "study")
    assert main(["surrogate", str(folder), "--objective", "quadratic", "--method", "poly"]) == 0
    out = capsys.readouterr().out
    assert "quadratic" in out and "poly 2" in out and "u.c" in out and "balanced accuracy" in out
    assert (folder / "surrogate" / "models.json").is_file() and (folder / "surrogate" / "summary.csv").is_file()
    # cosim report shows them: Q², ranking, the predicted-vs-simulated figure
    stored = read(folder / "surrogate").objectives["quadratic"]
    assert main(["report", str(folder), "-o", str(tmp_path / "report.html")]) == 0
    page = (tmp_path / "report.html").read_text()
    section = page[page.index("<h2>Surrogates and their prognosis quality</h2>"):]
    assert f"<td class='l'>quadratic</td><td class=''>poly 2</td><td class=''>{stored.fitted.q2:.6g}</td>" in section
    assert "u.a " in section and "alt='figure'" in section.split("<h2>")[1]
    assert "Q² of the parameter" in section and f"({stored.fitted.q2 * stored.ranking[0].total:.2f})" in section
    assert len(stored.fitted.simulated) == len(stored.fitted.cross_validated) == stored.rows
    designs = tmp_path / "designs.csv"
    pd.DataFrame({"u.a": [0.2, 0.5], "u.b": [1.0, 0.5], "u.c": [0.0, 0.3]}).to_csv(designs, index=False)
    predicted = tmp_path / "predicted.csv"
    assert main(["surrogate", str(folder), "--predict", str(designs), "-o", str(predicted)]) == 0
    table = pd.read_csv(predicted)
    x = table[PARAMETERS].to_numpy()
    np.testing.assert_allclose(table["quadratic"], quadratic(x), atol=1e-3)
    assert (table["quadratic_std"] > 0).all() and table["p_fail"].between(0, 1).all()
    capsys.readouterr()

    def refused(argv, *words):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "Traceback" not in err
        for word in words:
            assert word in err, (word, err)

    refused(["surrogate", str(folder), "--objective", "quadratc"], "quadratc", "quadratic")
    refused(["surrogate", str(folder), "-o", str(predicted)], "-o", "--predict")
    refused(["surrogate", str(folder), "--predict", str(designs)], "--predict needs -o")
    refused(["surrogate", str(folder), "--predict", str(tmp_path / "none.csv"), "-o", str(predicted)], "none.csv")
    pd.DataFrame({"u.a": [0.2], "u.b": [1.0]}).to_csv(tmp_path / "short.csv", index=False)
    refused(["surrogate", str(folder), "--predict", str(tmp_path / "short.csv"), "-o", str(predicted)],
            "short.csv", "'u.c'", "u.a, u.b, u.c")
    pd.DataFrame({"u.a": [0.2], "u.b": ["x"], "u.c": [0.0]}).to_csv(tmp_path / "text.csv", index=False)
    refused(["surrogate", str(folder), "--predict", str(tmp_path / "text.csv"), "-o", str(predicted)],
            "row 1", "'u.b'")
    refused(["surrogate", str(tmp_path / "missing")], "missing")
    other, _, _ = make_study(tmp_path / "other")
    refused(["surrogate", str(other), "--predict", str(designs), "-o", str(predicted)], "cosim surrogate")
    (tmp_path / "other" / "metadata.json").unlink()
    refused(["surrogate", str(other)], "--spec")


def test_q2_of_a_parameter_is_its_drop_of_q2_for_an_additive_objective(tmp_path):
    """Q² x ST per parameter against what it stands for on an additive objective: Q² of the surrogate with
    every parameter minus Q² of one refitted (5-fold) without that parameter."""
    from cosim.analysis.surrogate.ranking import parameter_q2, sobol_ranking

    rng = np.random.default_rng(7)
    x = rng.random((400, 3))
    y = 3 * x[:, 0] + x[:, 1] + 0.05 * rng.standard_normal(400)  # ST about 0.9, 0.1, 0
    full = fit_objective(x, y, "poly")
    ranking = {i.parameter: i for i in sobol_ranking(full.model, ["a", "b", "c"])}
    for j, name in enumerate(["a", "b", "c"]):
        without = fit_objective(np.delete(x, j, axis=1), y, "poly")
        assert parameter_q2(full.q2, ranking[name]) == pytest.approx(full.q2 - without.q2, abs=0.03)
    assert parameter_q2(full.q2, ranking["a"]) > 0.85 and parameter_q2(full.q2, ranking["c"]) < 0.01
    assert math.isnan(parameter_q2(float("nan"), ranking["a"]))
