"""Energy-optimal timing along the parabolic blend's path (models/optimal_timing.py).

Every check samples the planned trajectory densely and recomputes what it
claims independently: joint speeds and accelerations from the samples, torques
with pinocchio's RNEA, the electric energy with the thesis's drive equations
as written in tests/models/test_pick_and_place.py (not the planner's own model).
"""

from __future__ import annotations

import functools
import json

import numpy as np
import pinocchio as pin
import pytest

import cosim
from cosim.models.optimal_timing import DriveParameters, TimingInfeasible, plan_optimal_timing
from cosim.models.panda_model import FRANKA_DOC_LIMITS as LIMITS
from cosim.models.panda_model import panda_model, thesis_to_urdf
from cosim.models.trajectory import plan_parabolic_blend
from tests.models.test_pick_and_place import FOLDER, electric_power, thesis_waypoints

DESIGNS = [(-45.0, 70.0), (20.0, 0.0), (-100.0, 0.0), (-100.0, 140.0)]  # thesis q2[2], q2[4] (degrees)
MODES = {"1.25 x the blend's duration": dict(factor=1.25), "energy + 20 J/s x duration": dict(time_weight=20.0)}
DT = 5e-4  # dense sampling (s)


def blend_of(design, factor: float = 1.0):
    """The parabolic blend of a design, with limits scaled so that it lasts ``factor`` times longer."""
    return plan_parabolic_blend(thesis_to_urdf(thesis_waypoints(*design)), LIMITS.qd_max / factor,
                                LIMITS.qdd_max / factor**2)


@functools.lru_cache(maxsize=None)
def planned(design, mode: str):
    blend = blend_of(design)
    options = MODES[mode]
    bound = options["factor"] * blend.duration if "factor" in options else None
    return plan_optimal_timing(blend, panda_model(), LIMITS.qd_max, LIMITS.qdd_max, LIMITS.tau_max,
                               max_duration=bound, time_weight=options.get("time_weight", 0.0))


def dense(trajectory):
    """(qd, qdd, tau, energy) on a dense midpoint grid over the trajectory's duration."""
    model = panda_model()
    data = model.createData()
    times = np.arange(0.0, trajectory.duration, DT) + DT / 2
    q, qd, qdd = trajectory.sample_many(times)
    tau = np.array([pin.rnea(model, data, *x) for x in zip(q, qd, qdd)])
    energy = float(electric_power(tau, qd).sum() * DT)
    return qd, qdd, tau, energy


@pytest.mark.parametrize("mode", list(MODES))
@pytest.mark.parametrize("design", DESIGNS)
def test_every_limit_holds_on_dense_sampling(design, mode):
    qd, qdd, tau, _ = dense(planned(design, mode))
    assert np.all(np.abs(qd) <= LIMITS.qd_max * (1 + 1e-9))
    assert np.all(np.abs(qdd) <= LIMITS.qdd_max * (1 + 1e-6))  # IPOPT's constraint tolerance
    assert np.all(np.abs(tau) <= LIMITS.tau_max)


@pytest.mark.parametrize("mode", list(MODES))
@pytest.mark.parametrize("design", DESIGNS)
def test_at_rest_at_both_ends_and_on_the_blends_path(design, mode):
    timing = planned(design, mode)
    blend = timing.blend
    for t, waypoint in ((0.0, blend.waypoints[0]), (timing.duration, blend.waypoints[-1])):
        q, qd, qdd = timing.sample(t)
        assert q == pytest.approx(waypoint, abs=1e-12) and np.all(qd == 0.0)
    for t in (1e-4, timing.duration - 1e-4):  # the speed goes to zero continuously
        assert np.abs(timing.sample(t)[1]).max() < 1e-2
    # the geometric path is the blend's: every sampled pose is a pose of the blend
    s = [timing.path_state(t)[0] for t in np.linspace(0, timing.duration, 50)]
    for t, s_t in zip(np.linspace(0, timing.duration, 50), s):
        assert timing.sample(t)[0] == pytest.approx(blend.sample(s_t)[0], abs=1e-12)


@pytest.mark.parametrize("design", DESIGNS)
def test_energy_is_never_above_the_blends_at_the_same_duration(design):
    timing = planned(design, "1.25 x the blend's duration")
    slowed = blend_of(design, 1.25)  # the blend uniformly slowed down to 1.25 x its duration
    assert timing.duration <= slowed.duration * (1 + 1e-9)
    # the planner keeps a timing only if its grid model of the energy improves; the dense energy of
    # the grid may differ from the grid's midpoint rule by ~0.05 %: the tolerance
    assert dense(timing)[3] <= dense(slowed)[3] * (1 + 1e-3)
    # at the blend's own duration (its minimum time along the path here) the result is the blend
    at_blend = plan_optimal_timing(blend_of(design), panda_model(), LIMITS.qd_max, LIMITS.qdd_max,
                                   LIMITS.tau_max, max_duration=blend_of(design).duration)
    assert dense(at_blend)[3] <= dense(blend_of(design))[3] * (1 + 1e-3)


