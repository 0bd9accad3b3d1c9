"""Energy-optimal timing of a path given as samples (models/sampled_path.py + models/optimal_timing.py).

A straight line in joint space has a timing known in closed form: with loose torque limits the
minimum time under joint speed and acceleration limits is bang-coast-bang along the line, with the
path speed and acceleration limited by the most demanding joint.  The planner with a large weight on
time must find that duration; with a duration bound and no weight on time its energy (recomputed
independently on dense samples) must not exceed that of the same bang-coast-bang profile slowed down to the bound.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pinocchio as pin
import pytest

import cosim
from cosim.models.optimal_timing import plan_optimal_timing
from cosim.models.panda_model import FRANKA_DOC_LIMITS as LIMITS
from cosim.models.panda_model import panda_model, thesis_to_urdf
from cosim.models.sampled_path import SampledPath
from cosim.models.trajectory import plan_parabolic_blend
from tests.models.test_pick_and_place import FOLDER, electric_power, thesis_waypoints

Q0 = np.array([0.0, -0.6, 0.0, -2.2, 0.0, 1.6, 0.8])
DELTA = np.array([0.9, 0.35, -0.5, 0.7, 0.4, -0.6, 1.0])
LOOSE_TORQUE = LIMITS.tau_max * 100  # torque limits that cannot bind
DT = 5e-4


def line_samples(m: int = 11) -> np.ndarray:
    return Q0 + np.linspace(0.0, 1.0, m)[:, None] * DELTA


def bang_coast_bang(v_max, a_max):
    """Minimum time along the line (fraction sigma in [0, 1]) and the path speed/acceleration limits."""
    speed = np.min(v_max / np.abs(DELTA))
    acceleration = np.min(a_max / np.abs(DELTA))
    if speed**2 / acceleration >= 1.0:  # no cruise: a triangle
        return 2.0 * np.sqrt(1.0 / acceleration), np.sqrt(acceleration), acceleration
    return 1.0 / speed + speed / acceleration, speed, acceleration


def bang_coast_bang_samples(times, v_max, a_max):
    """q, qd, qdd of the bang-coast-bang motion along the line at ``times``."""
    total, speed, acc = bang_coast_bang(v_max, a_max)
    ramp = speed / acc
    t = np.clip(np.asarray(times), 0.0, total)
    sigma = np.where(t < ramp, 0.5 * acc * t**2,
                     np.where(t < total - ramp, 0.5 * acc * ramp**2 + speed * (t - ramp),
                              1.0 - 0.5 * acc * (total - t) ** 2))
    rate = np.where(t < ramp, acc * t, np.where(t < total - ramp, speed, acc * (total - t)))
    accel = np.where(t < ramp, acc, np.where(t < total - ramp, 0.0, -acc))
    return Q0 + sigma[:, None] * DELTA, rate[:, None] * DELTA, accel[:, None] * DELTA


def dense(times, q, qd, qdd):
    model = panda_model()
    data = model.createData()
    tau = np.array([pin.rnea(model, data, *x) for x in zip(q, qd, qdd)])
    return tau, float(electric_power(tau, qd).sum() * DT)


def test_a_straight_line_in_time_is_bang_coast_bang():
    path = SampledPath.from_samples(line_samples(), v_max=LIMITS.qd_max)
    assert path.sample(0.37 * path.duration)[0] == pytest.approx(Q0 + 0.37 * DELTA, abs=1e-12)  # stays straight
    timing = plan_optimal_timing(path, panda_model(), LIMITS.qd_max, LIMITS.qdd_max, LOOSE_TORQUE,
                                 time_weight=1e5)
    minimum, _, _ = bang_coast_bang(LIMITS.qd_max, LIMITS.qdd_max)
    # the grid (60 intervals, b linear on each) meets the switching points only approximately
    assert timing.duration == pytest.approx(minimum, rel=1e-3)  # seen: 1.5e-4
    assert timing.duration >= minimum * (1 - 1e-6)  # never faster than the limits allow
    times = np.arange(0.0, timing.duration, DT) + DT / 2
    q, qd, qdd = timing.sample_many(times)
    assert np.all(np.abs(qd) <= LIMITS.qd_max * (1 + 1e-9))
    assert np.all(np.abs(qdd) <= LIMITS.qdd_max * (1 + 1e-6))
    # on the line, at rest at both ends (the samples' path does not start at rest: s_dot does)
    sigma = (q - Q0) @ DELTA / (DELTA @ DELTA)
    assert q == pytest.approx(Q0 + sigma[:, None] * DELTA, abs=1e-12)
    for t in (0.0, timing.duration):
        assert np.all(timing.sample(t)[1] == 0.0)
    assert np.abs(timing.sample(1e-4)[1]).max() < 1e-2 and np.abs(timing.sample(timing.duration - 1e-4)[1]).max() < 1e-2


def test_a_straight_line_at_a_duration_bound_spends_no_more_than_bang_coast_bang():
    path = SampledPath.from_samples(line_samples(), v_max=LIMITS.qd_max)
    minimum, _, _ = bang_coast_bang(LIMITS.qd_max, LIMITS.qdd_max)
    factor = 1.4
    timing = plan_optimal_timing(path, panda_model(), LIMITS.qd_max, LIMITS.qdd_max, LIMITS.tau_max,
                                 max_duration=factor * minimum)
    assert timing.duration <= factor * minimum * (1 + 1e-9)
    times = np.arange(0.0, timing.duration, DT) + DT / 2
    q, qd, qdd = timing.sample_many(times)
    tau, energy = dense(times, q, qd, qdd)
    assert np.all(np.abs(tau) <= LIMITS.tau_max)
    # the reference: bang-coast-bang slowed down to the bound (speeds / f, accelerations / f^2)
    slow_times = np.arange(0.0, factor * minimum, DT) + DT / 2
    _, reference = dense(slow_times, *bang_coast_bang_samples(slow_times, LIMITS.qd_max / factor,
                                                              LIMITS.qdd_max / factor**2))
    assert energy <= reference * (1 + 1e-3)


def test_bad_samples_are_reported():
    with pytest.raises(ValueError, match="m x 7"):
        SampledPath.from_samples(np.zeros((5, 6)), v_max=LIMITS.qd_max)
    with pytest.raises(ValueError, match="two distinct samples"):
        SampledPath.from_samples(np.zeros((5, 7)), v_max=LIMITS.qd_max)
    with pytest.raises(ValueError, match="increase"):
        SampledPath.from_samples(line_samples(3), s=[0.0, 0.5, 0.25])


def test_a_recorded_event_two_rows_at_one_time_is_refused_with_the_time_and_the_fix(tmp_path):
    q = line_samples(4)
    times = [1.0, 1.5, 1.5, 2.0]  # an event at 1.5 s: the row before it and the row after it
    with pytest.raises(ValueError, match=r"two different samples at path parameter \(time\) 1\.5.*one row per time"):
        SampledPath.from_samples(q, s=times)
    table = pd.DataFrame({"time": times, **{f"traj.q_ref[{j + 1}]": q[:, j] for j in range(7)}})
    table.to_csv(tmp_path / "recorded.csv", index=False)
    with pytest.raises(ValueError, match=r"recorded\.csv: two different samples at path parameter \(time\) 1\.5"):
        SampledPath.from_table(tmp_path / "recorded.csv")
    # the fix the message names: one row per time (the last) gives a path through the three rows kept
    table.drop_duplicates("time", keep="last").to_csv(tmp_path / "fixed.csv", index=False)
    path = SampledPath.from_table(tmp_path / "fixed.csv")
    assert np.array_equal(path.s, [0.0, 0.5, 1.0])
    assert np.allclose(path.waypoints, q[[0, 2, 3]], rtol=1e-12, atol=0)  # through CSV text: to an ulp


def recorded_blend(tmp_path, design=(-45.0, 70.0)):
    """The blend of a pick-and-place design as a recorded table (10 ms, the player's column names)."""
    blend = plan_parabolic_blend(thesis_to_urdf(thesis_waypoints(*design)), LIMITS.qd_max, LIMITS.qdd_max)
    times = np.append(np.arange(0.0, blend.duration, 0.01), blend.duration)
    q = blend.sample_many(times)[0]
    table = pd.DataFrame({"time": times, **{f"traj.q_ref[{j + 1}]": q[:, j] for j in range(7)}})
    table.to_parquet(tmp_path / "recorded.parquet")
    return blend, tmp_path / "recorded.parquet"


def test_unit_re_times_a_recorded_path_in_the_whole_pipeline(tmp_path):
    blend, recorded = recorded_blend(tmp_path)
    raw = json.loads((FOLDER / "spec_coarse.json").read_text())
    raw.pop("design")
    raw["units"]["traj"]["python"] = "models.optimal_timing:OptimalTimingTrajectory"
    raw["units"]["traj"]["parameters"].update(path_file=str(recorded), max_duration_factor=1.25)
    results = {}
    for optimize in (True, False):
        raw["units"]["traj"]["parameters"]["optimize"] = optimize
        spec = tmp_path / f"spec_{optimize}.json"
        spec.write_text(json.dumps(raw))
        results[optimize] = cosim.run(str(spec), record=False)
        assert results[optimize].ok, results[optimize].message
    # the samples' own timing is the blend's: the reference is the blend slowed down to 1.25 x
    assert results[False].objectives["duration"] == pytest.approx(1.25 * blend.duration, rel=1e-9)
    assert results[True].objectives["duration"] <= 1.25 * blend.duration * (1 + 1e-9)
    assert results[True].objectives["e_total"] < results[False].objectives["e_total"] * 0.99
    assert results[True].objectives["peak_tau_ratio[2]"] <= 1.0


def test_unit_reports_a_table_without_the_path_columns(tmp_path):
    _, recorded = recorded_blend(tmp_path)
    raw = json.loads((FOLDER / "spec_coarse.json").read_text())
    raw.pop("design")
    raw["units"]["traj"]["python"] = "models.optimal_timing:OptimalTimingTrajectory"
    raw["units"]["traj"]["parameters"].update(path_file=str(recorded), path_columns="robot.q")
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps(raw))
    result = cosim.run(str(spec), record=False)
    assert not result.ok and "no column 'robot.q[1]'" in result.message and "recorded.parquet" in result.message
