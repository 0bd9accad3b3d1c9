"""The optimiser's front against the Latin hypercube's, and what the front's designs look like.

Reads results_optimize/ (`cosim optimize spec.json`) and results_lhs/ (`cosim sweep spec.json`, the Latin
hypercube of the same budget): the committed folders beside this file, or those given by ``--optimize`` and
``--lhs``; writes front_vs_lhs.png, hypervolume.png and results_summary.md into ``--out`` (default
``results/pick_and_place_free_pose/`` at the repository's root, which git ignores; ``--out
examples/pick_and_place_free_pose`` refreshes the committed ones).

    python examples/pick_and_place_free_pose/compare.py
    python examples/pick_and_place_free_pose/compare.py --optimize results/pick_and_place_free_pose/optimize --lhs results/pick_and_place_free_pose/lhs
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))
OUT = HERE.parents[1] / "results" / HERE.name  # git-ignored: running the example leaves the tracked tree as it was

from cosim.analysis.hypervolume import hypervolume, normalised_losses  # noqa: E402
from cosim.analysis.pareto import pareto_mask  # noqa: E402
from cosim.analysis.plots import new_figure, save  # noqa: E402

OBJ = ["e_total", "duration"]
JOINTS = [f"traj.waypoints[{8 + j}]" for j in range(7)]
SCALE = "traj.velocity_scale"


def feasible(df: pd.DataFrame) -> pd.Series:
    """ok and every joint's peak torque within its limit (recomputed from the table, not from `feasible`)."""
    ratio = df[[f"peak_tau_ratio[{j}]" for j in range(1, 8)]].max(axis=1)
    return (df["status"] == "ok") & (ratio <= 1.0)


def front(df: pd.DataFrame) -> pd.DataFrame:
    good = df[feasible(df)]
    return good[pareto_mask(good[OBJ].to_numpy(float))].sort_values("duration")


def hv_history(df: pd.DataFrame, ideal: np.ndarray, nadir: np.ndarray) -> np.ndarray:
    ok = feasible(df).to_numpy()
    losses = normalised_losses(df[OBJ].to_numpy(float), ["min", "min"], ideal, nadir)
    out, current = np.zeros(len(df)), np.zeros((0, 2))
    for i in range(len(df)):
        if ok[i]:
            current = np.vstack([current, losses[i]])
            current = current[pareto_mask(current)]
        out[i] = hypervolume(current)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--optimize", type=Path, default=HERE / "results_optimize",
                        help="folder of the optimisation (default: the committed results_optimize/)")
    parser.add_argument("--lhs", type=Path, default=HERE / "results_lhs",
                        help="folder of the Latin hypercube sweep (default: the committed results_lhs/)")
    parser.add_argument("--out", type=Path, default=OUT, help=f"folder of the figures and the summary (default: {OUT})")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    opt = pd.read_parquet(args.optimize / "results.parquet").sort_values("trial")
    lhs = pd.read_parquet(args.lhs / "results.parquet")
    f_opt, f_lhs = front(opt), front(lhs)
    both = pd.concat([f_opt, f_lhs])
    ideal, nadir = both[OBJ].min().to_numpy(float), both[OBJ].max().to_numpy(float)
    h_opt, h_lhs = hv_history(opt, ideal, nadir), hv_history(lhs, ideal, nadir)

    fig = new_figure(7.5, 5.0)
    ax = fig.add_subplot(111)
    for df, colour, label in ((lhs, "tab:orange", "Latin hypercube"), (opt, "tab:blue", "cosim optimize (TPE)")):
        good = feasible(df)
        ax.scatter(df.loc[good, "duration"], df.loc[good, "e_total"], s=6, alpha=0.35, color=colour,
                   label=f"{label}: {int(good.sum())} feasible of {len(df)}")
    for f, colour in ((f_lhs, "tab:orange"), (f_opt, "tab:blue")):
        ax.step(f["duration"], f["e_total"], where="post", color=colour, lw=2)
    ax.set_xlabel("execution time duration [s]")
    ax.set_ylabel("total electric energy e_total [J]")
    ax.set_xlim(0, min(float(np.nanmax(pd.concat([opt, lhs])["duration"])), 3 * float(nadir[1])))
    ax.set_ylim(0, 3 * float(nadir[0]))
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title("feasible designs (peak torque within limits) and their fronts")
    save(fig, args.out / "front_vs_lhs.png")

    fig = new_figure(6.5, 4.0)
    ax = fig.add_subplot(111)
    ax.plot(np.arange(1, len(h_opt) + 1), h_opt, label="cosim optimize (TPE)")
    ax.plot(np.arange(1, len(h_lhs) + 1), h_lhs, label="Latin hypercube (sweep order)")
    ax.set_xlabel("evaluations")
    ax.set_ylabel("hypervolume (scaled to the two fronts)")
    ax.grid(alpha=0.3)
    ax.legend()
    save(fig, args.out / "hypervolume.png")

    def at(history: np.ndarray, share: float) -> str:
        hit = np.flatnonzero(history >= share * h_lhs[-1])
        return str(int(hit[0]) + 1) if len(hit) else "—"

    lines = ["# Free intermediate pose: results (written by compare.py)", "",
             "| | cosim optimize (TPE) | Latin hypercube |", "|---|---|---|",
             f"| evaluations | {len(opt)} | {len(lhs)} |",
             f"| not ok | {int((opt['status'] != 'ok').sum())} | {int((lhs['status'] != 'ok').sum())} |",
             f"| feasible (peak torque <= limit) | {int(feasible(opt).sum())} | {int(feasible(lhs).sum())} |",
             f"| front size | {len(f_opt)} | {len(f_lhs)} |",
             f"| hypervolume (both fronts scaled to [0, 1], reference 1.1) | {h_opt[-1]:.4f} | {h_lhs[-1]:.4f} |",
             f"| evaluations to the Latin hypercube's final hypervolume | {at(h_opt, 1.0)} | {len(lhs)} |",
             f"| least energy, J (its time, s) | {f_opt['e_total'].min():.2f} ({f_opt.iloc[-1]['duration']:.2f}) "
             f"| {f_lhs['e_total'].min():.2f} ({f_lhs.iloc[-1]['duration']:.2f}) |",
             f"| shortest time, s (its energy, J) | {f_opt['duration'].min():.3f} ({f_opt.iloc[0]['e_total']:.2f}) "
             f"| {f_lhs['duration'].min():.3f} ({f_lhs.iloc[0]['e_total']:.2f}) |",
             "", "The optimiser's front (thesis degrees; q2 = the intermediate pose; v = velocity scale):", "",
             "| duration s | e_total J | " + " | ".join(f"q2[{j}]" for j in range(1, 8)) + " | v | peak torque ratio |",
             "|" + "---|" * 11]
    for _, row in f_opt.iterrows():
        peak = max(row[f"peak_tau_ratio[{j}]"] for j in range(1, 8))
        lines.append(f"| {row['duration']:.3f} | {row['e_total']:.2f} | "
                     + " | ".join(f"{row[c]:.0f}" for c in JOINTS) + f" | {row[SCALE]:.2f} | {peak:.2f} |")
    (args.out / "results_summary.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines[:14]))


if __name__ == "__main__":
    main()
