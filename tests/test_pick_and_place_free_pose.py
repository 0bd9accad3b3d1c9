"""The free-pose optimisation example: its specs are what make_specs.py writes, and they are usable."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np

from orchestrator.design import DesignSpace
from orchestrator.optimize import OptimizeSettings, distributions
from orchestrator.validate import check_spec

FOLDER = Path(__file__).resolve().parents[1] / "examples" / "pick_and_place_free_pose"


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
