"""Prognosis quality of `cosim surrogate` on the committed 17061-design pick-and-place table (issue 37).

For each seed: 200 random designs are drawn, a surrogate of each objective is fitted on them (``auto``: the
candidate with the best 5-fold Q² on those 200, as the command does; also ``gp`` and ``poly`` alone), and Q² is
computed on the other 16861 designs, which the surrogate never saw.  The baseline is scipy's thin-plate-spline
RBF interpolation on the same 200 designs (unit box scaling, no smoothing).

    PYTHONPATH=src python benchmarks/surrogate_quality.py [SEEDS]      (default 3 seeds: 0, 1, 2)
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

    from cosim.analysis.surrogate.fit import fit_objective, q_squared
    from cosim.analysis.table import load_results

    table = load_results(TABLE)
    parameters = table.parameter_columns()
    x = np.column_stack([table.values(p) for p in parameters])
    print(f"{TABLE.relative_to(REPO)}: {len(x)} designs, parameters {', '.join(parameters)}")
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; load average {os.getloadavg()}; "
          f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC")
    print("| objective | seed | auto: chosen | auto Q² | gp Q² | poly Q² | thin-plate RBF Q² | auto fit time |")
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
            for method in ("gp", "poly"):
                q[method] = q_squared(y[test], fit_objective(x[train], y[train], method, seed=seed).model.predict(
                    x[test])[0])
            low, span = x[train].min(axis=0), np.ptp(x[train], axis=0)
            rbf = RBFInterpolator((x[train] - low) / span, y[train], kernel="thin_plate_spline")
            q["rbf"] = q_squared(y[test], rbf((x[test] - low) / span))
            print(f"| {name} | {seed} | {auto.candidate} | {q['auto']:.5f} | {q['gp']:.5f} | {q['poly']:.5f} | "
                  f"{q['rbf']:.5f} | {took:.1f} s |", flush=True)
    print(f"load average at the end {os.getloadavg()}; {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 3)
