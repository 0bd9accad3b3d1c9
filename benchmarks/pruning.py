"""Exact pruning on the pick-and-place study: the pruned sweep's front against the unpruned one's, and its CPU.

Runs examples/pick_and_place/spec_pruned.json (coarse 13 x 21 = 273 designs, Exudyn level; minimize the energy
without recuperation and the duration, subject to peak_tau <= 1) twice, each as its own ``cosim sweep`` process
on a local Dask cluster: without and with ``--prune``.  ``--full`` takes spec_pruned_full.json (the whole
121 x 141 = 17061-design grid); ``--level id`` the same objectives, declarations and constraint at the
inverse-dynamics level (the robot unit and the 10 ms step of examples/pick_and_place/spec.json: a derived spec
written into the output folder).  Checks and prints:

- the front of the feasible ``ok`` rows (peak_tau <= 1) of both studies: the same designs, the same values bit
  for bit;
- every pruned row's bound is strictly dominated by a member of the unpruned front (or breaks the constraint),
  and never exceeds that design's final value in the unpruned study;
- every row the pruned study ran to its end equals the unpruned study's row in every objective, bit for bit
  (the script exits non-zero when the front, a bound or such a row is not as promised);
- the CPU time of all points together, two ways: the sum of the rows' ``run_time`` (a lock-step group's time is
  divided among its points) and the CPU of the whole ``cosim sweep`` process with every process it starts
  (client, scheduler, workers, point children: ``getrusage(RUSAGE_CHILDREN)`` as a subreaper,
  benchmarks/process_cpu.py), pruned / unpruned; and the wall time;
- the cost of the front that travels with each batch (its pickled size and the time to pickle it).

Usage: python benchmarks/pruning.py [--level exudyn|id] [--full] [--spec FILE] [--workers N] [--out DIR]
       [--pruned-first]      (the coarse Exudyn grid: about 3 minutes on 2 idle cores)
   or: ... --side unpruned --out DIR & ... --side pruned --out DIR; then ... --compare --out DIR
       (the two studies at the same time, for a long grid on a shared machine)
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from cosim.analysis.pareto import pareto_mask
from cosim.studies.pruning import FrontKeeper
from cosim.studies.sweep import Sweep

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from process_cpu import become_subreaper, reap_orphans  # noqa: E402

EXAMPLE = HERE.parent / "examples" / "pick_and_place"
SPEC = EXAMPLE / "spec_pruned.json"
OBJECTIVES = ["e_total_no_recuperation", "duration"]
LIMIT = ("peak_tau", 1.0)


def inverse_dynamics_spec(spec: Path, out: Path) -> Path:
    """``spec`` (a pruning spec at the Exudyn level) with spec.json's robot unit and step: the same objectives,
    declarations, constraint and grid at the inverse-dynamics level, written into ``out``."""
    raw = json.loads(spec.read_text())
    level = json.loads((EXAMPLE / "spec.json").read_text())
    raw["units"]["robot"] = level["units"]["robot"]
    raw["experiment"]["step"] = level["experiment"]["step"]
    raw["description"] = "inverse-dynamics level of " + spec.name + " (benchmarks/pruning.py --level id)"
    path = out / f"{spec.stem}_id.json"
    path.write_text(json.dumps(raw, indent=1))
    return path


def sweep(spec: Path, out: Path, workers: int, prune: bool) -> dict:
    """One ``cosim sweep`` process; its table, wall time and the CPU of it and everything it started."""
    command = [sys.executable, "-m", "cosim", "sweep", str(spec), "--out", str(out), "--workers", str(workers)]
    if prune:
        command.append("--prune")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    wall = time.perf_counter() - started
    reap_orphans()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed ({done.returncode}):\n{done.stdout[-3000:]}")
    table = pd.read_parquet(out / "results.parquet")
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    return {"table": table, "wall_s": round(wall, 1), "process_cpu_s": round(cpu, 1),
            "cpu_points_s": round(float(table["run_time"].sum()), 1),
            "status": table["status"].value_counts().to_dict(), "load_after": os.getloadavg(),
            "finished": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())}


def front(table):
    ok = table[(table["status"] == "ok") & (table[LIMIT[0]] <= LIMIT[1])]
    mask = pareto_mask(ok[OBJECTIVES].to_numpy(), ["minimize"] * len(OBJECTIVES))
    return ok[mask].set_index("point_id")[OBJECTIVES].sort_index()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spec", default=None, help="a pruning spec at the Exudyn level (default: spec_pruned.json)")
    parser.add_argument("--full", action="store_true", help="spec_pruned_full.json: the 17061-design grid")
    parser.add_argument("--level", choices=("exudyn", "id"), default="exudyn")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default=None)
    parser.add_argument("--pruned-first", action="store_true", help="run the pruned study first")
    parser.add_argument("--side", choices=("unpruned", "pruned"),
                        help="run only this study (its figures into OUT/SIDE.json; the other may run at the same "
                             "time in another process); then --compare OUT")
    parser.add_argument("--compare", action="store_true", help="compare the two studies already in --out")
    args = parser.parse_args()
    become_subreaper()
    out = Path(args.out or tempfile.mkdtemp(prefix="cosim_pruning_"))
    out.mkdir(parents=True, exist_ok=True)
    spec = Path(args.spec) if args.spec else EXAMPLE / ("spec_pruned_full.json" if args.full else "spec_pruned.json")
    if args.level == "id":
        spec = inverse_dynamics_spec(spec, out)
    figures: dict = {"spec": str(spec), "machine": f"{os.cpu_count()} cores {platform.machine()}",
                     "started": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()), "load_before": os.getloadavg()}
    runs = {}
    order = (("pruned", True), ("unpruned", False)) if args.pruned_first else (("unpruned", False), ("pruned", True))
    for name, prune in order:
        if args.side not in (None, name):
            continue
        if args.compare:  # the study's table and figures from an earlier --side run
            runs[name] = pd.read_parquet(out / name / "results.parquet")
            figures[name] = json.loads((out / f"{name}.json").read_text())
            continue
        result = sweep(spec, out / name, args.workers, prune)
        runs[name] = result.pop("table")
        figures[name] = result
        if args.side:
            (out / f"{name}.json").write_text(json.dumps(dict(result, started=figures["started"],
                                                              load_before=figures["load_before"]), default=str))
            print(json.dumps(figures, indent=1, default=str))
            return
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
    # every row the pruned study ran to its end equals the unpruned study's row, every objective bit for bit
    objective_columns = [c for c in full.columns if c not in ("status", "message", "run_time", "worker")
                         and c in pruned.columns and pd.api.types.is_float_dtype(full[c])]
    ok = pruned[pruned["status"] == "ok"].set_index("point_id")[objective_columns]
    same = finals.loc[ok.index, objective_columns]
    differ = [pid for pid in ok.index if not all(
        (a == b) or (a != a and b != b) for a, b in zip(ok.loc[pid].to_numpy(), same.loc[pid].to_numpy()))]
    figures["ok_rows_differing"] = differ
    figures["ok_rows_compared"] = len(ok)
    figures["cpu_ratio"] = round(figures["pruned"]["cpu_points_s"] / figures["unpruned"]["cpu_points_s"], 3)
    figures["process_cpu_ratio"] = round(figures["pruned"]["process_cpu_s"] / figures["unpruned"]["process_cpu_s"], 3)
    stopped = pruned[pruned["status"] == "pruned"]
    if len(stopped) and "pruned_at" in stopped and "duration" in finals:
        share = stopped["pruned_at"].to_numpy(float) / finals.loc[stopped["point_id"], "t_end"].to_numpy(float)
        figures["pruned_at_share_of_run"] = {"median": round(float(np.median(share)), 3),
                                             "quartiles": [round(float(q), 3) for q in np.quantile(share, [0.25, 0.75])]}
    figures["wall_ratio"] = round(figures["pruned"]["wall_s"] / figures["unpruned"]["wall_s"], 3)
    keeper = FrontKeeper(Sweep(spec, workers=1, out=out / "probe", quiet=True, prune=True).prune)
    for _, row in full.iterrows():
        if row["status"] == "ok":
            keeper.add(row["point_id"], row.to_dict())
    started = time.perf_counter()
    for _ in range(1000):
        blob = pickle.dumps(keeper.order())
    figures["front_message"] = {"members": len(keeper.ids), "bytes": len(blob),
                                "pickle_us": round((time.perf_counter() - started) * 1e3, 1)}
    print(json.dumps(figures, indent=1, default=str))
    if not figures["front_identical"] or bad or differ:  # the benchmark's promise: the same answer, proven
        raise SystemExit(f"pruning changed the answer: front identical {figures['front_identical']}, "
                         f"{len(bad)} pruned rows not proven, {len(differ)} ok rows differ")


if __name__ == "__main__":
    main()
