"""Figures and numbers of the optimal-timing study on the thesis's full grid (17061 designs).

Reads ``results_full.parquet`` (spec_full.json: every design of the 1-degree grid at a duration bound of
1.25 x its full-speed blend's, optimal timing and uniformly slowed blend; the columns this analysis and
the README use) and ``../pick_and_place/study/results.parquet`` (the full-speed blend of the same 17061
designs), and writes

- ``figures/energy_saved_full.png``   energy the optimal timing saves at 1.25 x, over the full grid
- ``figures/time_saved_full.png``     time it saves at the slowed blend's energy (lower bound)
- ``results_table_full.md``           the numbers quoted in the README

into ``--out`` (default ``results/optimal_timing/``, which git ignores); ``--tables DIR`` reads the table
run_study.py wrote instead of the committed one.

    python examples/optimal_timing/run_study.py spec_full.json    # the sweep -> results/optimal_timing/results_full.parquet
    python examples/optimal_timing/analyze_full.py --tables results/optimal_timing

``results_full.parquet`` is committed with the columns listed in ``COLUMNS`` only (the sweep's whole table
has 79 columns, ~16 MB): this script drops the others the first time it reads a fresh sweep's table.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from analyze import FACTOR, OPT, Q22, Q24, arguments, grid_plot, paired, summary_table, time_at_reference_energy, where  # noqa: E402

TABLE = "results_full.parquet"
COLUMNS = ["point_id", Q22, Q24, FACTOR, OPT, "e_total", "duration", "blend_duration", "planned_energy", "solve_time",
           "peak_tau_ratio[1]", "peak_tau_ratio[2]", "peak_tau_ratio[4]", "status", "message", "run_time"]


def read_table(folder: Path) -> pd.DataFrame:
    """``results_full.parquet`` of ``folder`` with :data:`COLUMNS`; a fresh sweep's whole table is cut down to
    them in place (the committed one has only them)."""
    df = pd.read_parquet(folder / TABLE)
    if list(df.columns) != COLUMNS:
        df = df[COLUMNS]
        df.to_parquet(folder / TABLE, index=False, compression="zstd")
    return df


def main() -> None:
    args = arguments()
    df = read_table(args.tables)
    blend = pd.read_parquet(HERE.parent / "pick_and_place" / "study" / "results.parquet")
    failed = df[df["status"] != "ok"]
    pairs = time_at_reference_energy(paired(df[df["status"] == "ok"]), blend[blend["status"] == "ok"])
    figures = args.out / "figures"
    figures.mkdir(parents=True, exist_ok=True)
    for name, panels, cmap in (
            ("energy_saved_full.png", (("saved_pct", "energy saved (%)"), ("saved_J", "energy saved (J)")), "viridis"),
            ("time_saved_full.png", (("time_saved_pct", "time saved (%)"), ("time_saved_s", "time saved (s)")), "magma")):
        fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
        for ax, (column, label) in zip(axes, panels):
            grid_plot(ax, pairs, column, label, cmap=cmap)
        what = ("energy saved by the optimal timing at 1.25 x the blend's duration" if name.startswith("energy")
                else "time saved at the slowed blend's energy (lower bound)")
        fig.suptitle(f"{what}: full thesis grid, {len(pairs)} designs")
        fig.tight_layout()
        fig.savefig(figures / name, dpi=110)
        plt.close(fig)

    lines = ["# Optimal-timing study on the full grid: numbers (written by analyze_full.py)", "",
             f"Designs: {len(pairs)} of the thesis's 1-degree grid at a duration bound of 1.25 x the full-speed "
             f"blend's ({len(failed)} failed points).", "",
             *summary_table(pairs)]
    saved = pairs["saved_pct"]
    worse = pairs[pairs["e_total_opt"] > pairs["e_total_ref"] * (1 + 1e-12)]
    lines += ["", "Share of designs by energy saved at the same duration:", "",
              "| saved | designs |", "|---|---|"]
    for lo, hi in ((-np.inf, 0.0), (0.0, 1.0), (1.0, 5.0), (5.0, 10.0), (10.0, np.inf)):
        n = int(((saved > lo) & (saved <= hi)).sum())
        label = "at most 0 %" if lo == -np.inf else f"above {lo:g} %" if hi == np.inf else f"{lo:g} .. {hi:g} %"
        lines.append(f"| {label} | {n} ({100 * n / len(pairs):.1f} %) |")
    lines += ["", f"Designs where the optimal timing used more energy than the slowed blend: {len(worse)}"
              + (f" (largest excess {(-worse['saved_pct']).max():.3f} % at "
                 f"{where(worse.assign(excess=-worse['saved_pct']), 'excess', 'idxmax')[1]})" if len(worse) else "") + ".",
              f"Duration: optimal timing at most the bound in every design: "
              f"{bool((pairs['duration_opt'] <= pairs['duration_ref'] * (1 + 1e-9)).all())}; "
              f"median duration optimal / slowed blend {np.median(pairs['duration_opt'] / pairs['duration_ref']):.3f}.",
              f"Peak torque ratio (joints 1, 2, 4), optimal timing: max "
              f"{pairs[['peak_tau_ratio[1]_opt', 'peak_tau_ratio[2]_opt', 'peak_tau_ratio[4]_opt']].to_numpy().max():.3f} "
              f"(slowed blend {pairs[['peak_tau_ratio[1]_ref', 'peak_tau_ratio[2]_ref', 'peak_tau_ratio[4]_ref']].to_numpy().max():.3f}).",
              ""]
    (args.out / "results_table_full.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
