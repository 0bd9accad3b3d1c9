"""A hand-written vectorised evaluation of one inverse-dynamics pick-and-place point.

The yardstick for the cost of a co-simulated point (issue 16): the same point of
``examples/pick_and_place/spec.json`` computed without co-simulation, with numpy
over the whole time grid at once and pinocchio per sample, at the same 10 ms
sampling and with the same outputs (every objective of the spec):

- the parabolic-blend trajectory (planned by ``models.trajectory.plan_parabolic_blend``,
  the planner the unit uses) sampled on the grid as the unit's ``step_midpoint``
  sampling does: position and velocity at each step's middle, acceleration the
  step's mean ``(qd(t_k) - qd(t_k-1)) / h``;
- joint torques by RNEA and the TCP by forward kinematics (pinocchio, per sample);
- the motor/gear energy model of ``fmus/motor_gear_energy`` (thesis eq. 7-13..7-19)
  in numpy, integrated as the FMU does (inputs held over a step, ``E += p h``);
- the objectives reduced as the spec says (trapezoid integrals over the
  communication points, finals, extremes, the overshoot correction).

``evaluate_point(q22, q24)`` returns the objectives by the names of the sweep's
table; ``tests/execution/test_pick_and_place_reference.py`` checks they agree with cosim's.

Run ``python benchmarks/pick_and_place_reference.py`` to time it against cosim's
point, interleaved (see pick_and_place_reference.md).
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from cosim.models.panda_model import FRANKA_DOC_LIMITS, N_JOINTS, cached_model, ee_frame_id, thesis_to_urdf
from cosim.models.trajectory import plan_parabolic_blend

STEP = 0.01  # s, the spec's communication step
STOP = 10.0  # s, the spec's stop time (the run ends earlier, when the trajectory has finished)

# the motor_gear_energy FMU's default parameters (fmus/motor_gear_energy/model.json)
GEAR_RATIO, R_TERMINAL, K_M, ETA_MOTOR = 100.0, 0.22, 0.134, 0.92
ETA_GEAR_SPEED = np.array([500.0, 1000.0, 2000.0, 3000.0])  # rpm
ETA_GEAR_VALUE = np.array([0.75, 0.69, 0.63, 0.58])
RAD_PER_S_TO_RPM = 60.0 / (2.0 * math.pi)


def waypoints(q22: float, q24: float) -> np.ndarray:
    """The study's three waypoints (thesis eq. 7-22/7-23) in URDF radians."""
    thesis = np.array([[0, 0, 0, 0, 0, 0, 0], [-90, q22, 0, q24, 0, 0, 0], [-180, 0, 0, 0, 0, 0, 0]], dtype=float)
    return thesis_to_urdf(thesis)