def test_drive_model_is_the_energy_units():
    rng = np.random.default_rng(3)
    tau, omega = rng.uniform(-80, 80, (200, 7)), rng.uniform(-2.5, 2.5, (200, 7))
    omega[::10] = 0.0  # standstill under load
    assert DriveParameters().electric_power(tau, omega) == pytest.approx(electric_power(tau, omega), rel=1e-12)


def test_torque_limits_too_low_for_the_path_are_reported():
    with pytest.raises(TimingInfeasible, match="no timing of the path"):
        plan_optimal_timing(blend_of(DESIGNS[0]), panda_model(), LIMITS.qd_max, LIMITS.qdd_max,
                            np.full(7, 5.0), max_duration=3.0)
    with pytest.raises(ValueError, match="time weight"):
        plan_optimal_timing(blend_of(DESIGNS[0]), panda_model(), LIMITS.qd_max, LIMITS.qdd_max, LIMITS.tau_max)


def test_unit_swaps_in_with_one_line_and_saves_energy_in_the_whole_pipeline(tmp_path):
    """The pick-and-place system (energy FMU): optimal timing vs the blend slowed to the same duration."""
    raw = json.loads((FOLDER / "spec_coarse.json").read_text())
    raw.pop("design")
    blend_spec, optimal_spec = tmp_path / "blend.json", tmp_path / "optimal.json"
    factor = 1.25
    raw["units"]["traj"]["parameters"].update(v_max=list(LIMITS.qd_max / factor), a_max=list(LIMITS.qdd_max / factor**2))
    blend_spec.write_text(json.dumps(raw))
    raw["units"]["traj"]["python"] = "models.optimal_timing:OptimalTimingTrajectory"  # the one line
    raw["units"]["traj"]["parameters"].update(v_max=list(LIMITS.qd_max), a_max=list(LIMITS.qdd_max),
                                              max_duration_factor=factor)
    optimal_spec.write_text(json.dumps(raw))
    blend = cosim.run(str(blend_spec), record=False)
    optimal = cosim.run(str(optimal_spec), record=False)
    assert blend.ok and optimal.ok, (blend.message, optimal.message)
    assert optimal.objectives["duration"] <= blend.objectives["duration"] * (1 + 1e-9)
    assert optimal.objectives["e_total"] < blend.objectives["e_total"] * 0.99  # -3.4 % at this design
    assert optimal.objectives["peak_tau_ratio[2]"] <= 1.0


def test_unit_reports_an_infeasible_timing_as_a_failed_run(tmp_path):
    raw = json.loads((FOLDER / "spec_coarse.json").read_text())
    raw.pop("design")
    raw["units"]["traj"]["python"] = "models.optimal_timing:OptimalTimingTrajectory"
    raw["units"]["traj"]["parameters"]["tau_max"] = [5.0] * 7
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps(raw))
    result = cosim.run(str(spec), record=False)
    assert not result.ok and "no timing of the path" in result.message


def test_unit_plays_the_slowed_blend_as_the_reference_when_not_optimizing(tmp_path):
    raw = json.loads((FOLDER / "spec_coarse.json").read_text())
    raw.pop("design")
    raw["units"]["traj"]["python"] = "models.optimal_timing:OptimalTimingTrajectory"
    raw["units"]["traj"]["parameters"].update(max_duration_factor=1.25, optimize=False)
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps(raw))
    result = cosim.run(str(spec), record=False)
    assert result.ok, result.message
    slowed = blend_of((-45.0, 70.0), 1.25)
    assert result.objectives["duration"] == pytest.approx(slowed.duration, rel=1e-12)
    assert result.objectives["duration"] == pytest.approx(1.25 * blend_of((-45.0, 70.0)).duration, rel=1e-12)


def test_study_specs_are_up_to_date_and_validate():
    import importlib.util

    from cosim.spec.design import DesignSpace
    from cosim.spec.loader import load_spec
    from cosim.system.builder import build_system

    folder = FOLDER.parent / "optimal_timing"
    module_spec = importlib.util.spec_from_file_location("make_specs_optimal", folder / "make_specs.py")
    make_specs = importlib.util.module_from_spec(module_spec)
    module_spec.loader.exec_module(make_specs)
    base = json.loads((FOLDER / "spec_coarse.json").read_text())
    full = json.loads((FOLDER / "spec.json").read_text())
    for name, raw in {"spec.json": make_specs.main_study(base), "spec_tradeoff.json": make_specs.tradeoff(base),
                      "spec_full.json": make_specs.main_study(full)}.items():
        assert json.loads((folder / name).read_text()) == raw, f"{name} is stale: run make_specs.py"
        assert list(build_system(load_spec(folder / name)).order) == ["traj", "robot", "energy"]
    assert len(DesignSpace.from_spec(load_spec(folder / "spec.json"))) == 13 * 21 * 2
    assert len(DesignSpace.from_spec(load_spec(folder / "spec_tradeoff.json"))) == 9 * 8 * 2
    assert len(DesignSpace.from_spec(load_spec(folder / "spec_full.json"))) == 121 * 141 * 2
