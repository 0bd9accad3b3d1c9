"""Numbers of the bin-picking sweep that the README compares with thesis section 8.2.

Usage: ``python examples/bin_picking/summary.py examples/bin_picking/results.parquet``
"""

from __future__ import annotations

import sys

import numpy as np
import pandas as pd

from cosim.models.planner import CODE_NAMES

X, Y, Z = "planner.offset_x", "planner.offset_y", "planner.offset_z"


def main(path: str) -> None:
    df = pd.read_parquet(path).reset_index(drop=True)
    print(f"rows {len(df)}, status: {df['status'].value_counts().to_dict()}")
    valid_sets = {}
    for variant in ("simple", "complex"):
        d = df[df["planner.box_variant"] == variant]
        v = d[d["executed_ok"] == 1.0]
        valid_sets[variant] = set(map(tuple, v[[X, Y, Z]].round(3).to_numpy()))
        print(f"\n## {variant}: {len(v)} of {len(d)} valid ({100 * len(v) / len(d):.2f} %); "
              f"planned fully {int(d['planned_ok'].sum())}, collided in execution {int(((d['planned_ok'] == 1) & (d['collided'] == 1)).sum())}")
        for axis, name in ((X, "x"), (Y, "y"), (Z, "z")):
            print(f"  {name}_pos with >= 1 valid: {sorted(np.round(v[axis].unique(), 2).tolist())}")
        blocked = d[d["planned_ok"] != 1.0]
        reasons = blocked["blocked_code"].map(lambda c: CODE_NAMES[int(c)]).value_counts().to_dict()
        print(f"  why planning stopped: {reasons}")
        print(f"  mean fraction planned: {d['fraction_planned'].mean():.3f}")
        if v.empty:
            continue
        for col, unit in (("duration", "s"), ("joint_distance", "deg"), ("cartesian_distance", "m"), ("e_total", "J"),
                          ("pendulum_max", "rad"), ("tracking_error", "rad")):
            lo, hi = v.loc[v[col].idxmin()], v.loc[v[col].idxmax()]
            print(f"  {col:18s} min {lo[col]:8.2f} {unit} at ({lo[X]:.2f}, {lo[Y]:.2f}, {lo[Z]:.2f}); "
                  f"max {hi[col]:8.2f} at ({hi[X]:.2f}, {hi[Y]:.2f}, {hi[Z]:.2f}); median {v[col].median():.2f}")
        for axis, name in ((X, "x"), (Y, "y"), (Z, "z")):
            g = v.groupby(v[axis].round(2))["duration"].mean().round(2).to_dict()
            print(f"  mean time by {name}_pos: {g}")
        c = np.corrcoef(v["joint_distance"], v["duration"])[0, 1]
        print(f"  corr(time, joint distance) = {c:.3f}; corr(time, energy) = {np.corrcoef(v['e_total'], v['duration'])[0, 1]:.3f}")
        print(f"  limit_violated among valid: {int(v['limit_violated'].sum())}")
    s, c = valid_sets["simple"], valid_sets["complex"]
    print(f"\ncomplex-valid also simple-valid: {len(c & s)} of {len(c)}")
    print(f"run_time median {df['run_time'].median():.3f} s; valid {df[df['executed_ok'] == 1]['run_time'].median():.3f} s; "
          f"not executed {df[df['planned_ok'] != 1]['run_time'].median():.3f} s; planning median {df['planning_time'].median() * 1e3:.1f} ms")


if __name__ == "__main__":
    main(sys.argv[1])
