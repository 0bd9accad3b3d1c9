"""docs/tutorial.md, run as a reader follows it: its Python and JSON blocks saved as the files it names, its
shell block run line by line in an empty folder; the results checked against the physics (static deflection
1/k) and against each other (the SSP round trip)."""

from __future__ import annotations

import shlex

import numpy as np
import pandas as pd

from tests.helpers.paths import REPO
from tests.project.test_docs import fenced_blocks, run_command

TUTORIAL = REPO / "docs" / "tutorial.md"


def test_the_tutorial_runs_as_written_and_its_numbers_hold(tmp_path, monkeypatch):
    # the folder is checked below to hold nothing cosim did not write; Python's own bytecode cache of the reader's
    # spring_damper.py (__pycache__, written wherever PYTHONDONTWRITEBYTECODE is not set) is kept out of it
    monkeypatch.setenv("PYTHONDONTWRITEBYTECODE", "1")
    (python,), (spec,), (shell,) = (fenced_blocks(TUTORIAL, lang) for lang in ("python", "json", "bash"))
    (tmp_path / "spring_damper.py").write_text(python)
    (tmp_path / "spec.json").write_text(spec)
    lines = [line for line in shell.splitlines() if line.strip()]
    assert all(shlex.split(line)[0] == "cosim" for line in lines)
    outputs = {}
    for line in lines:
        done = run_command(line, tmp_path, timeout=900)
        assert done.returncode == 0, (line, done.stdout[-1000:], done.stderr[-2000:])
        outputs[line] = done
    sweep = pd.read_parquet(tmp_path / "results" / "sweep" / "results.parquet")
    assert len(sweep) == 6 and (sweep["status"] == "ok").all()
    # after 6 s (30 actuator time constants, the slowest mass mode decayed to < 1 %) the mass rests at F / k
    np.testing.assert_allclose(sweep["x_end"], 1.0 / sweep["mass.k"], atol=4e-3)
    assert (sweep["overshoot"] >= sweep["x_end"] - 1e-12).all()
    optimized = pd.read_parquet(tmp_path / "results" / "optimize" / "results.parquet")
    assert len(optimized) == 6 and optimized["point_id"].is_unique  # every design once
    assert sorted(zip(optimized["mass.k"], optimized["mass.d"])) == sorted(zip(sweep["mass.k"], sweep["mass.d"]))
    # issue 39: the front is a trade-off (it held 1 of 6 designs with the objectives before): what `cosim pareto`
    # printed is the stiffer spring with each damper, overshoot falling as the damping grows
    front_text = outputs["cosim pareto results/optimize"].stdout
    front = sorted((k, d) for k, d in zip(optimized["mass.k"], optimized["mass.d"])
                   if optimized.loc[(optimized["mass.k"] == k) & (optimized["mass.d"] == d), "point_id"].iloc[0]
                   in front_text)
    assert front == [(8.0, 2.0), (8.0, 4.0), (8.0, 6.0)], front_text
    by_damping = sweep[sweep["mass.k"] == 8.0].sort_values("mass.d")["overshoot"].to_numpy()
    assert (np.diff(by_damping) < 0).all(), by_damping
    one = pd.read_parquet(tmp_path / "results" / "one.parquet")
    again = pd.read_parquet(tmp_path / "results" / "from_ssp.parquet")
    np.testing.assert_allclose(again["mass.x"], one["mass.x"], rtol=0, atol=1e-12)
    assert (tmp_path / "results" / "spring_damper.fmu").stat().st_size > 0
    assert "warning" not in outputs[next(line for line in lines if "--fmi 2" in line)].stderr
    assert set(p.name for p in tmp_path.iterdir()) == {"spring_damper.py", "spec.json", "results"}
