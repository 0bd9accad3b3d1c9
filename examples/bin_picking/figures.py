"""Figures of the bin-picking study: the plant, and the sweep's results like thesis fig. 8-8..8-12.

Usage (from the repository root)::

    python examples/bin_picking/figures.py                      # plant.png only
    python examples/bin_picking/figures.py results.parquet      # plus the result figures

Writes PNG files into ``--out`` (default ``results/bin_picking/`` at the repository's root, which git ignores;
``--out examples/bin_picking`` refreshes the committed figures), with matplotlib's Agg backend.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))
OUT = HERE.parents[1] / "results" / HERE.name  # git-ignored: running the example leaves the tracked tree as it was

from cosim.models.collision import CellCollision  # noqa: E402
from cosim.models.planner import CartesianPlanner  # noqa: E402
from cosim.models.plant import load_plant  # noqa: E402

OFFSETS = ["planner.offset_x", "planner.offset_y", "planner.offset_z"]


def _box_faces(size, center):
    hx, hy, hz = np.asarray(size) / 2
    c = np.asarray(center)
    v = np.array([[sx * hx, sy * hy, sz * hz] for sx, sy, sz in itertools.product((-1, 1), repeat=3)]) + c
    idx = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
    return [v[list(f)] for f in idx]


def plant_figure(out: Path) -> None:
    """Both plant variants with the zero-offset arm at the pick and drop poses and the planned TCP path."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    fig = plt.figure(figsize=(12, 5.5))
    for k, (variant, offset) in enumerate((("simple", (0, 0, 0)), ("complex", (0, 0, -0.1)))):
        plant = load_plant("", variant)
        ax = fig.add_subplot(1, 2, k + 1, projection="3d")
        for o in plant.obstacles:
            if o.name in ("floor", "fence_back"):
                continue  # they would hide the rest; see the README's table
            color = "tab:red" if "lip" in o.name else "tab:orange" if o.name.startswith("box") else "tab:blue"
            ax.add_collection3d(Poly3DCollection(_box_faces(o.size, o.center), facecolor=color, alpha=0.25, edgecolor="k", lw=0.3))
        base = plant.unity_offset_to_world(offset)
        p = plant.in_base_frame(base)
        cc = CellCollision(p.obstacles)
        path = CartesianPlanner(cc).plan(p.waypoints, p.tcp_rotation)
        tcp = path.tcp + base
        ax.plot(*tcp.T, "g-", lw=2, label=f"planned TCP path (fraction {path.fraction:.2f})")
        ax.scatter(*plant.waypoints.T, c="g", s=15)
        for i in (path.stops[1], path.stops[4]) if path.ok else (len(path.q) - 1,):
            pts = np.array([M.translation for M in cc.placements(path.q[i])[: cc.n_arm]]) + base
            pts = pts[[0, 1, 2, 3, 4, 5, 6, 7, 8]]  # link0..link7 and the hand origins
            ax.plot(*pts.T, "k.-", lw=2)
        ax.scatter(*base, c="k", marker="^", s=60, label="robot base")
        ax.set_xlabel("x_W = z_U (toward box) [m]")
        ax.set_ylabel("y_W = -x_U [m]")
        ax.set_zlabel("z_W = y_U (up) [m]")
        ax.set_xlim(-0.4, 1.0), ax.set_ylim(-0.9, 0.5), ax.set_zlim(-0.8, 0.6)
        ax.set_box_aspect((1.4, 1.4, 1.4))
        ax.view_init(elev=30, azim=40)
        ax.set_title(f"{variant} box, offset (x_U, y_U, z_U) = {offset} m")
        ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def result_figures(table: Path, out: Path) -> None:
    import pandas as pd

    df = pd.read_parquet(table)
    df = df[df["status"] == "ok"]
    for variant in ("simple", "complex"):
        d = df[df["planner.box_variant"] == variant]
        valid = d[d["executed_ok"] == 1.0]
        # fig. 8-8 / 8-9: valid placements in 3-D
        fig = plt.figure(figsize=(6.5, 5.5))
        ax = fig.add_subplot(projection="3d")
        bad = d[d["executed_ok"] != 1.0]
        ax.scatter(bad[OFFSETS[0]], bad[OFFSETS[2]], bad[OFFSETS[1]], c="tab:purple", s=6, alpha=0.25, label="terminated early")
        ax.scatter(valid[OFFSETS[0]], valid[OFFSETS[2]], valid[OFFSETS[1]], c="tab:red", s=22, label="valid")
        ax.set_xlabel("x_pos (toward conveyor) [m]"), ax.set_ylabel("z_pos (toward box) [m]"), ax.set_zlabel("y_pos (up) [m]")
        ax.set_title(f"{variant} box: {len(valid)} of {len(d)} placements valid ({100 * len(valid) / max(len(d), 1):.2f} %)")
        ax.legend(fontsize=8)
        fig.tight_layout(), fig.savefig(out / f"valid_{variant}.png", dpi=110), plt.close(fig)
        if valid.empty:
            continue
        # fig. 8-10: execution time over the valid placements
        fig = plt.figure(figsize=(6.5, 5.5))
        ax = fig.add_subplot(projection="3d")
        sc = ax.scatter(valid[OFFSETS[0]], valid[OFFSETS[2]], valid[OFFSETS[1]], c=valid["duration"], cmap="viridis", s=30)
        fig.colorbar(sc, label="execution time [s]", shrink=0.7, pad=0.12)
        ax.set_xlabel("x_pos [m]"), ax.set_ylabel("z_pos [m]"), ax.set_zlabel("y_pos [m]")
        best = valid.loc[valid["duration"].idxmin()]
        ax.set_title(f"{variant}: t_min = {best['duration']:.2f} s at "
                     f"({best[OFFSETS[0]]:.2f}, {best[OFFSETS[1]]:.2f}, {best[OFFSETS[2]]:.2f})")
        fig.tight_layout(), fig.savefig(out / f"time_{variant}.png", dpi=110), plt.close(fig)
        # fig. 8-11 / 8-12: time against joint distance, colour Cartesian distance
        fig, ax = plt.subplots(figsize=(6.5, 4.5))
        sc = ax.scatter(valid["joint_distance"], valid["duration"], c=valid["cartesian_distance"], cmap="plasma", s=18)
        fig.colorbar(sc, label="Cartesian distance [m]")
        ax.set_xlabel("total joint distance [deg]"), ax.set_ylabel("execution time [s]")
        ax.set_title(f"{variant} box, valid placements")
        ax.grid(alpha=0.3)
        fig.tight_layout(), fig.savefig(out / f"time_vs_distance_{variant}.png", dpi=110), plt.close(fig)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("table", nargs="?", help="the sweep's results.parquet: also draw the result figures")
    parser.add_argument("--out", type=Path, default=OUT, help=f"folder of the figures (default: {OUT})")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    plant_figure(args.out / "plant.png")
    if args.table:
        result_figures(Path(args.table), args.out)
    print(f"figures written to {args.out}")
