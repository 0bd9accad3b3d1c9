"""How many evaluations does `cosim optimize` need on the thesis pick-and-place grid?

The full grid (examples/pick_and_place/results.parquet, 121 x 141 = 17061 designs of q2[2] and q2[4]) gives
the true front of total energy `e_total` against execution time `duration` (both minimised).  Each sampler
optimises the same two parameters (integer degrees, as the grid) with a budget of 5 % of the grid; the
hypervolume of its front after every evaluation is compared with the grid front's.  The grid's front is a
single design, (1, 1), which has both the least energy and the shortest time, so objectives are scaled to
[0, 1] between the best and the worst value of each over the whole grid (reference point 1.1 in each): the
grid front's hypervolume is 1.21, and 99 % of it needs a design within about 1 % of the energy range (1.4 J)
of the least energy at the shortest time.

The simulation is deterministic, so the grid table *is* the objective function: the samplers run through
`orchestrator.optimize.Optimization` exactly as `cosim optimize` does, with an evaluator that looks the design
up in the grid table instead of simulating it (`--real` also runs one sampler through Dask with real
simulations and checks that it proposes and gets exactly the same).  The Latin hypercube of equal budget is the
design space a sweep with `"method": "lhs", "samples": BUDGET` would run, in its order.

    python benchmarks/optimize_pick_and_place.py [--seeds 1 2 3] [--tpe-seeds 1] [--budget 850] [--real]
        [--cache DIR] [--out FILE.md]

``--cache DIR`` keeps each optimisation's results folder as DIR/<sampler>_<seed>_<budget> and reuses it
when it is there, so a long benchmark can be completed in several invocations.

(TPE's asks cost Optuna about 0.25 s of CPU each near the end of an 850-evaluation run, so it gets its own,
usually shorter, list of seeds on a loaded machine.)
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from orchestrator.analysis.pareto import pareto_mask  # noqa: E402
from orchestrator.design import DesignSpace  # noqa: E402
from orchestrator.optimize import Optimization, hypervolume, normalised_losses  # noqa: E402
from orchestrator.spec import load_spec  # noqa: E402

SPEC = ROOT / "examples" / "pick_and_place" / "spec.json"
GRID = ROOT / "examples" / "pick_and_place" / "results.parquet"
Q2, Q4 = "traj.waypoints[9]", "traj.waypoints[11]"
OBJECTIVES = {"e_total": "minimize", "duration": "minimize"}
SAMPLERS = ("tpe", "nsga2", "random", "qmc")


class GridEvaluator:
    """Answers each design from the full-grid table (the values the simulation gives, it being deterministic)."""

    def __init__(self, grid: pd.DataFrame):
        self.lookup = {(int(a), int(b)): (e, d) for a, b, e, d in
                       grid[[Q2, Q4, "e_total", "duration"]].itertuples(index=False)}

    def evaluate(self, points):
        rows = []
        for pid, values in points:
            e, d = self.lookup[(int(values[Q2]), int(values[Q4]))]
            rows.append({"point_id": pid, "status": "ok", "message": "", "run_time": 0.0, "worker": "grid table",
                         "objectives": {"e_total": e, "duration": d}})
        return rows


class Scale:
    """Objectives scaled to [0, 1] over the grid front; hypervolume history of a sequence of evaluations."""

    def __init__(self, grid: pd.DataFrame):
        values = grid[["e_total", "duration"]].to_numpy(float)
        self.front = values[pareto_mask(values)]
        self.ideal, self.nadir = values.min(axis=0), values.max(axis=0)  # the grid front is one design
        self.grid_hv = self.hv(self.front)

    def hv(self, values: np.ndarray) -> float:
        losses = normalised_losses(values, ["min", "min"], self.ideal, self.nadir)
        return hypervolume(losses[pareto_mask(losses)])

    def history(self, values: np.ndarray) -> np.ndarray:
        """Share of the grid front's hypervolume after each evaluation."""
        out, front = np.zeros(len(values)), np.zeros((0, 2))
        for i, v in enumerate(values):
            front = np.vstack([front, v])
            front = front[pareto_mask(front)]
            out[i] = self.hv(front) / self.grid_hv
        return out


def evaluations_to(history: np.ndarray, share: float) -> int | None:
    reached = np.flatnonzero(history >= share)
    return int(reached[0]) + 1 if len(reached) else None


