"""How good is `cosim sweep --dry-run`'s time estimate? Measured on studies whose every point's time is recorded.

A dry run runs a few sample points and scales their mean time to the whole space. Here the sample is drawn
from a committed results table instead of being run, so the estimate can be compared with the table's own total
(the sum of its rows' run times) many times over: once per hypercube seed for the stratified sample (the dry
run uses seed 0), and for the sample of earlier releases (4 points spread evenly through the enumeration, the
first dropped as a warm-up). For each study it prints the true mean per point, the seed-0 estimate and range,
and over 200 seeds: the median ratio estimate/true, the 10th-90th percentile of that ratio, and how often the
true mean lay in the printed range.

    python benchmarks/dry_run_estimate.py            # figures in benchmarks/dry_run_estimate.md

No simulation runs: the tables' run times are the truth (each was measured by its sweep, on its machine).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from cosim.spec.design import DesignSpace
from cosim.spec.loader import load_spec
from cosim.studies.estimate import estimate_time

ROOT = Path(__file__).resolve().parent.parent
STUDIES = {  # results table -> the spec it was swept from
    "bin_picking": ("examples/bin_picking/results.parquet", "examples/bin_picking/spec.json"),
    "pick_and_place_coarse_exudyn": ("examples/pick_and_place/results_coarse_exudyn.parquet",
                                     "examples/pick_and_place/spec_coarse_exudyn.json"),
    "pick_and_place_coarse": ("examples/pick_and_place/results_coarse.parquet",
                              "examples/pick_and_place/spec_coarse.json"),
}
SEEDS = 200
SAMPLES = (8, 12, 16)  # the dry run takes 12 (cosim.cli.sweep.DRY_RUN_SAMPLES)


def _times_by_values(table: pd.DataFrame, space: DesignSpace) -> dict[str, float]:
    """run_time per point, keyed by the point's parameter values (ids depend on the spec's digest at the time)."""
    columns = list(space.columns(next(iter(space)).values))
    return {json.dumps([row[c] for c in columns], default=float): float(row["run_time"])
            for row in table[columns + ["run_time"]].to_dict("records")}


def _key(space: DesignSpace, point) -> str:
    columns = space.columns(point.values)
    return json.dumps(list(columns.values()), default=float)


def study_figures(name: str, table_path: str, spec_path: str, samples: int) -> dict:
    space = DesignSpace.from_spec(load_spec(ROOT / spec_path))
    times = _times_by_values(pd.read_parquet(ROOT / table_path), space)
    true_mean = float(np.mean(list(times.values())))
    old = [times[_key(space, p)] for p in space.spread(4)][1:]
    seeded = []
    for seed in range(SEEDS):
        sample = [times[_key(space, p)] for p in space.stratified(samples, seed=seed)]
        e = estimate_time(sample)
        seeded.append((e.mean / true_mean, e.low <= true_mean <= e.high, e))
    ratios = np.array([r for r, _, _ in seeded])
    first = seeded[0][2]
    return {"study": name, "samples": samples, "points": len(space), "true_mean_s": true_mean,
            "old_estimate_ratio": float(np.mean(old) / true_mean),
            "seed0_ratio": first.mean / true_mean, "seed0_range": (first.low / true_mean, first.high / true_mean),
            "median_ratio": float(np.median(ratios)),
            "p10_p90_ratio": tuple(float(x) for x in np.quantile(ratios, [0.1, 0.9])),
            "covered": float(np.mean([c for _, c, _ in seeded]))}


def main() -> None:
    print(f"{'study':30} {'n':>2} {'points':>6} {'true s/pt':>9} {'old/true':>8} {'seed0/true':>10} {'seed0 range':>13} "
          f"{'median':>6} {'p10-p90':>11} {'covered':>7}")
    for (name, (table, spec)), n in ((study, n) for study in STUDIES.items() for n in SAMPLES):
        f = study_figures(name, table, spec, n)
        lo, hi = f["seed0_range"]
        p10, p90 = f["p10_p90_ratio"]
        print(f"{name:30} {n:2d} {f['points']:6d} {f['true_mean_s']:9.3f} {f['old_estimate_ratio']:8.2f} "
              f"{f['seed0_ratio']:10.2f} {lo:6.2f}-{hi:<6.2f} {f['median_ratio']:6.2f} {p10:5.2f}-{p90:<5.2f} "
              f"{f['covered']:7.0%}")


if __name__ == "__main__":
    main()
