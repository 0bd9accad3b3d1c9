"""cosim sensitivity on real Dask: Sobol indices of the Ishigami function against their analytic values,
Morris elementary effects of a linear function, the report and the command line."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pandas as pd
import pytest

from cosim.cli.main import main
from cosim.studies.sensitivity import SensitivityStudy
from tests.helpers.tools import python_unit

A, B = 7.0, 0.1


def ishigami_indices() -> dict[tuple[str, str], float]:
    """Analytic first-order and total Sobol indices of the Ishigami function on [-pi, pi]^3."""
    pi = math.pi
    v1 = 0.5 * (1 + B * pi ** 4 / 5) ** 2
    v2 = A ** 2 / 8
    v13 = B ** 2 * pi ** 8 * (1 / 18 - 1 / 50)
    v = v1 + v2 + v13
    return {("b.x1", "S1"): v1 / v, ("b.x2", "S1"): v2 / v, ("b.x3", "S1"): 0.0,
            ("b.x1", "ST"): (v1 + v13) / v, ("b.x2", "ST"): v2 / v, ("b.x3", "ST"): v13 / v}


def ishigami_spec(bounds: float = math.pi) -> dict:
    box = {"min": -bounds, "max": bounds}
    return {
        "name": "ishigami",
        "units": {"b": {"python": python_unit("Ishigami"), "parameters": {"a": A, "b": B}}},
        "experiment": {"stop": 1.0, "step": 1.0},
        "objectives": {"y": {"signal": "b.y", "reduce": "final"}, "lin": {"signal": "b.lin", "reduce": "final"}},
        "design": {"method": "lhs", "samples": 10, "parameters": {"b.x1": box, "b.x2": box, "b.x3": box}},
    }


def test_ishigami_sobol_indices_lie_within_their_confidence_intervals(write_spec, tmp_path, local_cluster):
    spec = write_spec(ishigami_spec())
    study = SensitivityStudy(spec, tmp_path / "out", method="sobol", n=512, seed=2, objectives=["y"],
                             scheduler=local_cluster, quiet=True)
    counts, indices = study.run()
    assert counts["ok"] == 512 * 5  # Saltelli: n * (D + 2) runs for first-order and total indices
    table = pd.read_parquet(tmp_path / "out" / "results.parquet")
    x1, x2, x3 = (table[f"b.x{i}"].to_numpy() for i in (1, 2, 3))
    np.testing.assert_allclose(table["y"], np.sin(x1) + A * np.sin(x2) ** 2 + B * x3 ** 4 * np.sin(x1), rtol=1e-12)
    for (parameter, index), expected in ishigami_indices().items():
        row = indices[(indices["parameter"] == parameter) & (indices["index"] == index)].iloc[0]
        assert 0 < row["conf"] < 0.15, row  # a confidence interval narrow enough to mean something (S1, ST ~ 0.3-0.6)
        assert abs(row["value"] - expected) <= row["conf"], (parameter, index, row["value"], expected, row["conf"])
    written = pd.read_csv(tmp_path / "out" / "sensitivity.csv")
    assert len(written) == 6 and set(written["index"]) == {"S1", "ST"}
    assert (tmp_path / "out" / "sensitivity.png").stat().st_size > 5000
    meta = json.loads((tmp_path / "out" / "metadata.json").read_text())
    assert meta["kind"] == "sensitivity" and meta["sensitivity"]["samples"] == 2560
    assert main(["report", str(tmp_path / "out"), "-o", str(tmp_path / "r.html")]) == 0
    page = (tmp_path / "r.html").read_text()
    assert "Sensitivity indices" in page and "b.x3" in page and "data:image/png;base64" in page
    # issue 28.12: the indices come right after the overview, before the status and the (for the Panda: 70-row)
    # objective tables; the page names the spec without the author's absolute path
    headings = re.findall(r"<h2>([^<(]+)", page)
    assert headings[:4] == ["Table", "Sensitivity indices ", "Status", "Objectives"], headings
    assert str(spec) not in page and str(tmp_path) not in page
    assert f"<td class='l'>spec_path</td><td class='l'>{spec.parent.name}/spec.json</td>" in page


def test_morris_elementary_effects_of_a_linear_function(write_spec, tmp_path, local_cluster, capsys):
    spec = write_spec(ishigami_spec(bounds=1.0))
    code = main(["sensitivity", str(spec), "--method", "morris", "-n", "10", "--objective", "lin",
                 "--out", str(tmp_path / "m"), "--scheduler", local_cluster])
    assert code == 0
    indices = pd.read_csv(tmp_path / "m" / "sensitivity.csv")
    mu = indices[indices["index"] == "mu_star"].set_index("parameter")["value"]
    sigma = indices[indices["index"] == "sigma"].set_index("parameter")["value"]
    # lin = 3 x1 + x2 on [-1, 1]^3: every elementary effect (per unit of the scaled [0, 1] range) is 6, 2, 0
    assert mu["b.x1"] == pytest.approx(6.0) and mu["b.x2"] == pytest.approx(2.0) and mu["b.x3"] == pytest.approx(0.0)
    assert np.allclose(sigma, 0.0, atol=1e-9)
    assert "mu_star" in capsys.readouterr().out


def test_design_constraint_and_unknown_objective_are_exit_2(write_spec, tmp_path, capsys):
    spec_dict = ishigami_spec()
    spec_dict["design"]["constraint"] = "b_x1 < b_x2"
    spec = write_spec(spec_dict)
    assert main(["sensitivity", str(spec), "--out", str(tmp_path / "a")]) == 2
    assert "$.design.constraint" in capsys.readouterr().err
    spec = write_spec(ishigami_spec(), "b.json")
    assert main(["sensitivity", str(spec), "--objective", "energy", "--out", str(tmp_path / "b")]) == 2
    assert "not an objective" in capsys.readouterr().err


def test_sobol_indices_from_too_small_a_sample_come_with_a_warning_naming_n(write_spec, tmp_path, local_cluster,
                                                                            capsys):  # noqa: F811
    """Issue 28: `cosim sensitivity -n 8` printed indices of 1.21 and -0.31 without a word."""
    spec = write_spec(ishigami_spec())
    code = main(["sensitivity", str(spec), "-n", "8", "--objective", "y", "--out", str(tmp_path / "s"),
                 "--scheduler", local_cluster])
    assert code == 0
    err = capsys.readouterr().err
    indices = pd.read_csv(tmp_path / "s" / "sensitivity.csv")
    outside = indices[(indices["value"] < -0.05) | (indices["value"] > 1.05)]
    assert len(outside) or (indices["conf"] > 0.25).any()  # what 40 runs give for the Ishigami function
    assert "cosim: warning: Sobol indices with n = 8 are not reliable" in err and "larger -n" in err
    for row in outside.itertuples():
        assert f"{row.index} of {row.parameter} for y = {row.value:.2f}" in err or len(outside) > 3


def test_no_warning_for_indices_within_their_bounds():
    from cosim.studies.sensitivity import unreliable_indices

    rows = [{"objective": "y", "parameter": p, "index": i, "value": v, "conf": c}
            for p, i, v, c in [("b.x1", "S1", 0.31, 0.05), ("b.x1", "ST", 0.56, 0.06), ("b.x2", "S1", 0.44, 0.04),
                               ("b.x3", "S1", -0.01, 0.03), ("b.x3", "ST", 0.24, 0.05)]]
    assert unreliable_indices(pd.DataFrame(rows), "sobol", 512) == ""
    rows[0]["value"] = 1.21
    assert "S1 of b.x1 for y = 1.21" in unreliable_indices(pd.DataFrame(rows), "sobol", 8)
    assert unreliable_indices(pd.DataFrame(rows), "morris", 8) == ""  # mu* and sigma have no bound


def test_a_sensitivity_folder_is_of_kind_sensitivity_from_its_first_row(write_spec, tmp_path, local_cluster):
    """Its metadata said 'sensitivity' only once finished while its rows and its resume check said 'sweep': a
    finished study could not be resumed ("holds sensitivity results, not sweep results") and a sweep could resume
    into an interrupted one. Now the kind is 'sensitivity' from the start, in metadata.json and in every file of
    rows, and a resume accepts that kind only."""
    import pyarrow.parquet as pq

    from cosim.results.store import IDENTITY_KEY
    from cosim.studies.sweep import Sweep, SweepError

    spec = write_spec(ishigami_spec())
    out = tmp_path / "out"
    options = dict(method="morris", n=4, seed=3, objectives=["y"], scheduler=local_cluster, quiet=True)
    first, _ = SensitivityStudy(spec, out, **options).run()
    table = pq.read_table(out / "results.parquet")
    assert json.loads(table.schema.metadata[IDENTITY_KEY])["kind"] == "sensitivity"
    again, indices = SensitivityStudy(spec, out, resume=True, **options).run()  # all points stored: none run
    assert again == first and first["ok"] == len(pd.read_parquet(out / "results.parquet")) > 0
    assert json.loads((out / "metadata.json").read_text())["kind"] == "sensitivity"
    with pytest.raises(SweepError, match="holds sensitivity results, not sweep results"):
        Sweep(spec, out=out, scheduler=local_cluster, resume=True, quiet=True)