def optimise(sampler: str, seed: int, budget: int, evaluator, folder: Path) -> pd.DataFrame:
    """The results table of one optimisation (reused when ``folder`` already holds a finished one)."""
    if (folder / "results.parquet").exists() and (folder / "metadata.json").exists():
        meta = json.loads((folder / "metadata.json").read_text())
        if meta.get("ended") and meta.get("optimize", {}).get("seed") == seed:
            table = pd.read_parquet(folder / "results.parquet")
            table.attrs["seconds"] = (datetime.fromisoformat(meta["ended"])
                                      - datetime.fromisoformat(meta["started"])).total_seconds()
            return table
    run = Optimization(SPEC, folder, objectives=OBJECTIVES, budget=budget, sampler=sampler, seed=seed, quiet=True)
    started = time.perf_counter()
    run.run(evaluator=evaluator)
    table = run.store.table()
    table.attrs["seconds"] = time.perf_counter() - started
    return table


def latin_hypercube(budget: int, seed: int, grid: GridEvaluator) -> np.ndarray:
    raw = copy.deepcopy(json.loads(SPEC.read_text()))
    raw["design"].update(method="lhs", samples=budget, seed=seed)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "spec.json"
        path.write_text(json.dumps(raw))
        points = list(DesignSpace.from_spec(load_spec(path)))
    return np.array([grid.lookup[(int(p.values[Q2]), int(p.values[Q4]))] for p in points], dtype=float)


def real_run(sampler: str, seed: int, budget: int, scratch: Path, expected: pd.DataFrame) -> dict:
    """`cosim optimize` with real simulations on Dask; checks it matches the grid-table run of the same seed."""
    out = scratch / f"real_{sampler}_{seed}"
    command = [sys.executable, "-m", "orchestrator.cli", "optimize", str(SPEC), "--min", "e_total", "--min",
               "duration", "--budget", str(budget), "--sampler", sampler, "--seed", str(seed), "--out", str(out)]
    started = time.perf_counter()
    done = subprocess.run(command, env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True)
    seconds = time.perf_counter() - started
    if done.returncode != 0:
        raise SystemExit(f"real run failed ({done.returncode}): {done.stderr[-2000:]}")
    table = pd.read_parquet(out / "results.parquet")
    same_designs = table[[Q2, Q4]].reset_index(drop=True).equals(expected[[Q2, Q4]].reset_index(drop=True))
    worst = float(np.max(np.abs(table[["e_total", "duration"]].to_numpy() - expected[["e_total", "duration"]]
                                .to_numpy()))) if same_designs else float("nan")
    return {"command": " ".join(["cosim"] + command[3:]).replace(str(ROOT) + "/", ""), "seconds": seconds,
            "same_designs": same_designs, "max_abs_difference": worst, "rows": len(table),
            "median_run_time": float(table["run_time"].median())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--tpe-seeds", type=int, nargs="+", help="seeds for TPE (default: --seeds)")
    parser.add_argument("--samplers", nargs="+", choices=SAMPLERS, default=list(SAMPLERS))
    parser.add_argument("--budget", type=int, default=850)
    parser.add_argument("--real", action="store_true",
                        help="also run NSGA-II with the first seed with real simulations on Dask")
    parser.add_argument("--cache", type=Path, help="keep and reuse the optimisations' results folders here")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "optimize_pick_and_place.md")
    args = parser.parse_args()
    load_before = os.getloadavg()
    grid_table = pd.read_parquet(GRID)
    grid_table = grid_table[grid_table["status"] == "ok"]
    grid, scale = GridEvaluator(grid_table), Scale(grid_table)
    results = []  # (method, seed, history, seconds)
    tables = {}
    with tempfile.TemporaryDirectory(prefix="cosim_bench_opt_") as scratch:
        for sampler in args.samplers:
            for seed in (args.tpe_seeds or args.seeds) if sampler == "tpe" else args.seeds:
                table = optimise(sampler, seed, args.budget, grid,
                                 (args.cache or Path(scratch)) / f"{sampler}_{seed}_{args.budget}")
                tables[sampler, seed] = table
                history = scale.history(table[["e_total", "duration"]].to_numpy(float))
                results.append((sampler, seed, history, table.attrs["seconds"]))
                print(f"{sampler} seed {seed}: {history[-1]:.4f} of the grid hypervolume after {len(history)}",
                      flush=True)
        for seed in args.seeds:
            history = scale.history(latin_hypercube(args.budget, seed, grid))
            results.append(("lhs (sweep)", seed, history, 0.0))
            print(f"lhs seed {seed}: {history[-1]:.4f} after {len(history)}", flush=True)
        real = real_run("nsga2", args.seeds[0], args.budget, Path(scratch), tables["nsga2", args.seeds[0]]) \
            if args.real else None
    load_after = os.getloadavg()
    write_report(args, results, scale, len(grid_table), real, load_before, load_after)


