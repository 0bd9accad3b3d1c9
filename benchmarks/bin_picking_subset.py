"""Bin picking on a sub-grid of its 2592 placements, checked against the committed table's rows of them.

    python benchmarks/bin_picking_subset.py                       # 96 placements, this tree
    python benchmarks/bin_picking_subset.py --src OTHER/src       # the same with another checkout's sources

The whole study (``examples/bin_picking/spec.json``) costs 4495 s of point run time in its committed table
(about 1.25 h of CPU on two workers); this runs the placements of a sub-grid that keeps both ends of every axis
(offset_x and offset_z at indices 0, 4, 7, 11 of 12, offset_y at 0, 4, 8 of 9, both boxes: 96 points, 29 of them
executed in the committed table, every ``blocked_code`` of the study among them) with ``cosim sweep`` as its own
process, 2 workers, and compares every objective column with the committed rows of the same placements: same
statuses, and per column the points that differ and the largest difference. ``planning_time`` is a wall time
and is not compared. Prints the wall and CPU time (the sweep with every process it started) and exits 1 when an
objective differs by more than ``--tolerance`` (relative; default 0: bit for bit).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
from process_cpu import become_subreaper, reap_orphans

ROOT = Path(__file__).resolve().parents[1]
FOLDER = ROOT / "examples" / "bin_picking"
AXES = {"planner.offset_x": (0, 4, 7, 11), "planner.offset_y": (0, 4, 8), "planner.offset_z": (0, 4, 7, 11)}
KEY = [*AXES, "planner.box_variant"]
NOT_COMPARED = {"point_id", "status", "message", "run_time", "worker", "planning_time"}


def subset_spec(committed: pd.DataFrame, folder: Path, kernel: str | None) -> Path:
    """The study's spec with the sub-grid's values (taken from the committed table, so they match it exactly)."""
    spec = json.loads((FOLDER / "spec.json").read_text())
    for name, indices in AXES.items():
        values = sorted(committed[name].unique())
        spec["design"]["parameters"][name] = {"values": [float(values[i]) for i in indices], "unit": "m"}
    if kernel:
        spec["experiment"]["kernel"] = kernel
    path = folder / "spec.json"
    path.write_text(json.dumps(spec, indent=1))
    return path


def compare(new: pd.DataFrame, committed: pd.DataFrame) -> dict[str, tuple[int, float, float]]:
    """Per objective column of ``new``'s points: (points that differ, largest absolute, largest relative)."""
    merged = new.merge(committed, on=KEY, suffixes=("_new", "_old"))
    assert len(merged) == len(new), "a placement of the run is not in the committed table"
    assert (merged["status_new"] == merged["status_old"]).all(), "a placement's status differs"
    columns: dict[str, tuple[int, float, float]] = {}
    for column in committed.columns:
        if column in NOT_COMPARED or column in KEY or not pd.api.types.is_numeric_dtype(committed[column]):
            continue
        old, got = merged[f"{column}_old"].to_numpy(float), merged[f"{column}_new"].to_numpy(float)
        same = (old == got) | (np.isnan(old) & np.isnan(got))
        absolute = np.abs(np.where(same, 0.0, got - old))
        relative = absolute / np.maximum(np.abs(old), 1e-300)
        worst = float("inf") if np.isnan(relative).any() else float(relative.max(initial=0.0))
        columns[column] = (int((~same).sum()), float(np.nanmax(absolute, initial=0.0)), worst)
    return columns


def run(spec: Path, out: Path, src: Path, workers: int) -> tuple[float, float]:
    """(wall, CPU) seconds of ``cosim sweep`` with ``src`` first on the path; exits on failure."""
    env = dict(os.environ, PYTHONPATH=str(src))
    command = [sys.executable, "-m", "cosim.cli.main", "sweep", str(spec), "--out", str(out),
               "--workers", str(workers), "--timeout", "600"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - started
    reap_orphans()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        sys.exit(f"the sweep failed (exit code {done.returncode}):\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}")
    return wall, after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--src", type=Path, default=ROOT / "src", help="the sources to run (default: this tree's)")
    parser.add_argument("--kernel", choices=["auto", "native", "python"], help="experiment.kernel (default: the spec's)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--tolerance", type=float, default=0.0, help="largest relative difference accepted")
    parser.add_argument("--keep", type=Path, help="also copy the new table to this file")
    args = parser.parse_args()
    become_subreaper()  # the sweep's processes are counted even if orphaned (process_cpu.py)
    committed = pd.read_parquet(FOLDER / "results.parquet")
    with tempfile.TemporaryDirectory(prefix="cosim_bin_picking_") as scratch:
        spec = subset_spec(committed, Path(scratch), args.kernel)
        wall, cpu = run(spec, Path(scratch) / "sweep", args.src.resolve(), args.workers)
        table = pd.read_parquet(Path(scratch) / "sweep" / "results.parquet")
    if args.keep:
        table.to_parquet(args.keep)
    columns = compare(table, committed)
    load = os.getloadavg()
    print(f"# bin picking, {len(table)} placements of 2592, {args.workers} workers, sources {args.src}; "
          f"{platform.machine()}, {os.cpu_count()} cores, load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}, "
          f"{time.strftime('%Y-%m-%d %H:%M %Z')}")
    print(f"cosim sweep: {wall:.1f} s wall, {cpu:.1f} s CPU (the sweep and every process it started); statuses "
          f"{table['status'].value_counts().to_dict()}; run_time sum {table['run_time'].sum():.1f} s "
          f"(the committed rows: {committed.merge(table[KEY], on=KEY)['run_time'].sum():.1f} s)")
    differing = {name: value for name, value in columns.items() if value[0]}
    print(f"{len(columns)} objective columns compared; {len(columns) - len(differing)} equal bit for bit")
    for name, (count, absolute, relative) in differing.items():
        print(f"  {name}: {count} of {len(table)} points differ, largest {absolute:.3g} absolute, {relative:.3g} relative")
    worst = max((relative for _, _, relative in columns.values()), default=0.0)
    print(f"largest relative difference: {worst:.3g} ({'within' if worst <= args.tolerance else 'OUTSIDE'} "
          f"{args.tolerance:g})")
    if worst > args.tolerance:
        sys.exit(1)


if __name__ == "__main__":
    main()
