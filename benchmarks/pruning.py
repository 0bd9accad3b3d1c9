"""Exact pruning on the pick-and-place study: the pruned sweep's front against the unpruned one's, and its CPU.

Runs examples/pick_and_place/spec_pruned.json (coarse 13 x 21 = 273 designs, Exudyn level; minimize the energy
without recuperation and the duration, subject to peak_tau <= 1) twice on a local Dask cluster: without and
with ``prune=True``.  Checks and prints:

- the front of the feasible ``ok`` rows (peak_tau <= 1) of both studies: the same designs, the same values bit
  for bit;
- every pruned row's bound is strictly dominated by a member of the unpruned front (or breaks the constraint),
  and never exceeds that design's final value in the unpruned study;
- the CPU time of all points together (sum of ``run_time``: each point runs alone in a worker's child process)
  and the wall time, pruned / unpruned;
- the cost of the front that travels with each batch (its pickled size and the time to pickle it).

Usage: python benchmarks/pruning.py [--spec FILE] [--workers N] [--out DIR]   (about 3 minutes on 2 cores)
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from cosim.analysis.pareto import pareto_mask
from cosim.studies.pruning import FrontKeeper
from cosim.studies.sweep import Sweep

HERE = Path(__file__).resolve().parent
SPEC = HERE.parent / "examples" / "pick_and_place" / "spec_pruned.json"
OBJECTIVES = ["e_total_no_recuperation", "duration"]
LIMIT = ("peak_tau", 1.0)


def front(table):
    ok = table[(table["status"] == "ok") & (table[LIMIT[0]] <= LIMIT[1])]
    mask = pareto_mask(ok[OBJECTIVES].to_numpy(), ["minimize"] * len(OBJECTIVES))
    return ok[mask].set_index("point_id")[OBJECTIVES].sort_index()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spec", default=str(SPEC))
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    out = Path(args.out or tempfile.mkdtemp(prefix="cosim_pruning_"))
    figures: dict = {"machine": f"{os.cpu_count()} cores {platform.machine()}", "load_before": os.getloadavg()}
    runs = {}
    for name, prune in (("unpruned", False), ("pruned", True)):
        started = time.perf_counter()
        table = Sweep(args.spec, workers=args.workers, out=out / name, quiet=True, prune=prune).run()
        runs[name] = table
        figures[name] = {"wall_s": round(time.perf_counter() - started, 1),
                         "cpu_points_s": round(float(table["run_time"].sum()), 1),
                         "status": table["status"].value_counts().to_dict(), "load_after": os.getloadavg()}
    full, pruned = runs["unpruned"], runs["pruned"]
    a, b = front(full), front(pruned)
    figures["front_designs"] = len(a)
    figures["front_identical"] = list(a.index) == list(b.index) and bool((a.to_numpy() == b.to_numpy()).all())
    finals = full.set_index("point_id")
    bad = []
    for _, row in pruned[pruned["status"] == "pruned"].iterrows():
        bound = row[OBJECTIVES].to_numpy(dtype=float)
        final = finals.loc[row["point_id"], OBJECTIVES].to_numpy(dtype=float)
        dominated = ((a.to_numpy() <= bound).all(axis=1) & (a.to_numpy() < bound).any(axis=1)).any()
        broken = row["pruned_by"] == "" and row[LIMIT[0]] > LIMIT[1]
        infeasible = finals.loc[row["point_id"], LIMIT[0]] > LIMIT[1]
        if not (dominated or (broken and infeasible)) or (np.nan_to_num(bound, nan=-np.inf) > final).any():
            bad.append(row["point_id"])
    figures["pruned_rows_not_proven"] = bad
    figures["cpu_ratio"] = round(figures["pruned"]["cpu_points_s"] / figures["unpruned"]["cpu_points_s"], 3)
    figures["wall_ratio"] = round(figures["pruned"]["wall_s"] / figures["unpruned"]["wall_s"], 3)
    keeper = FrontKeeper(Sweep(args.spec, workers=1, out=out / "probe", quiet=True, prune=True).prune)
    for _, row in full.iterrows():
        if row["status"] == "ok":
            keeper.add(row["point_id"], row.to_dict())
    started = time.perf_counter()
    for _ in range(1000):
        blob = pickle.dumps(keeper.order())
    figures["front_message"] = {"members": len(keeper.ids), "bytes": len(blob),
                                "pickle_us": round((time.perf_counter() - started) * 1e3, 1)}
    print(json.dumps(figures, indent=1, default=str))


if __name__ == "__main__":
    main()
