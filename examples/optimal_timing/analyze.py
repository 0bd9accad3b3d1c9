"""Figures and tables of the optimal-timing study.

Reads ``results.parquet`` (spec.json: 273 designs at a duration bound of 1.25 x
the full-speed blend's, optimal timing and the uniformly slowed blend),
``results_tradeoff.parquet`` (spec_tradeoff.json: 9 designs, bounds 1.0 .. 2.0 x)
and ``../pick_and_place/results_coarse.parquet`` (the full-speed blend of the
same 273 designs), and writes

- ``figures/energy_saved_grid.png``   energy the optimal timing saves at 1.25 x, over the grid
- ``figures/time_saved_grid.png``     time it saves at the slowed blend's energy, over the grid
- ``figures/tradeoff.png``            energy over duration of 9 designs, both timings
- ``results_table.md``                the numbers quoted in the README

into ``--out`` (default ``results/optimal_timing/`` at the repository's root, which git ignores).  The tables
are the committed ones beside this file, or those of ``--tables DIR`` (where run_study.py wrote them).

    python examples/optimal_timing/analyze.py
    python examples/optimal_timing/analyze.py --tables results/optimal_timing    # after run_study.py
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

HERE = Path(__file__).resolve().parent
OUT = HERE.parents[1] / "results" / HERE.name  # git-ignored: running the example leaves the tracked tree as it was
Q22, Q24 = "traj.waypoints[9]", "traj.waypoints[11]"
FACTOR, OPT = "traj.max_duration_factor", "traj.optimize"


def paired(df: pd.DataFrame) -> pd.DataFrame:
    """One row per design and bound: the reference's and the optimal timing's energy and duration."""
    keys = [Q22, Q24, FACTOR]
    cols = ["e_total", "duration", "solve_time", "status", "peak_tau_ratio[1]", "peak_tau_ratio[2]", "peak_tau_ratio[4]"]
    ref = df[~df[OPT].astype(bool)].set_index(keys)[cols]
    opt = df[df[OPT].astype(bool)].set_index(keys)[cols]
    out = ref.add_suffix("_ref").join(opt.add_suffix("_opt")).reset_index()
    out["saved_J"] = out["e_total_ref"] - out["e_total_opt"]
    out["saved_pct"] = 100 * out["saved_J"] / out["e_total_ref"]
    return out


def time_at_reference_energy(pairs: pd.DataFrame, blend: pd.DataFrame) -> pd.DataFrame:
    """Duration at which the optimal timing reaches the slowed blend's energy, by the chord from the
    full-speed blend (the optimal timing at 1.0 x, checked in the trade-off sweep) to the optimal
    timing at the bound.  The energy falls convexly with the duration (figures/tradeoff.png), so the
    chord lies above the curve: this duration is an upper bound, the time saved a lower bound."""
    b = blend.set_index([Q22, Q24])[["e_total", "duration"]].rename(columns={"e_total": "e_blend", "duration": "t_blend"})
    p = pairs.set_index([Q22, Q24]).join(b).reset_index()
    fraction = (p["e_blend"] - p["e_total_ref"]) / (p["e_blend"] - p["e_total_opt"])
    valid = (p["e_total_opt"] < p["e_total_ref"]) & (p["e_total_ref"] < p["e_blend"])
    p["t_same_energy"] = np.where(valid, p["t_blend"] + fraction * (p["duration_opt"] - p["t_blend"]), p["duration_ref"])
    p["time_saved_s"] = p["duration_ref"] - p["t_same_energy"]
    p["time_saved_pct"] = 100 * p["time_saved_s"] / p["duration_ref"]
    return p


def grid_plot(ax, df, column, label, cmap="viridis"):
    table = df.pivot(index=Q24, columns=Q22, values=column)
    x, y = table.columns.to_numpy(), table.index.to_numpy()
    mesh = ax.pcolormesh(x, y, table.to_numpy(), shading="nearest", cmap=cmap)
    ax.set_xlabel("q2[2] (deg, thesis)")
    ax.set_ylabel("q2[4] (deg, thesis)")
    plt.colorbar(mesh, ax=ax, label=label)


def where(df, column, fn):
    row = df.loc[getattr(df[column], fn)()]
    return row[column], (int(row[Q22]), int(row[Q24]))


def summary_table(pairs: pd.DataFrame) -> list[str]:
    """The Markdown lines of the figures' table: median, minimum and maximum of each figure with their design."""
    lines = ["| figure | median | min at (q2[2], q2[4]) | max at |", "|---|---|---|---|"]
    for column, label, fmt in (("saved_pct", "energy saved at the same duration (%)", "{:.2f}"),
                               ("saved_J", "energy saved at the same duration (J)", "{:.2f}"),
                               ("time_saved_pct", "time saved at the same energy, lower bound (%)", "{:.1f}"),
                               ("time_saved_s", "time saved at the same energy, lower bound (s)", "{:.3f}"),
                               ("e_total_ref", "energy, slowed blend (J)", "{:.2f}"),
                               ("e_total_opt", "energy, optimal timing (J)", "{:.2f}"),
                               ("solve_time_opt", "planning time per path in the sweep (s)", "{:.3f}")):
        lo, lo_at = where(pairs, column, "idxmin")
        hi, hi_at = where(pairs, column, "idxmax")
        lines.append(f"| {label} | {fmt.format(pairs[column].median())} | {fmt.format(lo)} {lo_at} | "
                     f"{fmt.format(hi)} {hi_at} |")
    return lines