def write_report(args, results, scale, grid_size, real, load_before, load_after) -> None:
    budget = args.budget
    lines = [
        "# `cosim optimize` on the pick-and-place grid (thesis 7.2.3)",
        "",
        f"Command: `python benchmarks/optimize_pick_and_place.py --seeds {' '.join(map(str, args.seeds))} "
        + (f"--tpe-seeds {' '.join(map(str, args.tpe_seeds))} " if args.tpe_seeds else "")
        + (f"--samplers {' '.join(args.samplers)} " if list(args.samplers) != list(SAMPLERS) else "")
        + f"--budget {budget}{' --real' if args.real else ''}`",
        f"Machine: {platform.machine()}, {os.cpu_count()} cores (a 2-core box shared with other engineers' "
        f"work); load average (1, 5, 15 min) before {tuple(round(x, 1) for x in load_before)}, after "
        f"{tuple(round(x, 1) for x in load_after)}; "
        f"{datetime.now(timezone.utc).isoformat(timespec='minutes')}; Optuna {_version('optuna')}.",
        "",
        f"The grid: {grid_size} designs (every one ok); its front of `e_total` and `duration` is "
        f"{len(scale.front)} design: (q2[2], q2[4]) = (1, 1), best in both. Budget: {budget} evaluations = "
        f"{100 * budget / grid_size:.1f} % of the grid. Hypervolume: objectives scaled to [0, 1] between the best "
        "and worst value of each over the grid, reference point 1.1; shares are of the grid front's hypervolume "
        "(1.21): 99 % needs a design within about 1 % of the energy range of the least energy at the shortest "
        "time. Samplers run through "
        "`orchestrator.optimize.Optimization` (batches of 8; NSGA-II 20 = its population) with each design "
        "answered from the grid table; a design proposed twice costs one evaluation.",
        "",
        "| method | seed | evaluations to 95 % | evaluations to 99 % | share after the budget | optimiser time (s) |",
        "|---|---|---|---|---|---|",
    ]
    for method, seed, history, seconds in results:
        lines.append(f"| {method} | {seed} | {_n(evaluations_to(history, 0.95))} | "
                     f"{_n(evaluations_to(history, 0.99))} | {100 * history[-1]:.2f} % | "
                     f"{seconds:.1f} |" if seconds else
                     f"| {method} | {seed} | {_n(evaluations_to(history, 0.95))} | "
                     f"{_n(evaluations_to(history, 0.99))} | {100 * history[-1]:.2f} % | — |")
    lines += ["", "Median over the seeds:", "", "| method | to 95 % | to 99 % | share after the budget |",
              "|---|---|---|---|"]
    for method in dict.fromkeys(r[0] for r in results):
        rows = [r for r in results if r[0] == method]
        lines.append(f"| {method} | {_median([evaluations_to(r[2], 0.95) for r in rows])} | "
                     f"{_median([evaluations_to(r[2], 0.99) for r in rows])} | "
                     f"{100 * float(np.median([r[2][-1] for r in rows])):.2f} % |")
    lines += ["", "('—': not reached within the budget.)"]
    if real:
        lines += ["", "## The same with real simulations", "",
                  f"`{real['command']}` (Dask, 2 worker processes, inverse-dynamics level): {real['rows']} "
                  f"evaluations in {real['seconds']:.0f} s wall time (including the cluster start; median "
                  f"{1000 * real['median_run_time']:.1f} ms per simulation in the workers). Same designs in the same "
                  f"order as the grid-table run of that seed: {real['same_designs']}; largest difference of an "
                  f"objective from the grid table: {real['max_abs_difference']:.3g}."]
    args.out.write_text("\n".join(lines) + "\n")
    print(f"written: {args.out}")


def _n(value) -> str:
    return "—" if value is None else str(value)


def _median(values) -> str:
    if any(v is None for v in values):
        reached = [v for v in values if v is not None]
        return f"{int(np.median(reached))} ({len(reached)} of {len(values)} seeds reached it)" if reached else "—"
    return str(int(np.median(values)))


def _version(name: str) -> str:
    from importlib import metadata

    return metadata.version(name)


if __name__ == "__main__":
    main()
