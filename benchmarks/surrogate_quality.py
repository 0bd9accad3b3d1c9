"""Prognosis quality of `cosim surrogate` on the committed 17061-design pick-and-place table (issue 37).

For each seed: 200 random designs are drawn, a surrogate of each objective is fitted on them (``auto``: the
candidate with the best 5-fold Q² on those 200, as the command does; its 5-fold Q² is shown too, the estimate
the command reports), and Q² is computed on the other 16861 designs, which the surrogate never saw.  The best
polynomial (by the same 5-fold Q²) is refitted and scored the same way.  The baseline is scipy's thin-plate-spline
RBF interpolation on the same 200 designs (unit box scaling, no smoothing).

    PYTHONPATH=src python benchmarks/surrogate_quality.py [SEEDS]      (default 2 seeds: 0, 1)
"""

from __future__ import annotations

import os
import platform
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
TABLE = REPO / "examples" / "pick_and_place" / "study"
OBJECTIVES = ("e_total", "peak_tau_ratio[2]")
TRAIN = 200


def main(seeds: int) -> None:
    from scipy.interpolate import RBFInterpolator

    from cosim.analysis.surrogate.fit import fit_candidate, fit_objective, q_squared
    from cosim.analysis.table import load_results

    table = load_results(TABLE)
    parameters = table.parameter_columns()
    x = np.column_stack([table.values(p) for p in parameters])
    print(f"{TABLE.relative_to(REPO)}: {len(x)} designs, parameters {', '.join(parameters)}")
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; load average {os.getloadavg()}; "
          f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC")
    print("| objective | seed | auto: chosen | its 5-fold Q² (on the 200) | auto Q² (16861 unseen) | best polynomial: "
          "Q² (unseen) | thin-plate RBF Q² (unseen) | auto fit time |")
    print("|---|---|---|---|---|---|---|---|")
    for name in OBJECTIVES:
        y = table.values(name)
        for seed in range(seeds):
            order = np.random.default_rng(seed).permutation(len(x))
            train, test = order[:TRAIN], order[TRAIN:]
            start = time.perf_counter()
            auto = fit_objective(x[train], y[train], "auto", seed=seed)
            took = time.perf_counter() - start
            q = {"auto": q_squared(y[test], auto.model.predict(x[test])[0])}
            polys = {c: v for c, v in auto.tried.items() if c.startswith("poly")}
            best_poly = max(polys, key=polys.get)
            q["poly"] = q_squared(y[test], fit_candidate(best_poly, x[train], y[train], seed).predict(x[test])[0])
            low, span = x[train].min(axis=0), np.ptp(x[train], axis=0)
            rbf = RBFInterpolator((x[train] - low) / span, y[train], kernel="thin_plate_spline")
            q["rbf"] = q_squared(y[test], rbf((x[test] - low) / span))
            print(f"| {name} | {seed} | {auto.candidate} | {auto.q2:.5f} | {q['auto']:.5f} | {best_poly}: "
                  f"{q['poly']:.5f} | {q['rbf']:.5f} | {took:.1f} s |", flush=True)
    print(f"load average at the end {os.getloadavg()}; {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 2)
