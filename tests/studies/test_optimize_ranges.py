"""Continuous ranges ``{min, max}`` for ``cosim optimize`` with no ``optimize`` section, and ``cosim validate``
checking what the chosen study runs (issue 28, item 4).

Before, a range without ``step`` made ``cosim optimize`` refuse the spec ("a grid needs a 'step'") unless an
undocumented empty ``"optimize": {}`` was added, and then ``cosim validate`` refused it with an unrelated fix.
"""

from __future__ import annotations

import json
import shutil

import pytest

import cosim
from cosim.cli.main import main
from tests.helpers.paths import REPO

EXAMPLE = REPO / "examples" / "drive_energy"
RANGES = {"energy.gear_ratio": {"min": 50.0, "max": 160.0}, "drive.duration": {"min": 1.0, "max": 2.0, "unit": "s"}}


def _spec(folder, **extra):
    shutil.copy(EXAMPLE / "drive_profile.py", folder)
    spec = json.loads((EXAMPLE / "spec.json").read_text())
    spec["experiment"].update(stop=2.2, step=0.01)
    spec["design"] = {"parameters": RANGES}
    spec.update(extra)
    path = folder / "spec.json"
    path.write_text(json.dumps(spec))
    return path


def test_validate_checks_the_design_for_the_study_named(tmp_path, capsys):
    spec = _spec(tmp_path)
    assert main(["validate", str(spec)]) == 2  # a sweep's grid needs steps: said, with the way out
    err = capsys.readouterr().err
    assert "$.design.parameters.energy.gear_ratio: a grid needs a 'step' for each range" in err
    assert "cosim validate SPEC --for optimize" in err
    for study in ("optimize", "sensitivity"):
        assert main(["validate", str(spec), "--for", study]) == 0
        assert f"design checked for cosim {study}" in capsys.readouterr().out


def test_validate_for_optimize_refuses_what_optimize_refuses(tmp_path, capsys):
    spec = _spec(tmp_path, optimize={"constraints": ["peak_power <= nonsense"], "sampler": "annealing"})
    assert main(["validate", str(spec)]) == 2  # the optimize section chooses the study
    err = capsys.readouterr().err
    assert "$.optimize.sampler: 'annealing' is not allowed" in err  # the schema's check
    spec = _spec(tmp_path, optimize={"constraints": ["peak_power <= nonsense"]})
    assert main(["validate", str(spec), "--for", "optimize"]) == 2
    err = capsys.readouterr().err
    assert "$.optimize.constraints[0]: unknown name(s) in 'peak_power <= nonsense': nonsense" in err
    with pytest.raises(cosim.SpecError, match="nonsense"):
        cosim.optimize(spec, tmp_path / "out", budget=2)


def test_validate_for_sensitivity_refuses_a_constraint(tmp_path, capsys):
    spec = _spec(tmp_path)
    raw = json.loads(spec.read_text())
    raw["design"]["constraint"] = "drive.duration > 1.2"
    spec.write_text(json.dumps(raw))
    assert main(["validate", str(spec), "--for", "sensitivity"]) == 2
    assert "$.design.constraint: a sensitivity study samples the whole box" in capsys.readouterr().err


def test_optimize_draws_continuous_ranges_without_an_optimize_section(tmp_path, local_cluster):  # noqa: F811
    spec = _spec(tmp_path)
    assert "optimize" not in json.loads(spec.read_text())
    df = cosim.optimize(spec, tmp_path / "out", budget=4, batch=2, sampler="random", seed=3,
                        scheduler=local_cluster, quiet=True)
    assert len(df) == 4 and (df["status"] == "ok").all(), df["message"].tolist()
    ratios, durations = df["energy.gear_ratio"], df["drive.duration"]
    assert ratios.between(50.0, 160.0).all() and durations.between(1.0, 2.0).all()
    assert (ratios % 1 != 0).all()  # drawn from the continuum, not a grid of whole numbers
    row = df.iloc[0]  # its objective is the one a single run of the same design gives
    alone = cosim.run(str(spec), {"energy.gear_ratio": float(row["energy.gear_ratio"]),
                                  "drive.duration": float(row["drive.duration"])})
    assert alone.objectives["energy"] == pytest.approx(row["energy"], rel=1e-12)
