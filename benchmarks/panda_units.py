"""Wall time of the Panda units: per 1 ms step and per pick-and-place trajectory.

Run:  cd /work/main && python benchmarks/panda_units.py
Drives the units through the unit protocol the way a master does (inputs set
and outputs read through pre-resolved selections every step), on the thesis
pick-and-place trajectory with q2 = (-90, -45, 0, 70, 0, 0, 0) deg (thesis
convention), 1 ms communication steps.  Prints medians of several repetitions.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from cosim.models.panda_exudyn import PandaExudyn  # noqa: E402
from cosim.models.panda_inverse_dynamics import PandaInverseDynamics  # noqa: E402
from cosim.models.trajectory import N_MAX_WAYPOINTS, TrajectoryGenerator  # noqa: E402
from cosim.units.protocol import resolve_port  # noqa: E402

H = 1e-3
REPEATS = 5
WAYPOINTS_DEG = [[0, 0, 0, 0, 0, 0, 0], [-90, -45, 0, 70, 0, 0, 0], [-180, 0, 0, 0, 0, 0, 0]]


def selection(unit, ports):
    refs = []
    for p in ports:
        refs.extend(resolve_port(unit.description, p)[1])
    return unit.select(refs)


def one_run(traj_unit, robot):
    """Initialise both units and run the whole trajectory; returns (total s, traj s, robot s, steps)."""
    flat = np.zeros((N_MAX_WAYPOINTS, 7))
    flat[:3] = WAYPOINTS_DEG
    t0 = time.perf_counter()
    traj_unit.reset()
    traj_unit.set_values({"waypoints": flat.ravel(), "n_waypoints": 3, "convention": "thesis_deg"})
    traj_unit.setup(0.0, None)
    traj_unit.exit_initialization()
    out_sel = selection(traj_unit, ["q_ref", "qd_ref", "qdd_ref"])
    in_sel = selection(robot, ["q_ref", "qd_ref", "qdd_ref"])
    robot_out = selection(robot, ["tau", "qd", "ee_pos"])
    robot.reset()
    robot.set(in_sel, traj_unit.get(out_sel))
    robot.setup(0.0, None)
    robot.exit_initialization()
    duration = traj_unit.duration
    n = int(np.ceil(duration / H))
    t_traj = t_robot = 0.0
    for k in range(n):
        a = time.perf_counter()
        traj_unit.do_step(k * H, H)
        values = traj_unit.get(out_sel)
        b = time.perf_counter()
        robot.set(in_sel, values)
        robot.do_step(k * H, H)
        robot.get(robot_out)
        c = time.perf_counter()
        t_traj += b - a
        t_robot += c - b
    robot.terminate()
    return time.perf_counter() - t0, t_traj, t_robot, n


def main() -> None:
    print(f"pick-and-place, 1 ms steps, median of {REPEATS} runs (after one warm-up run)")
    for cls in (PandaInverseDynamics, PandaExudyn):
        traj_unit, robot = TrajectoryGenerator("traj"), cls("robot")
        one_run(traj_unit, robot)  # warm-up: builds the models once per instance
        runs = [one_run(traj_unit, robot) for _ in range(REPEATS)]
        total = statistics.median(r[0] for r in runs)
        per_traj = statistics.median(r[1] / r[3] for r in runs) * 1e6
        per_robot = statistics.median(r[2] / r[3] for r in runs) * 1e6
        print(f"{cls.__name__:22s} steps={runs[0][3]}  robot step (set+do_step+get) {per_robot:6.1f} us"
              f"  trajectory step {per_traj:5.1f} us  whole run (both units, incl. init) {total * 1e3:7.1f} ms")
    components()
    # cost of (re)initialisation after reset, and of the first build
    for cls in (PandaInverseDynamics, PandaExudyn):
        t0 = time.perf_counter()
        u = cls("robot")
        u.setup(0.0, None)
        u.exit_initialization()
        first = time.perf_counter() - t0
        times = []
        for _ in range(20):
            u.reset()
            t0 = time.perf_counter()
            u.setup(0.0, None)
            u.exit_initialization()
            times.append(time.perf_counter() - t0)
        print(f"{cls.__name__:22s} first initialize {first * 1e3:6.2f} ms, after reset {statistics.median(times) * 1e3:6.3f} ms")


def components(n: int = 1500) -> None:
    """Each unit's own work per step, apart from the PythonUnit get/set protocol."""
    traj_unit = TrajectoryGenerator("traj")
    flat = np.zeros((N_MAX_WAYPOINTS, 7))
    flat[:3] = WAYPOINTS_DEG
    traj_unit.set_values({"waypoints": flat.ravel(), "n_waypoints": 3, "convention": "thesis_deg"})
    traj_unit.setup(0.0, None)
    traj_unit.exit_initialization()
    refs = []
    t0 = time.perf_counter()
    for k in range(n):
        traj_unit.do_step(k * H, H)
        refs.append((traj_unit.q_ref.copy(), traj_unit.qd_ref.copy(), traj_unit.qdd_ref.copy()))
    t_traj = (time.perf_counter() - t0) / n
    sel = selection(traj_unit, ["q_ref", "qd_ref", "qdd_ref"])
    t0 = time.perf_counter()
    for _ in range(n):
        traj_unit.get(sel)
    t_get = (time.perf_counter() - t0) / n
    line = [f"trajectory do_step {t_traj * 1e6:.1f} us", f"PythonUnit.get of its 21 outputs {t_get * 1e6:.1f} us"]
    for cls, hook in ((PandaInverseDynamics, "compute_outputs"), (PandaExudyn, None)):
        robot = cls("robot")
        robot.q_ref[:], robot.qd_ref[:], robot.qdd_ref[:] = refs[0]
        robot.setup(0.0, None)
        robot.exit_initialization()
        t0 = time.perf_counter()
        for k, (q, qd, qdd) in enumerate(refs):
            robot.q_ref[:], robot.qd_ref[:], robot.qdd_ref[:] = q, qd, qdd
            getattr(robot, hook)() if hook else robot.do_step(k * H, H)
        line.append(f"{cls.__name__} {hook or 'do_step'} {(time.perf_counter() - t0) / n * 1e6:.1f} us")
    print("own work per step: " + "; ".join(line))


if __name__ == "__main__":
    main()
