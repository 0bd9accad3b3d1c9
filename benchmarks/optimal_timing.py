"""Solution time per path of the energy-optimal timing (models/optimal_timing.py).

Paths: designs of the coarse pick-and-place grid (thesis q2[2] every 10 deg,
q2[4] every 7 deg), every ``--every``-th one.  For each path and mode the whole
``plan_optimal_timing`` call is timed (path data from pinocchio + all passes),
wall clock and CPU time of this process, once with the default solver (Fatrop,
IPOPT where a Fatrop pass fails) and once with IPOPT alone, interleaved path by
path so that both see the same machine load; CasADi's own solver timers are
summed over the passes (``t_proc_total``; of it the function evaluations,
``t_proc_nlp_*``).  The path data (pinocchio RNEA on the grid) is timed alone.
The solvers are built once per process (first call, reported separately).

Usage::

    python benchmarks/optimal_timing.py               # every 7th coarse design (39 paths)
    python benchmarks/optimal_timing.py --every 1 --grid 100

Results are recorded in benchmarks/optimal_timing.md.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.models.optimal_timing import DEFAULT_GRID, path_data, plan_optimal_timing  # noqa: E402
from cosim.models.panda_model import FRANKA_DOC_LIMITS as LIMITS  # noqa: E402
from cosim.models.panda_model import panda_model, thesis_to_urdf  # noqa: E402
from cosim.models.trajectory import plan_parabolic_blend  # noqa: E402

SOLVERS = ("fatrop", "ipopt")  # the default first; IPOPT alone is the previous planner
MODES = {"at most the blend's duration": dict(factor=1.0), "at most 1.25 x the blend's": dict(factor=1.25),
         "energy + 20 J/s x duration": dict(time_weight=20.0)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--every", type=int, default=7, help="take every N-th design of the 273 coarse ones")
    parser.add_argument("--grid", type=int, default=DEFAULT_GRID, help="grid intervals along the path")
    args = parser.parse_args()
    designs = [(a, b) for a in range(-100, 21, 10) for b in range(0, 141, 7)][:: args.every]
    model = panda_model()
    blends = [plan_parabolic_blend(thesis_to_urdf([[0] * 7, [-90, a, 0, b, 0, 0, 0], [-180, 0, 0, 0, 0, 0, 0]]),
                                   LIMITS.qd_max, LIMITS.qdd_max) for a, b in designs]
    start = time.perf_counter()
    for solver in SOLVERS:
        plan_optimal_timing(blends[0], model, LIMITS.qd_max, LIMITS.qdd_max, LIMITS.tau_max,
                            max_duration=1.25 * blends[0].duration, n_grid=args.grid, solver=solver)
    first = time.perf_counter() - start
    print(f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {len(designs)} paths, grid {args.grid}, "
          f"load average {os.getloadavg()}, first calls (build both solvers) {first:.2f} s")
    data_cpu = []
    for blend in blends:
        c0 = time.process_time()
        path_data(blend, model, args.grid)
        data_cpu.append(time.process_time() - c0)
    print(f"path data (pinocchio RNEA at 3 points per interval): CPU ms median {statistics.median(data_cpu) * 1e3:.1f}")
    print("| mode | solver | wall ms median | p90 | CPU ms median | p90 | solver CPU ms median (CasADi t_proc_total) | "
          "of it function evaluations | iterations (mean) | passes (mean) | passes by Fatrop / IPOPT | "
          "objective vs IPOPT alone (rel. diff. min .. max) | failed |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, mode in MODES.items():
        runs = {solver: {"wall": [], "cpu": [], "passes": [], "solver": [], "functions": [], "iterations": [],
                         "fatrop": 0, "ipopt": 0, "energy": [], "failed": 0} for solver in SOLVERS}
        for blend in blends:
            bound = mode["factor"] * blend.duration if "factor" in mode else None
            for solver, run in runs.items():
                t0, c0 = time.perf_counter(), time.process_time()
                try:
                    timing = plan_optimal_timing(blend, model, LIMITS.qd_max, LIMITS.qdd_max, LIMITS.tau_max,
                                                 max_duration=bound, time_weight=mode.get("time_weight", 0.0),
                                                 n_grid=args.grid, solver=solver)
                except (ValueError, RuntimeError):
                    run["failed"] += 1
                    run["energy"].append(np.nan)
                    continue
                run["wall"].append(time.perf_counter() - t0)
                run["cpu"].append(time.process_time() - c0)
                stats = timing.solver_stats
                run["passes"].append(timing.passes)
                run["solver"].append(stats["t_proc_total"])
                run["functions"].append(stats["t_proc_functions"])
                run["iterations"].append(stats["iterations"])
                run["fatrop"] += stats["fatrop_passes"]
                run["ipopt"] += stats["ipopt_passes"]
                run["energy"].append(timing.planned_energy + mode.get("time_weight", 0.0) * timing.duration)
        reference = np.array(runs["ipopt"]["energy"])
        q = lambda x, p: np.percentile(x, p) * 1e3  # noqa: E731
        for solver, run in runs.items():
            diff = np.array(run["energy"]) / reference - 1  # objective (energy + time weight x duration)
            print(f"| {name} | {solver} | {statistics.median(run['wall']) * 1e3:.0f} | {q(run['wall'], 90):.0f} | "
                  f"{statistics.median(run['cpu']) * 1e3:.0f} | {q(run['cpu'], 90):.0f} | "
                  f"{statistics.median(run['solver']) * 1e3:.0f} | {sum(run['functions']) / sum(run['solver']):.1%} | "
                  f"{np.mean(run['iterations']):.0f} | {np.mean(run['passes']):.1f} | {run['fatrop']} / {run['ipopt']} | "
                  f"{np.nanmin(diff):+.1e} .. {np.nanmax(diff):+.1e} | {run['failed']} |")


if __name__ == "__main__":
    main()
