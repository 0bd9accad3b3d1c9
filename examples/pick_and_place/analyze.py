"""Figures and the minima/maxima table of the pick-and-place study, beside the thesis's values.

Reads ``study/results.parquet`` (the full study, written by run_study.py) and writes

- ``figures/energy_grid.png``            total electric energy over the grid (thesis fig. 8-1)
- ``figures/joint_energy_grid.png``      energy of joints 1, 2 and 4 (fig. 8-2, 8-3, 8-4)
- ``figures/energy_vs_joint_distance.png``      (fig. 8-5)
- ``figures/energy_vs_cartesian_distance.png``  (fig. 8-6)
- ``figures/distances_time_energy_3d.png``  (fig. 8-7)
- ``figures/peak_torque_and_limits.png``  what the thesis did not show: peak torque ratio, position limits
- ``results_table.md``                   our minima and maxima, where they occur, and table 8-1

    python examples/pick_and_place/analyze.py [TABLE] [--out DIR]

TABLE is the committed ``study/results.parquet`` unless given (run_study.py writes
``results/pick_and_place/study/results.parquet``); the figures and the table go to ``--out`` (default
``results/pick_and_place/`` at the repository's root, which git ignores; ``--out examples/pick_and_place``
refreshes the committed ones).
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
sys.path.insert(0, str(HERE.parents[1]))
OUT = HERE.parents[1] / "results" / HERE.name  # git-ignored: running the example leaves the tracked tree as it was
from cosim.models.panda_model import FRANKA_DOC_LIMITS  # noqa: E402

Q22, Q24 = "traj.waypoints[9]", "traj.waypoints[11]"

# Table 8-1 and the locations section 8.1 gives: (min, where, max, where); None where the thesis does not say.
THESIS = {
    "e_total": ("Total electric energy E_el", "Ws = J", (19.46, (0, 0)), (110.02, (-100, 140))),
    "e_el[1]": ("Electric energy joint 1", "Ws = J", (5.08, (-100, 0)), (40.27, (-74, 85))),
    "e_el[2]": ("Electric energy joint 2", "Ws = J", (4.78, (1, 76)), (63.88, (-100, 126))),
    "e_el[4]": ("Electric energy joint 4", "Ws = J", (1.31, (20, 0)), (35.64, (-86, 140))),
    "duration": ("Execution time t", "s", (1.28, None), (2.12, None)),
    "joint_distance": ("Total joint distance", "deg", (177.5, (0, 0)), (590.2, (-100, 140))),
    "cartesian_distance": ("Total Cartesian distance", "m", (2.17, (-100, 140)), (2.90, (20, 140))),
    "avg_joint_velocity[1]": ("Average joint velocity 1", "deg/s", (78.5, None), (129.5, None)),
    "avg_joint_velocity[2]": ("Average joint velocity 2", "deg/s", (0.5, None), (88.0, None)),
    "avg_joint_velocity[4]": ("Average joint velocity 4", "deg/s", (0.8, None), (120.3, None)),
}
# Further points section 8.1 quotes: (q2[2], q2[4]) -> {objective: thesis value}
THESIS_POINTS = {
    (-100, 140): {"e_total": 109.95, "joint_distance": 590.2, "cartesian_distance": 2.17},
    (0, 140): {"e_total": 34.42, "joint_distance": 428.8},
    (-91, 88): {"e_total": 100.21, "joint_distance": 429.0},
    (20, 140): {"e_total": 39.86, "cartesian_distance": 2.90},
    (0, 0): {"e_total": 19.46, "joint_distance": 177.5, "cartesian_distance": 2.27},
}


def grid(df: pd.DataFrame, column: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """x (q2[2]), y (q2[4]) axes and the column as a 2-D array (rows: q2[4])."""
    table = df.pivot_table(index=Q24, columns=Q22, values=column)
    return table.columns.to_numpy(), table.index.to_numpy(), table.to_numpy()


def grid_plot(ax, df, column, label):
    x, y, z = grid(df, column)
    step_x = x[1] - x[0] if len(x) > 1 else 1
    step_y = y[1] - y[0] if len(y) > 1 else 1
    im = ax.imshow(z, origin="lower", aspect="auto", cmap="turbo",
                   extent=(x[0] - step_x / 2, x[-1] + step_x / 2, y[0] - step_y / 2, y[-1] + step_y / 2))
    i = np.unravel_index(np.nanargmin(z), z.shape)
    k = np.unravel_index(np.nanargmax(z), z.shape)
    ax.plot(x[i[1]], y[i[0]], "wo", mec="k", label=f"min {z[i]:.2f} at ({x[i[1]]:g}, {y[i[0]]:g})")
    ax.plot(x[k[1]], y[k[0]], "w^", mec="k", label=f"max {z[k]:.2f} at ({x[k[1]]:g}, {y[k[0]]:g})")
    ax.set_xlabel("q2[2] (deg, thesis convention)")
    ax.set_ylabel("q2[4] (deg)")
    ax.legend(loc="upper right", fontsize=7)
    plt.colorbar(im, ax=ax, label=label)


def where(df: pd.DataFrame, column: str, fn: str) -> tuple[float, tuple[int, int]]:
    row = df.loc[df[column].idxmin() if fn == "min" else df[column].idxmax()]
    return float(row[column]), (int(round(row[Q22])), int(round(row[Q24])))


def fmt_loc(loc) -> str:
    return "" if loc is None else f"({loc[0]}, {loc[1]})"


def table(df: pd.DataFrame) -> str:
    lines = ["| objective | unit | ours: min at (q2[2], q2[4]) | thesis: min at | ours: max at | thesis: max at |",
             "|---|---|---|---|---|---|"]
    for column, (label, unit, tmin, tmax) in THESIS.items():
        vmin, lmin = where(df, column, "min")
        vmax, lmax = where(df, column, "max")
        lines.append(f"| {label} (`{column}`) | {unit} | {vmin:.2f} {fmt_loc(lmin)} | {tmin[0]:.2f} {fmt_loc(tmin[1])} "
                     f"| {vmax:.2f} {fmt_loc(lmax)} | {tmax[0]:.2f} {fmt_loc(tmax[1])} |")
    lines += ["", "Points section 8.1 quotes, ours beside the thesis's:", "",
              "| (q2[2], q2[4]) | objective | ours | thesis |", "|---|---|---|---|"]
    indexed = df.set_index([df[Q22].round().astype(int), df[Q24].round().astype(int)])
    for point, values in THESIS_POINTS.items():
        for column, value in values.items():
            ours = float(indexed.loc[point, column])
            lines.append(f"| {point} | `{column}` | {ours:.2f} | {value:.2f} |")
    lines += ["", "Beyond the thesis (not in table 8-1):", "", "| objective | min at | max at |", "|---|---|---|"]
    for column in ("peak_tau_ratio[1]", "peak_tau_ratio[2]", "peak_tau_ratio[4]", "e_total_no_recuperation"):
        vmin, lmin = where(df, column, "min")
        vmax, lmax = where(df, column, "max")
        lines.append(f"| `{column}` | {vmin:.3f} {fmt_loc(lmin)} | {vmax:.3f} {fmt_loc(lmax)} |")
    q2_over = df["q_highest[2]"] > FRANKA_DOC_LIMITS.q_max[1] + 1e-9
    q4_over = df["q_highest[4]"] > FRANKA_DOC_LIMITS.q_max[3] + 1e-9
    tau_over = df[[f"peak_tau_ratio[{j}]" for j in range(1, 8)]].max(axis=1) > 1
    lines += ["", f"Limit checks over all {len(df)} points (Franka documentation limits): "
              f"joint 4 above its upper limit (-4 deg URDF) in {int(q4_over.sum())} points "
              f"(the stretched start and goal poses have URDF q4 = 0); joint 2 above its upper limit "
              f"(101 deg URDF, thesis q2[2] > 11 deg) in {int(q2_over.sum())} points; a torque above its limit in "
              f"{int(tau_over.sum())} points; `limit_violated` is 1 in {int((df['limit_violated'] > 0).sum())} points."]
    return "\n".join(lines) + "\n"


def main() -> None:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("table", nargs="?", type=Path, default=HERE / "study" / "results.parquet",
                        help="the study's table (default: the committed study/results.parquet)")
    parser.add_argument("--out", type=Path, default=OUT, help=f"folder of figures/ and results_table.md (default: {OUT})")
    args = parser.parse_args()
    df = pd.read_parquet(args.table)
    df = df[df["status"] == "ok"].reset_index(drop=True)
    out = args.out / "figures"
    out.mkdir(parents=True, exist_ok=True)

    fig, ax = plt.subplots(figsize=(7, 5))
    grid_plot(ax, df, "e_total", "total electric energy E_el (J)")
    ax.set_title("Total electric energy (cf. thesis fig. 8-1)")
    fig.tight_layout()
    fig.savefig(out / "energy_grid.png", dpi=120)
    plt.close(fig)

    fig, axes = plt.subplots(1, 3, figsize=(17, 4.6))
    for ax, j, n in zip(axes, (1, 2, 4), ("8-2", "8-3", "8-4")):
        grid_plot(ax, df, f"e_el[{j}]", f"E_el[{j}] (J)")
        ax.set_title(f"Joint {j} electric energy (cf. fig. {n})")
    fig.tight_layout()
    fig.savefig(out / "joint_energy_grid.png", dpi=110)
    plt.close(fig)

    for column, name, label, number in (("joint_distance", "energy_vs_joint_distance.png", "total joint distance (deg)", "8-5"),
                                        ("cartesian_distance", "energy_vs_cartesian_distance.png",
                                         "total Cartesian distance of the TCP (m)", "8-6")):
        fig, ax = plt.subplots(figsize=(7, 5))
        sc = ax.scatter(df[column], df["e_total"], c=df["duration"], s=3, cmap="viridis")
        plt.colorbar(sc, ax=ax, label="execution time (s)")
        ax.set_xlabel(label)
        ax.set_ylabel("total electric energy (J)")
        ax.set_title(f"Energy over {label.split(' (')[0]} (cf. fig. {number})")
        fig.tight_layout()
        fig.savefig(out / name, dpi=120)
        plt.close(fig)

    fig = plt.figure(figsize=(8, 6))
    ax = fig.add_subplot(projection="3d")
    sc = ax.scatter(df["cartesian_distance"], df["joint_distance"], df["duration"], c=df["e_total"], s=2, cmap="turbo")
    ax.set_xlabel("Cartesian distance (m)")
    ax.set_ylabel("joint distance (deg)")
    ax.set_zlabel("execution time (s)")
    plt.colorbar(sc, ax=ax, shrink=0.7, label="total electric energy (J)")
    ax.set_title("Distances, time and energy (cf. fig. 8-7)")
    fig.tight_layout()
    fig.savefig(out / "distances_time_energy_3d.png", dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(13, 4.6))
    df["peak_tau_ratio_max"] = df[[f"peak_tau_ratio[{j}]" for j in range(1, 8)]].max(axis=1)
    grid_plot(axes[0], df, "peak_tau_ratio_max", "max over joints of peak |tau| / tau_max")
    axes[0].set_title("Peak torque relative to the limit")
    df["q2_excess_deg"] = np.rad2deg(df["q_highest[2]"] - FRANKA_DOC_LIMITS.q_max[1]).clip(lower=0)
    grid_plot(axes[1], df, "q2_excess_deg", "joint 2 beyond its upper limit (deg)")
    axes[1].set_title("Joint 2 position limit excess (joint 4 is 4 deg beyond everywhere)")
    fig.tight_layout()
    fig.savefig(out / "peak_torque_and_limits.png", dpi=110)
    plt.close(fig)

    text = table(df)
    (args.out / "results_table.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
