"""Solution time per path of the energy-optimal timing (models/optimal_timing.py).

Paths: designs of the coarse pick-and-place grid (thesis q2[2] every 10 deg,
q2[4] every 7 deg), every ``--every``-th one.  For each path and mode the whole
``plan_optimal_timing`` call is timed (path data from pinocchio + all IPOPT
passes), wall clock and CPU time of this process, and CasADi's own timers of
IPOPT summed over the passes (``t_proc_total``; of it the function
evaluations, ``t_proc_nlp_*``); the path data (pinocchio RNEA on the grid) is
timed alone.  The NLP itself is built once per process (first call, reported
separately).

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
    plan_optimal_timing(blends[0], model, LIMITS.qd_max, LIMITS.qdd_max, LIMITS.tau_max,
                        max_duration=1.25 * blends[0].duration, n_grid=args.grid)
    first = time.perf_counter() - start
    print(f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {len(designs)} paths, grid {args.grid}, "
          f"load average {os.getloadavg()}, first call (builds the NLP) {first:.2f} s")
    data_cpu = []
    for blend in blends:
        c0 = time.process_time()
        path_data(blend, model, args.grid)
        data_cpu.append(time.process_time() - c0)
    print(f"path data (pinocchio RNEA at 3 points per interval): CPU ms median {statistics.median(data_cpu) * 1e3:.1f}")
    print("| mode | wall ms median | p90 | CPU ms median | p90 | IPOPT CPU ms median (CasADi t_proc_total) | "
          "of it function evaluations | IPOPT iterations (mean) | passes (mean) | failed |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, mode in MODES.items():
        wall, cpu, passes, failed = [], [], [], 0
        ipopt, functions, iterations = [], [], []
        for blend in blends:
            bound = mode["factor"] * blend.duration if "factor" in mode else None
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                timing = plan_optimal_timing(blend, model, LIMITS.qd_max, LIMITS.qdd_max, LIMITS.tau_max,
                                             max_duration=bound, time_weight=mode.get("time_weight", 0.0), n_grid=args.grid)
            except (ValueError, RuntimeError):
                failed += 1
                continue
            wall.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
            passes.append(timing.passes)
            ipopt.append(timing.solver_stats["t_proc_total"])
            functions.append(timing.solver_stats["t_proc_functions"])
            iterations.append(timing.solver_stats["iterations"])
        q = lambda x, p: np.percentile(x, p) * 1e3  # noqa: E731
        print(f"| {name} | {statistics.median(wall) * 1e3:.0f} | {q(wall, 90):.0f} | {statistics.median(cpu) * 1e3:.0f} | "
              f"{q(cpu, 90):.0f} | {statistics.median(ipopt) * 1e3:.0f} | {sum(functions) / sum(ipopt):.1%} | "
              f"{np.mean(iterations):.0f} | {np.mean(passes):.1f} | {failed} |")


if __name__ == "__main__":
    main()
