"""Table 8-1 of the thesis beside our study with the datasheet joint speeds and with Franka's documented limits.

Reads ``results_coarse_datasheet.parquet`` (spec_coarse_datasheet.json: the
coarse grid with the Panda datasheet's joint speeds, 150 deg/s joints 1-4 and
180 deg/s joints 5-7) and ``results_coarse.parquet`` (spec_coarse.json:
Franka's documentation limits), and writes ``results_datasheet_table.md``:
every row of table 8-1, min and max with where they occur, for the thesis and
both runs of ours; and the execution times over the thesis's full 1-degree grid
from the trajectory planner alone (the time needs no simulation).

    python examples/pick_and_place/run_study.py spec_coarse_datasheet.json --out /tmp/ds --table results_coarse_datasheet.parquet
    python examples/pick_and_place/datasheet_table.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from analyze import THESIS, fmt_loc, where  # noqa: E402

sys.path.insert(0, str(HERE.parents[1]))
from cosim.models.panda_model import DATASHEET_VELOCITY, FRANKA_DOC_LIMITS, thesis_to_urdf  # noqa: E402
from cosim.models.trajectory import plan_parabolic_blend  # noqa: E402


def full_grid_durations(speeds) -> tuple[tuple[float, tuple], tuple[float, tuple]]:
    """(min, where), (max, where) of the parabolic blend's duration over the 121 x 141 thesis grid."""
    times = {(a, b): plan_parabolic_blend(thesis_to_urdf([[0] * 7, [-90, a, 0, b, 0, 0, 0], [-180, 0, 0, 0, 0, 0, 0]]),
                                          speeds, FRANKA_DOC_LIMITS.qdd_max).duration
             for a in range(-100, 21) for b in range(0, 141)}
    lo, hi = min(times, key=times.get), max(times, key=times.get)
    return (times[lo], lo), (times[hi], hi)


def main() -> None:
    runs = {"datasheet speeds": pd.read_parquet(HERE / "results_coarse_datasheet.parquet"),
            "documentation limits": pd.read_parquet(HERE / "results_coarse.parquet")}
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
    text = "\n".join(lines) + (f"\n\nOurs on the coarse grid (q2[2] every 10 deg, q2[4] every 7 deg; {counts}), the "
                               "thesis's on its 1-degree grid; its rows for q2[2] and q2[4] are the grid itself.\n\n")
    text += "Execution time over the full 1-degree grid (17061 designs), from the trajectory planner alone:\n\n"
    text += "| joint speeds | min at (q2[2], q2[4]) | max at | thesis |\n|---|---|---|---|\n"
    for label, speeds in (("datasheet (150/180 deg/s)", DATASHEET_VELOCITY), ("documentation (2.175/2.61 rad/s)",
                                                                             FRANKA_DOC_LIMITS.qd_max)):
        (tmin, at_min), (tmax, at_max) = full_grid_durations(speeds)
        text += f"| {label} | {tmin:.3f} s {fmt_loc(at_min)} | {tmax:.3f} s {fmt_loc(at_max)} | 1.28-2.12 s |\n"
    (HERE / "results_datasheet_table.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
