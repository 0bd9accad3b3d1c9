"""Run the optimal-timing study's sweeps and store their tables in results/optimal_timing/ (zstd Parquet).

Uses the engine's sweep (``cosim.sweep``: Dask worker processes, units
reused per worker).  Writes ``results.parquet`` (spec.json) and
``results_tradeoff.parquet`` (spec_tradeoff.json), each with a ``*_run.json``
(points, status counts, wall time, machine load), into ``--out`` (default ``results/optimal_timing/`` at the
repository's root, which git ignores; ``--out examples/optimal_timing`` refreshes the committed tables).

    python examples/optimal_timing/run_study.py                 # both specs, 2 workers
    python examples/optimal_timing/run_study.py spec_tradeoff.json
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = HERE.parents[1] / "results" / HERE.name  # git-ignored: running the example leaves the tracked tree as it was
TABLES = {"spec.json": "results.parquet", "spec_tradeoff.json": "results_tradeoff.parquet",
          "spec_full.json": "results_full.parquet"}


def run(spec: str, workers: int, folder: Path) -> None:
    import cosim

    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as out:
        df = cosim.sweep(HERE / spec, workers=workers, out=out)
    wall = time.perf_counter() - started
    table = TABLES[spec]
    df.to_parquet(folder / table, index=False, compression="zstd")
    summary = {"spec": spec, "points": len(df), "status": df["status"].value_counts().to_dict(),
               "wall_s": round(wall, 1), "workers": workers,
               "median_run_time_ms": round(float(df["run_time"].median()) * 1e3, 2),
               "date_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M"),
               "load_average_at_end": [round(x, 2) for x in os.getloadavg()]}
    print(json.dumps(summary))
    (folder / (Path(table).stem + "_run.json")).write_text(json.dumps(summary, indent=2) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("specs", nargs="*", default=list(TABLES), help="spec files in this folder (default: both)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=OUT,
                        help=f"folder of the tables (default: {OUT}; --out examples/optimal_timing refreshes the "
                             "committed ones)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for spec in args.specs:
        run(spec, args.workers, args.out)


if __name__ == "__main__":
    main()
