"""Do the two robot fidelity levels rank the designs alike?  (coarse grid, 273 points)

Reads ``results_coarse.parquet`` (inverse dynamics) and ``results_coarse_exudyn.parquet``
(Exudyn with the joint servo), both written by run_study.py (the committed ones beside this file, or those in
``--tables DIR``), and prints

- the Spearman rank correlation of total energy, and whether argmin and argmax match;
- the energy the servo adds (Exudyn - inverse dynamics), total and per joint, and where it is largest;
- the same without the points where joint 2 stands still under load (q2[2] = 0), see the README.

    python examples/pick_and_place/compare_fidelity.py
    python examples/pick_and_place/compare_fidelity.py --tables results/pick_and_place
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import spearmanr

HERE = Path(__file__).resolve().parent
Q22, Q24 = "traj.waypoints[9]", "traj.waypoints[11]"


def load(folder: Path) -> pd.DataFrame:
    """Both tables of ``folder`` joined on the design point; columns suffixed _id and _ex."""
    fast = pd.read_parquet(folder / "results_coarse.parquet")
    servo = pd.read_parquet(folder / "results_coarse_exudyn.parquet")
    assert (fast["status"] == "ok").all() and (servo["status"] == "ok").all()
    return fast.merge(servo, on=[Q22, Q24], suffixes=("_id", "_ex"))


def report(df: pd.DataFrame, label: str) -> str:
    rho = spearmanr(df["e_total_id"], df["e_total_ex"]).statistic
    arg = lambda col, fn: tuple(int(v) for v in df.loc[getattr(df[col], fn)(), [Q22, Q24]])  # noqa: E731
    diff = df["e_total_ex"] - df["e_total_id"]
    rel = diff / df["e_total_id"]
    lines = [f"{label}: {len(df)} points",
             f"  Spearman rank correlation of e_total: {rho:.5f}",
             f"  argmin: inverse dynamics {arg('e_total_id', 'idxmin')}, Exudyn {arg('e_total_ex', 'idxmin')}",
             f"  argmax: inverse dynamics {arg('e_total_id', 'idxmax')}, Exudyn {arg('e_total_ex', 'idxmax')}",
             f"  servo adds (Exudyn - ID): median {diff.median():+.3f} J ({rel.median() * 100:+.2f} %), "
             f"range {diff.min():+.3f} .. {diff.max():+.3f} J ({rel.min() * 100:+.2f} .. {rel.max() * 100:+.2f} %)"]
    for j in (1, 2, 4):
        d = df[f"e_el[{j}]_ex"] - df[f"e_el[{j}]_id"]
        lines.append(f"  joint {j}: median {d.median():+.3f} J, range {d.min():+.3f} .. {d.max():+.3f} J")
    worst = df.loc[rel.abs().idxmax()]
    lines.append(f"  largest relative difference at ({int(worst[Q22])}, {int(worst[Q24])}): "
                 f"ID {worst['e_total_id']:.2f} J, Exudyn {worst['e_total_ex']:.2f} J")
    lines.append(f"  max tracking error (Exudyn): {np.rad2deg(df['tracking_error_ex'].max()):.3f} deg")
    return "\n".join(lines)


def main() -> None:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tables", type=Path, default=HERE, help=f"folder of both tables (default: {HERE})")
    df = load(parser.parse_args().tables)
    print(report(df, "all coarse points"))
    print(report(df[df[Q22] != 0], "without q2[2] = 0 (joint 2 at standstill under load)"))


if __name__ == "__main__":
    main()
