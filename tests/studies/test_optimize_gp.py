"""cosim optimize --sampler gp: Optuna's Gaussian-process sampler (PyTorch) on real Dask, and its absence.

PyTorch is in the test extra (cosim[gp]), so under CI the GP test runs; elsewhere, without torch, it is skipped
with that reason (and fails under CI=true, where a missing tool is a broken install).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from cosim.analysis.hypervolume import hypervolume, normalised_losses
from cosim.analysis.pareto import pareto_mask
from cosim.cli.main import main
from tests.helpers.paths import REPO
from tests.studies.test_optimize import bowls_spec


def _torch_or_skip() -> None:
    try:
        import torch  # noqa: F401
    except ImportError:
        if os.environ.get("CI") == "true":
            pytest.fail("PyTorch is missing under CI: .ci/run installs it with the test extra (cosim[gp])")
        pytest.skip("PyTorch is not installed (pip install -e '.[gp]')")


def test_gp_sampler_finds_the_known_front_under_a_constraint(write_spec, tmp_path, local_cluster):
    """TwoBowls (front: y = 0, 0 <= x <= 2) with f1 <= 2: after 16 random start-up designs the GP's 16
    proposals lie near the constrained front, far nearer than the random ones."""
    _torch_or_skip()
    spec = write_spec(bowls_spec(budget=32, batch=8, seed=3, constraints=["f1 <= 2"]))
    out = tmp_path / "out"
    assert main(["optimize", str(spec), "--sampler", "gp", "--out", str(out), "--scheduler", local_cluster]) == 0
    df = pd.read_parquet(out / "results.parquet")
    assert len(df) == 32 and (df["status"] == "ok").all() and set(df["sampler"]) == {"gp"}
    assert json.loads((out / "metadata.json").read_text())["optimize"]["sampler"] == "gp"
    # the objectives and feasibility, recomputed from the parameters
    x, y = df["b.x"].to_numpy(), df["b.y"].to_numpy()
    np.testing.assert_allclose(df["f1"], x ** 2 + y ** 2, rtol=1e-12)
    np.testing.assert_array_equal(df["feasible"], x ** 2 + y ** 2 <= 2)
    # Optuna's GPSampler draws its first designs at random (n_startup_trials = 10: the first two batches of 8);
    # distance of a design from the constrained front's designs (y = 0, 0 <= x <= sqrt(2))
    distance = np.hypot(np.clip(x, 0.0, np.sqrt(2.0)) - x, y)
    random_part, gp_part = distance[:16], distance[16:]
    assert np.median(gp_part) < 0.1, gp_part
    assert np.median(gp_part) < 0.25 * np.median(random_part), (gp_part, random_part)
    assert df["feasible"].iloc[16:].mean() >= 0.75  # the GP models the constraint as well
    # the front found: within 0.05 of the true constrained front and >= 90 % of its hypervolume (scaled to it)
    usable = df["feasible"].to_numpy()
    values = df.loc[usable, ["f1", "f2"]].to_numpy(float)
    front = values[pareto_mask(values)]
    f1 = np.linspace(0, 2, 4001)
    true = np.column_stack([f1, (2 - np.sqrt(f1)) ** 2])
    scale = dict(senses=["min", "min"], ideal=true.min(axis=0), nadir=true.max(axis=0))
    scaled_true = normalised_losses(true, **scale)
    gap = np.min(np.linalg.norm(normalised_losses(front, **scale)[:, None] - scaled_true[None], axis=2), axis=1)
    assert gap.max() < 0.05, gap
    assert hypervolume(normalised_losses(front, **scale)) >= 0.9 * hypervolume(scaled_true)


# Run in a fresh interpreter whose import system refuses torch, as if it were not installed.
_WITHOUT_TORCH = """
import importlib.abc, sys

class NoTorch(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "torch" or name.startswith("torch."):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None

sys.meta_path.insert(0, NoTorch())
from cosim.cli.main import main
sys.exit(main(sys.argv[1:]))
"""


def test_gp_without_pytorch_is_exit_2_with_the_fix(write_spec, tmp_path):
    spec = write_spec(bowls_spec(budget=8))
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-c", _WITHOUT_TORCH, "optimize", str(spec), "--sampler", "gp",
                           "--out", str(out), "--workers", "1"],
                          env={**os.environ, "PYTHONPATH": str(REPO)}, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stderr
    assert "the gp sampler needs PyTorch" in done.stderr and "cosim[gp]" in done.stderr
    assert "Traceback" not in done.stderr
    assert not (out / "results.parquet").exists() and not list(out.glob("parts/*.parquet"))
