"""Run the full pick-and-place study (17061 points) and store its table as zstd Parquet.

Uses the engine's sweep (``cosim.sweep``: Dask worker processes, units
reused per worker, rows streamed to a results folder), then writes the table
as ``results/pick_and_place/study/results.parquet`` (zstd; results/ at the repository's root, which git
ignores) with the sweep's ``metadata.json`` and prints the wall time.  ``--table
examples/pick_and_place/study/results.parquet`` refreshes the committed table.

    python examples/pick_and_place/run_study.py                  # spec.json, 2 workers
    python examples/pick_and_place/run_study.py spec_coarse.json --out /tmp/coarse --table results/pick_and_place/results_coarse.parquet

An interrupted run continues with ``--resume`` (same ``--out``).
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = HERE.parents[1] / "results" / HERE.name  # git-ignored: running the example leaves the tracked tree as it was


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("spec", nargs="?", default="spec.json", help="spec file in this folder (default spec.json)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default=str(OUT / "sweep_full"), help=f"sweep results folder (default: {OUT}/sweep_full)")
    parser.add_argument("--table", type=Path, default=OUT / "study" / "results.parquet",
                        help="the table to write; named results.parquet, it gets the sweep's metadata.json beside it "
                             f"(a sweep folder that report, pareto and explore open alone) (default: {OUT}/study/"
                             "results.parquet)")
    parser.add_argument("--resume", action="store_true")
    args = parser.parse_args()

    import cosim

    started = time.perf_counter()
    df = cosim.sweep(HERE / args.spec, workers=args.workers, out=args.out, resume=args.resume)
    wall = time.perf_counter() - started
    table = args.table
    table.parent.mkdir(parents=True, exist_ok=True)
    df.to_parquet(table, index=False, compression="zstd")
    if table.name == "results.parquet":  # its own folder: keep the sweep's metadata with it
        shutil.copy(Path(args.out) / "metadata.json", table.parent / "metadata.json")
    summary = {"spec": args.spec, "points": len(df), "status": df["status"].value_counts().to_dict(),
               "wall_s": round(wall, 1), "workers": args.workers,
               "median_run_time_ms": round(float(df["run_time"].median()) * 1e3, 2)}
    print(json.dumps(summary))
    (table.parent / (table.stem + "_run.json")).write_text(json.dumps(summary, indent=2) + "\n")


if __name__ == "__main__":
    main()