def sample(traj, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity of a planned trajectory at the times ``t`` (n,), all at once: (n, 7) each."""
    starts = traj.phase_start
    k = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)
    dt = (t - starts[k])[:, None]
    a = traj.phase_a[k]
    q = traj.phase_q[k] + traj.phase_v[k] * dt + 0.5 * a * dt * dt
    qd = traj.phase_v[k] + a * dt
    before, after = t <= 0.0, t >= traj.duration  # at rest at the first / last waypoint
    q[before], qd[before] = traj.waypoints[0], 0.0
    q[after], qd[after] = traj.waypoints[-1], 0.0
    return q, qd


def electric_power(tau: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """p_el per sample and joint (recuperation on), as the FMU computes it."""
    omega_motor = omega * GEAR_RATIO
    n_motor = omega_motor * RAD_PER_S_TO_RPM
    eta = np.interp(np.abs(n_motor), ETA_GEAR_SPEED, ETA_GEAR_VALUE) * ETA_MOTOR
    tau_motor = np.where(tau * omega < 0.0, tau * eta / GEAR_RATIO, tau / (GEAR_RATIO * eta))
    i_motor = tau_motor / K_M
    return R_TERMINAL * i_motor * i_motor + tau_motor * omega_motor


def evaluate_point(q22: float, q24: float, h: float = STEP) -> dict[str, float]:
    """Every objective of the spec for one design point (q2[2], q2[4] in thesis degrees), flat like a table row."""
    limits = FRANKA_DOC_LIMITS
    traj = plan_parabolic_blend(waypoints(q22, q24), limits.qd_max, limits.qdd_max)
    duration = traj.duration
    # communication points 0, h, ..., t_N: the run stops at the first one where the trajectory has finished
    n = max(1, math.ceil((duration - 1e-9) / h))
    if n * h < duration - 1e-9:  # the division rounded down
        n += 1
    elif n > 1 and (n - 1) * h >= duration - 1e-9:  # ... or up
        n -= 1
    n = min(n, round(STOP / h))
    t = np.arange(n + 1) * h
    # sample 0: the initial state (at rest at the start); samples 1..n: the step just taken (midpoint sampling)
    q_mid, qd_mid = sample(traj, t[1:] - 0.5 * h)
    _, qd_end = sample(traj, t)
    q = np.vstack([traj.waypoints[0], q_mid])
    qd = np.vstack([np.zeros(N_JOINTS), qd_mid])
    qdd = np.vstack([np.zeros(N_JOINTS), np.diff(qd_end, axis=0) / h])

    model = cached_model()
    data = model.createData()
    frame = ee_frame_id(model)
    tau = np.empty_like(q)
    ee = np.empty((n + 1, 3))
    for k in range(n + 1):
        tau[k] = pin.rnea(model, data, q[k], qd[k], qdd[k])
        pin.forwardKinematics(model, data, q[k])
        ee[k] = pin.updateFramePlacement(model, data, frame).translation

    p_el = electric_power(tau, qd)  # sample 0: the initial outputs; sample k: the power held over step k
    e_el_run = (p_el[1:] * h).sum(axis=0)
    p_el_end = p_el[-1]
    t_end = t[-1]
    overshoot = t_end - duration
    joint_distance_rad = np.trapezoid(np.abs(qd), t, axis=0)
    tau_ratio = np.abs(tau) / limits.tau_max
    violated = ((tau_ratio.max(axis=1) > 1.0) | ((q - limits.q_min).min(axis=1) < 0.0)
                | ((limits.q_max - q).min(axis=1) < 0.0) | ((np.abs(qd) - limits.qd_max).max(axis=1) > 0.0))
    row = {
        "e_total": float(e_el_run.sum() - p_el_end.sum() * overshoot),
        "e_total_run": float(e_el_run.sum()),
        "p_total_end": float(p_el_end.sum()),
        "t_end": float(t_end),
        "overshoot": float(overshoot),
        "e_total_no_recuperation": float((np.maximum(p_el[1:], 0.0).sum(axis=1) * h).sum()),
        "duration": float(duration),
        "joint_distance": float(np.rad2deg(joint_distance_rad.sum())),
        "cartesian_distance": float(np.linalg.norm(np.diff(ee, axis=0), axis=1).sum()),
        "limit_violated": float(violated.any()),
        "tracking_error": 0.0,
    }
    arrays = {
        "e_el": e_el_run - p_el_end * overshoot, "e_el_run": e_el_run, "p_el_end": p_el_end,
        "joint_distance_rad": joint_distance_rad, "avg_joint_velocity": np.rad2deg(joint_distance_rad) / duration,
        "peak_tau_ratio": tau_ratio.max(axis=0), "q_lowest": q.min(axis=0), "q_highest": q.max(axis=0),
    }
    for name, values in arrays.items():
        for j, value in enumerate(values, start=1):
            row[f"{name}[{j}]"] = float(value)
    return row


# -- the benchmark ----------------------------------------------------------------------------------

# 32 points over the whole grid (one lock-step group): every corner, short and long runs (159-246 steps)
POINTS = [(float(q22), float(q24)) for q22 in (-100, -60, -20, 20) for q24 in (0, 20, 40, 60, 80, 100, 120, 140)]
TARGET = 2.0  # issue 35 (issue 16 asked for 3x): a co-simulated point costs at most 2x this reference


def main() -> None:
    import argparse
    import os
    import platform
    import statistics
    import time
    from pathlib import Path

    from cosim import build_system, load_spec
    from cosim.execution.point import assignments_for, run_point

    try:
        from cosim.execution.lockstep import instantiate, run_lockstep
    except ImportError:  # a cosim from before lock-step (to measure the "before" figure)
        instantiate = run_lockstep = None

    parser = argparse.ArgumentParser(description="cosim's inverse-dynamics pick-and-place point against a "
                                                 "hand-written vectorised evaluation, interleaved")
    parser.add_argument("--rounds", type=int, default=9, help="rounds over the 32 points (default 9)")
    parser.add_argument("--only", choices=("reference", "lockstep", "single"),
                        help="warm up, then run only this variant --rounds times and print nothing (the workload "
                             "--callgrind counts)")
    parser.add_argument("--callgrind", action="store_true",
                        help="count instructions per point of the reference and of the lock-step run under "
                             "valgrind's callgrind (load-independent): runs of 1 and 1 + --rounds rounds, the "
                             "difference divided by the points")
    args = parser.parse_args()
    if args.callgrind:
        return count_instructions(args.rounds)
    spec = Path(__file__).resolve().parents[1] / "examples" / "pick_and_place" / "spec.json"
    system = build_system(load_spec(spec))
    values = [{"traj.waypoints[9]": q22, "traj.waypoints[11]": q24} for q22, q24 in POINTS]
    units = {name: su.unit_type.instantiate(name) for name, su in system.units.items()}
    batches = instantiate(system, len(POINTS)) if instantiate else {}

    def single() -> None:  # as a sweep child runs points one by one: units reused, reset after each
        for v in values:
            result = run_point(system, v, units=units)
            assert result.ok, result.message
            for unit in units.values():
                unit.reset()

    def lockstep() -> None:  # as a sweep child runs a group of points (cosim.execution.lockstep)
        results = run_lockstep(system, [assignments_for(system, v) for v in values], batches)
        assert all(r.ok for r in results)
        for batch in batches.values():
            batch.reset()

    def reference() -> None:
        for q22, q24 in POINTS:
            evaluate_point(q22, q24)

    variants = {"reference": reference, "cosim lock-step": lockstep, "cosim one by one": single}
    if run_lockstep is None:
        del variants["cosim lock-step"]
    if args.only:
        run = {"reference": reference, "lockstep": lockstep, "single": single}[args.only]
        for _ in range(1 + args.rounds):  # the first round warms up (imports, FMU extraction, model caches)
            run()
        return
    for run in variants.values():  # warm up (imports, FMU extraction, model caches)
        run()
    wall: dict[str, list[float]] = {name: [] for name in variants}
    cpu: dict[str, list[float]] = {name: [] for name in variants}
    names = list(variants)
    for r in range(args.rounds):  # interleaved, the order rotating from round to round
        for name in names[r % len(names):] + names[:r % len(names)]:
            w, c = time.perf_counter(), time.process_time()
            variants[name]()
            wall[name].append((time.perf_counter() - w) / len(POINTS))
            cpu[name].append((time.process_time() - c) / len(POINTS))
    load = os.getloadavg()
    print(f"# inverse-dynamics pick-and-place point (examples/pick_and_place/spec.json, 10 ms steps), "
          f"{len(POINTS)} points x {args.rounds} rounds, interleaved; {platform.machine()}, {os.cpu_count()} cores, "
          f"load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}, {time.strftime('%Y-%m-%d %H:%M %Z')}")
    print(f"{'variant':<18} {'wall ms/point':>14} {'CPU ms/point':>13} {'x reference (wall)':>19} {'(CPU)':>6}")
    for name in names:
        ratio_wall = statistics.median(a / b for a, b in zip(wall[name], wall["reference"]))
        ratio_cpu = statistics.median(a / b for a, b in zip(cpu[name], cpu["reference"]))
        print(f"{name:<18} {statistics.median(wall[name]) * 1e3:>14.3f} {statistics.median(cpu[name]) * 1e3:>13.3f} "
              f"{ratio_wall:>19.2f} {ratio_cpu:>6.2f}")
    way = "cosim lock-step" if "cosim lock-step" in wall else "cosim one by one"
    ratio = statistics.median(a / b for a, b in zip(wall[way], wall["reference"]))
    print(f"target: a point ({way}, as a sweep runs it) <= {TARGET:g}x the reference: "
          f"{'met' if ratio <= TARGET else 'NOT met'} ({ratio:.2f}x, median of per-round wall ratios)")
    for unit in units.values():
        unit.terminate()
    for batch in batches.values():
        batch.terminate()


def count_instructions(rounds: int) -> None:
    """Instructions per point (callgrind) of the reference and of cosim's lock-step run: each variant run under
    valgrind with 0 and ``rounds`` rounds after its warm-up round, the difference over ``rounds`` x 32 points."""
    import os
    import re
    import subprocess
    import sys
    import tempfile
    import time

    counts = {}
    with tempfile.TemporaryDirectory() as folder:
        for variant in ("reference", "lockstep"):
            totals = []
            for n in (0, rounds):
                out = os.path.join(folder, f"{variant}-{n}.out")
                done = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", sys.executable,
                                       __file__, "--only", variant, "--rounds", str(n)],
                                      capture_output=True, text=True)
                if done.returncode != 0:
                    raise SystemExit(f"valgrind failed ({done.returncode}):\n{done.stderr[-2000:]}")
                totals.append(int(re.search(r"^summary: (\d+)", open(out).read(), re.M).group(1)))
            counts[variant] = (totals[1] - totals[0]) / (rounds * len(POINTS))
    load = os.getloadavg()
    print(f"# callgrind instructions per point, {len(POINTS)} points x {rounds} rounds after a warm-up round; "
          f"load {load[0]:.2f}, {time.strftime('%Y-%m-%d %H:%M %Z')}")
    for variant, count in counts.items():
        print(f"{variant:<10} {count / 1e6:10.3f} M instructions/point")
    print(f"lock-step / reference: {counts['lockstep'] / counts['reference']:.2f}x")


if __name__ == "__main__":
    main()