def main() -> None:
    args = arguments()
    main_df = pd.read_parquet(args.tables / "results.parquet")
    trade = pd.read_parquet(args.tables / "results_tradeoff.parquet")
    blend = pd.read_parquet(HERE.parent / "pick_and_place" / "results_coarse.parquet")
    figures = args.out / "figures"
    figures.mkdir(parents=True, exist_ok=True)
    failed = main_df[main_df["status"] != "ok"]
    pairs = paired(main_df[main_df["status"] == "ok"])
    pairs = time_at_reference_energy(pairs, blend)

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    grid_plot(axes[0], pairs, "saved_pct", "energy saved (%)")
    axes[0].set_title("energy saved by optimal timing at 1.25 x the blend's duration")
    grid_plot(axes[1], pairs, "saved_J", "energy saved (J)")
    axes[1].set_title("the same in J")
    fig.tight_layout()
    fig.savefig(figures / "energy_saved_grid.png", dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    grid_plot(axes[0], pairs, "time_saved_pct", "time saved (%)", cmap="magma")
    axes[0].set_title("time saved at the slowed blend's energy (lower bound)")
    grid_plot(axes[1], pairs, "time_saved_s", "time saved (s)", cmap="magma")
    axes[1].set_title("the same in s")
    fig.tight_layout()
    fig.savefig(figures / "time_saved_grid.png", dpi=110)
    plt.close(fig)

    ok = trade[trade["status"] == "ok"]
    designs = sorted({(a, b) for a, b in zip(ok[Q22], ok[Q24])})
    fig, axes = plt.subplots(3, 3, figsize=(12, 10), sharex=False)
    for ax, (a, b) in zip(axes.ravel(), designs):
        d = ok[(ok[Q22] == a) & (ok[Q24] == b)].sort_values(FACTOR)
        for optimize, style, label in ((False, "o--", "parabolic blend, slowed down"), (True, "s-", "optimal timing")):
            s = d[d[OPT].astype(bool) == optimize]
            ax.plot(s["duration"], s["e_total"], style, label=label)
        ax.set_title(f"q2[2] = {a:g}, q2[4] = {b:g} deg")
        ax.set_xlabel("duration (s)")
        ax.set_ylabel("e_total (J)")
        ax.grid(alpha=0.3)
    axes[0, 0].legend()
    fig.suptitle("time-energy trade-off: duration bound 1.0 .. 2.0 x the full-speed blend's")
    fig.tight_layout()
    fig.savefig(figures / "tradeoff.png", dpi=110)
    plt.close(fig)

    # the optimal timing at 1.0 x is the blend (its duration is the path's minimum time here)
    at_one = ok[ok[FACTOR] == 1.0]
    one = at_one.pivot_table(index=[Q22, Q24], columns=OPT, values=["e_total", "duration"])
    lines = ["# Optimal-timing study: numbers (written by analyze.py)", "",
             f"Designs: {len(pairs)} of the coarse grid at a duration bound of 1.25 x the full-speed blend's "
             f"({len(failed)} failed points).", "",
             *summary_table(pairs)]
    worse = pairs[pairs["e_total_opt"] > pairs["e_total_ref"] * (1 + 1e-12)]  # not rounding-level ties
    lines += ["", f"Designs where the optimal timing used more energy than the slowed blend: {len(worse)}"
              + (f" (largest excess {(-worse['saved_pct']).max():.3f} %)" if len(worse) else "") + ".",
              f"Duration: optimal timing at most the bound in every design: "
              f"{bool((pairs['duration_opt'] <= pairs['duration_ref'] * (1 + 1e-9)).all())}; "
              f"median duration optimal / slowed blend {np.median(pairs['duration_opt'] / pairs['duration_ref']):.3f}.",
              f"Peak torque ratio (joints 1, 2, 4), optimal timing: max {pairs[['peak_tau_ratio[1]_opt', 'peak_tau_ratio[2]_opt', 'peak_tau_ratio[4]_opt']].to_numpy().max():.3f} "
              f"(slowed blend {pairs[['peak_tau_ratio[1]_ref', 'peak_tau_ratio[2]_ref', 'peak_tau_ratio[4]_ref']].to_numpy().max():.3f}).", ""]
    lines += ["Trade-off designs at a bound of 1.0 x (optimal timing vs the full-speed blend):", "",
              "| (q2[2], q2[4]) | blend e_total (J) | optimal e_total (J) | blend duration (s) | optimal duration (s) |",
              "|---|---|---|---|---|"]
    for (a, b), row in one.iterrows():
        lines.append(f"| ({a:g}, {b:g}) | {row[('e_total', False)]:.3f} | {row[('e_total', True)]:.3f} | "
                     f"{row[('duration', False)]:.4f} | {row[('duration', True)]:.4f} |")
    lines += ["", "Trade-off curves (e_total in J at duration bound x the full-speed blend's; duration reached in s):", "",
              "| (q2[2], q2[4]) | timing | " + " | ".join(f"{f:g} x" for f in sorted(ok[FACTOR].unique())) + " |",
              "|---|---|" + "---|" * ok[FACTOR].nunique()]
    for a, b in designs:
        d = ok[(ok[Q22] == a) & (ok[Q24] == b)].sort_values(FACTOR)
        for optimize, name in ((False, "slowed blend"), (True, "optimal")):
            s = d[d[OPT].astype(bool) == optimize]
            cells = " | ".join(f"{e:.2f} ({t:.2f} s)" for e, t in zip(s["e_total"], s["duration"]))
            lines.append(f"| ({a:g}, {b:g}) | {name} | {cells} |")
    (args.out / "results_table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def arguments() -> argparse.Namespace:
    """--tables (where run_study.py wrote; default: the committed tables beside this file), --out."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tables", type=Path, default=HERE,
                        help=f"folder of the study's tables (default: the committed ones, {HERE}; give "
                             f"{OUT} after run_study.py)")
    parser.add_argument("--out", type=Path, default=OUT,
                        help=f"folder of the figures and the table (default: {OUT}, which git ignores; --out "
                             "examples/optimal_timing refreshes the committed ones)")
    return parser.parse_args()


if __name__ == "__main__":
    main()
