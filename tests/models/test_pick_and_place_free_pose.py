"""The free-pose optimisation example: its specs are what make_specs.py writes, and they are usable."""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest

from cosim.spec.design import DesignSpace
from cosim.studies.optimize import OptimizeSettings, distributions
from cosim.system.validate import check_spec
from tests.helpers.paths import REPO

FOLDER = REPO / "examples" / "pick_and_place_free_pose"


def _make_specs():
    module_spec = importlib.util.spec_from_file_location("make_specs_free_pose", FOLDER / "make_specs.py")
    module = importlib.util.module_from_spec(module_spec)
    module_spec.loader.exec_module(module)
    return module


def test_specs_are_up_to_date_and_valid():
    make = _make_specs()
    base = json.loads(make.BASE.read_text())
    for name, spec in (("spec.json", make.free_pose_spec(base)), ("spec_motor_sobol.json", make.motor_sobol_spec(base))):
        assert json.loads((FOLDER / name).read_text()) == spec, f"{name} is stale: run make_specs.py"
        check_spec(FOLDER / name)


def test_free_pose_dimensions_lie_within_the_joint_limits():
    from cosim.models.panda_model import FRANKA_DOC_LIMITS, thesis_to_urdf

    system = check_spec(FOLDER / "spec.json")
    space = DesignSpace.dimensions_of(system.spec)
    dists = distributions(space)
    assert len(dists) == 8 and dists["traj.velocity_scale"].low == 0.2
    lows = [dists[f"traj.waypoints[{8 + j}]"].low for j in range(7)]
    highs = [dists[f"traj.waypoints[{8 + j}]"].high for j in range(7)]
    # the mapping to URDF angles is affine per joint: both ends of each range inside the limits suffice
    ends = np.sort(np.vstack([thesis_to_urdf(lows), thesis_to_urdf(highs)]), axis=0)
    assert (ends[0] >= FRANKA_DOC_LIMITS.q_min).all() and (ends[1] <= FRANKA_DOC_LIMITS.q_max).all(), ends
    settings = OptimizeSettings.from_spec(system.spec)
    assert settings.objectives == {"e_total": "minimize", "duration": "minimize"}
    assert settings.constraints == ["peak_tau_ratio <= 1"]


def test_the_committed_optimisation_opens_in_every_analysis_command(tmp_path, capsys):
    """An optimisation's folder is a sweep folder: report, pareto, plot, the explorer and run --point work on it
    unchanged, and the re-run of the least-energy feasible design gives the table's energy again."""
    import pandas as pd

    from cosim.analysis.explorer import ExplorerState
    from cosim.analysis.table import load_results
    from cosim.cli.main import main

    folder = FOLDER / "results_optimize"
    df = pd.read_parquet(folder / "results.parquet")
    usable = df[(df["status"] == "ok") & df["feasible"]]
    best = usable.loc[usable["e_total"].idxmin()]
    assert main(["report", str(folder), "-o", str(tmp_path / "report.html")]) == 0
    assert "<h2>Optimisation</h2>" in (tmp_path / "report.html").read_text()
    assert main(["pareto", str(folder), "--csv", str(tmp_path / "front.csv")]) == 0
    front = pd.read_csv(tmp_path / "front.csv")
    assert front["feasible"].all() and best["point_id"] in set(front["point_id"])  # least energy is on the front
    assert main(["plot", str(folder), "--x", "duration", "--y", "e_total", "--color", "traj.velocity_scale",
                 "-o", str(tmp_path / "front.png")]) == 0
    assert (tmp_path / "front.png").stat().st_size > 10_000
    state = ExplorerState(load_results(folder))
    assert {state.x, state.y} <= set(df.columns)
    capsys.readouterr()
    assert main(["run", str(FOLDER / "spec.json"), "--point", best["point_id"], "--results", str(folder),
                 "--out", str(tmp_path / "best.parquet")]) == 0
    out = capsys.readouterr().out
    e_total = float(next(line.split()[1] for line in out.splitlines() if line.startswith("e_total ")))
    assert e_total == pytest.approx(best["e_total"], rel=1e-5)  # printed with 6 digits
