"""Table 8-1 of the thesis beside our full-grid studies with the datasheet joint speeds and with Franka's documented limits.

Reads ``results_datasheet.parquet`` (spec_datasheet.json: the thesis's full 1-degree grid, 17061 designs,
with the Panda datasheet's joint speeds, 150 deg/s joints 1-4 and 180 deg/s joints 5-7; the table-8-1
columns of its sweep) and ``study/results.parquet`` (spec.json: the same grid with Franka's documentation
limits), and writes ``results_datasheet_table.md``: every row of table 8-1, min and max with where they
occur, for the thesis and both runs of ours; and what the shortest execution time needs.

    python examples/pick_and_place/run_study.py spec_datasheet.json --out /tmp/ds --table results/pick_and_place/results_datasheet.parquet
    python examples/pick_and_place/datasheet_table.py --tables results/pick_and_place

The tables are the committed ones beside this file unless ``--tables DIR`` is given; the Markdown table goes to
``--out`` (default ``results/pick_and_place/`` at the repository's root, which git ignores).

``results_datasheet.parquet`` is committed with the table-8-1 columns only (the sweep's whole table has 74
columns, ~6 MB): this script drops the others the first time it reads a fresh sweep's table.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import pandas as pd

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from analyze import Q22, Q24, THESIS, fmt_loc, where  # noqa: E402

sys.path.insert(0, str(HERE.parents[1]))
OUT = HERE.parents[1] / "results" / HERE.name  # git-ignored: running the example leaves the tracked tree as it was
from cosim.models.panda_model import DATASHEET_VELOCITY, FRANKA_DOC_LIMITS  # noqa: E402

TABLE = "results_datasheet.parquet"
THESIS_SHORTEST = 1.28  # s, table 8-1


def read_table(folder: Path) -> pd.DataFrame:
    """``results_datasheet.parquet`` with the parameters, table-8-1 objectives, status and run time; a fresh
    sweep's whole table is cut down to them in place."""
    columns = ["point_id", Q22, Q24, *THESIS, "status", "run_time"]
    df = pd.read_parquet(folder / TABLE)
    if list(df.columns) != columns:
        df = df[columns]
        df.to_parquet(folder / TABLE, index=False, compression="zstd")
    return df


def turn_time(speed: float, acceleration: float, angle: float = math.pi) -> float:
    """Duration of a rest-to-rest turn by ``angle`` with a trapezoidal speed profile (parabolic blends)."""
    return angle / speed + speed / acceleration


def speed_for(duration: float, acceleration: float, angle: float = math.pi) -> float:
    """The cruise speed at which :func:`turn_time` equals ``duration`` (the smaller root)."""
    return (duration - math.sqrt(duration**2 - 4 * angle / acceleration)) * acceleration / 2


def main() -> None:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tables", type=Path, default=HERE,
                        help=f"folder of results_datasheet.parquet and study/results.parquet (default: {HERE})")
    parser.add_argument("--out", type=Path, default=OUT, help=f"folder of results_datasheet_table.md (default: {OUT})")
    args = parser.parse_args()
    runs = {"datasheet speeds": read_table(args.tables),
            "documentation limits": pd.read_parquet(args.tables / "study" / "results.parquet")}
    runs = {k: df[df["status"] == "ok"].reset_index(drop=True) for k, df in runs.items()}
    head = "| table 8-1 row | unit | thesis min | " + " | ".join(f"ours, {k}: min at (q2[2], q2[4])" for k in runs) \
        + " | thesis max | " + " | ".join(f"ours, {k}: max at" for k in runs) + " |"
    lines = [head, "|---|---|---|" + "---|" * len(runs) + "---|" + "---|" * len(runs)]
    for column, (label, unit, tmin, tmax) in THESIS.items():
        mins = [where(df, column, "min") for df in runs.values()]
        maxs = [where(df, column, "max") for df in runs.values()]
        lines.append(f"| {label} (`{column}`) | {unit} | {tmin[0]:.2f} {fmt_loc(tmin[1])} | "
                     + " | ".join(f"{v:.2f} {fmt_loc(at)}" for v, at in mins)
                     + f" | {tmax[0]:.2f} {fmt_loc(tmax[1])} | "
                     + " | ".join(f"{v:.2f} {fmt_loc(at)}" for v, at in maxs) + " |")
    counts = ", ".join(f"{k}: {len(df)} ok points" for k, df in runs.items())
    text = "\n".join(lines) + (f"\n\nOurs and the thesis's on the full 1-degree grid ({counts}); the thesis's rows for "
                               "q2[2] and q2[4] are the grid itself.\n\n")
    a1 = float(FRANKA_DOC_LIMITS.qdd_max[0])
    text += ("The shortest motion is a 180 deg turn of joint 1 (the other joints move less): rest to rest with "
             f"parabolic blends at joint 1's {a1:g} rad/s^2 it takes pi/v + v/a.\n\n"
             "| joint-1 speed v | 180 deg turn (s) | shortest in our grid (s) |\n|---|---|---|\n")
    for label, speeds, df in (("datasheet", DATASHEET_VELOCITY, runs["datasheet speeds"]),
                              ("documentation", FRANKA_DOC_LIMITS.qd_max, runs["documentation limits"])):
        v = float(speeds[0])
        text += (f"| {label}: {v:.3f} rad/s = {math.degrees(v):.1f} deg/s | {turn_time(v, a1):.3f} | "
                 f"{df['duration'].min():.3f} |\n")
    v128 = speed_for(THESIS_SHORTEST, a1)
    text += (f"| needed for the thesis's {THESIS_SHORTEST} s | {v128:.3f} rad/s = {math.degrees(v128):.1f} deg/s | "
             f"(with infinite acceleration at 150 deg/s: {math.pi / float(DATASHEET_VELOCITY[0]):.3f} s) |\n")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "results_datasheet_table.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
