"""How many evaluations does `cosim optimize` need on the thesis pick-and-place grid?

The full grid (examples/pick_and_place/study/results.parquet, 121 x 141 = 17061 designs of q2[2] and q2[4]) gives
the true front of total energy `e_total` against execution time `duration` (both minimised).  Each sampler
optimises the same two parameters (integer degrees, as the grid) with a budget of 5 % of the grid; the
hypervolume of its front after every evaluation is compared with the grid front's.  The grid's front is a
single design, (1, 1), which has both the least energy and the shortest time, so objectives are scaled to
[0, 1] between the best and the worst value of each over the whole grid (reference point 1.1 in each): the
grid front's hypervolume is 1.21, and 99 % of it needs a design within about 1 % of the energy range (1.4 J)
of the least energy at the shortest time.

The simulation is deterministic, so the grid table *is* the objective function: the samplers run through
`cosim.studies.optimize.Optimization` exactly as `cosim optimize` does, with an evaluator that looks the design
up in the grid table instead of simulating it (`--real` also runs one sampler through Dask with real
simulations and checks that it proposes and gets exactly the same).  The Latin hypercube of equal budget is the
design space a sweep with `"method": "lhs", "samples": BUDGET` would run, in its order.

    python benchmarks/optimize_pick_and_place.py [--seeds 1 2 3 4 5] [--samplers ...] [--budget 850]
        [--gp-budget 850] [--real] [--cache DIR] [--out FILE.md]

``--cache DIR`` keeps each finished optimisation's results folder as DIR/<sampler>_<seed>_<budget> (with its
CPU and wall time in DIR/<sampler>_<seed>_<budget>.json) and reuses it when it is there, so a long benchmark
can be completed in several invocations; the report lists every sampler asked for.

Every optimisation runs in this process with a dictionary look-up as the objective, so the CPU time of the
process during a run is the optimiser's own cost (the sampler's asks and tells, cosim's bookkeeping and the
parquet part files); wall time is that plus waiting for a core on a shared machine.  The Gaussian-process
sampler's asks grow costly with the number of trials (a GP fit and an acquisition optimisation per ask), so
``--gp-budget`` may give it a smaller budget; evaluations to 95/99 % are exact whenever reached within it.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import platform
import shutil
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

from cosim.analysis.hypervolume import hypervolume, normalised_losses  # noqa: E402
from cosim.analysis.pareto import pareto_mask  # noqa: E402
from cosim.execution.point_row import PointRow  # noqa: E402
from cosim.spec.design import DesignSpace  # noqa: E402
from cosim.spec.loader import load_spec  # noqa: E402
from cosim.studies.optimize import Optimization  # noqa: E402

SPEC = ROOT / "examples" / "pick_and_place" / "spec.json"
GRID = ROOT / "examples" / "pick_and_place" / "study" / "results.parquet"
Q2, Q4 = "traj.waypoints[9]", "traj.waypoints[11]"
OBJECTIVES = {"e_total": "minimize", "duration": "minimize"}
SAMPLERS = ("nsga2", "tpe", "gp", "random", "qmc")


class GridEvaluator:
    """Answers each design from the full-grid table (the values the simulation gives, it being deterministic)."""

    def __init__(self, grid: pd.DataFrame):
        self.lookup = {(int(a), int(b)): (e, d) for a, b, e, d in
                       grid[[Q2, Q4, "e_total", "duration"]].itertuples(index=False)}

    def evaluate(self, points):
        rows = []
        for pid, values in points:
            e, d = self.lookup[(int(values[Q2]), int(values[Q4]))]
            rows.append(PointRow(pid, "ok", "", 0.0, {"e_total": e, "duration": d}, "grid table"))
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
    """The results table of one optimisation, with ``attrs`` cpu_seconds and wall_seconds (reused when
    ``folder`` already holds a finished one and its timing file; an unfinished one is started afresh)."""
    timing = folder.with_suffix(".json")
    if (folder / "results.parquet").exists() and timing.exists():
        times = json.loads(timing.read_text())
        if times.get("seed") == seed and times.get("budget") == budget:
            table = pd.read_parquet(folder / "results.parquet")
            table.attrs.update(times)
            return table
    if folder.exists():
        shutil.rmtree(folder)
    run = Optimization(SPEC, folder, objectives=OBJECTIVES, budget=budget, sampler=sampler, seed=seed, quiet=True)
    cpu, wall = time.process_time(), time.perf_counter()
    run.run(evaluator=evaluator)
    times = {"seed": seed, "budget": budget, "cpu_seconds": time.process_time() - cpu,
             "wall_seconds": time.perf_counter() - wall, "ended": datetime.now(timezone.utc).isoformat()}
    timing.write_text(json.dumps(times))
    table = run.store.table()
    table.attrs.update(times)
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
    command = [sys.executable, "-m", "cosim.cli.main", "optimize", str(SPEC), "--min", "e_total", "--min",
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


def planned_runs(args) -> list[tuple[str, int, int]]:
    """(sampler, seed, budget) of every optimisation asked for on the command line."""
    return [(sampler, seed, args.gp_budget if sampler == "gp" and args.gp_budget else args.budget)
            for sampler in args.samplers for seed in args.seeds]


def cached_runs(cache: Path) -> list[tuple[str, int, int]]:
    """(sampler, seed, budget) of every finished optimisation in ``cache``, samplers in SAMPLERS' order."""
    runs = []
    for timing in cache.glob("*_*_*.json"):
        sampler, seed, budget = timing.stem.rsplit("_", 2)
        if sampler in SAMPLERS and (cache / timing.stem / "results.parquet").exists():
            runs.append((sampler, int(seed), int(budget)))
    return sorted(runs, key=lambda r: (SAMPLERS.index(r[0]), r[2], r[1]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    parser.add_argument("--samplers", nargs="+", choices=SAMPLERS, default=list(SAMPLERS))
    parser.add_argument("--budget", type=int, default=850)
    parser.add_argument("--gp-budget", type=int, help="budget of the gp sampler (default: --budget)")
    parser.add_argument("--real", action="store_true",
                        help="also run NSGA-II with the first seed with real simulations on Dask")
    parser.add_argument("--cache", type=Path, help="keep and reuse the optimisations' results folders here")
    parser.add_argument("--from-cache", action="store_true",
                        help="run nothing: report every finished run in --cache (and the Latin hypercube of "
                             "--budget for each seed among them)")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "optimize_pick_and_place.md")
    args = parser.parse_args()
    if args.from_cache and not args.cache:
        parser.error("--from-cache needs --cache DIR")
    uptime_before = _uptime()
    grid_table = pd.read_parquet(GRID)
    grid_table = grid_table[grid_table["status"] == "ok"]
    grid, scale = GridEvaluator(grid_table), Scale(grid_table)
    results = []  # (method, seed, budget, history, cpu seconds, wall seconds)
    tables = {}
    with tempfile.TemporaryDirectory(prefix="cosim_bench_opt_") as scratch:
        for sampler, seed, budget in cached_runs(args.cache) if args.from_cache else planned_runs(args):
            table = optimise(sampler, seed, budget, grid,
                             (args.cache or Path(scratch)) / f"{sampler}_{seed}_{budget}")
            tables[sampler, seed] = table
            history = scale.history(table[["e_total", "duration"]].to_numpy(float))
            results.append((sampler, seed, budget, history, table.attrs["cpu_seconds"],
                            table.attrs["wall_seconds"]))
            print(f"{sampler} seed {seed}: {history[-1]:.4f} of the grid hypervolume after {len(history)}; "
                  f"{table.attrs['cpu_seconds']:.0f} s CPU, {table.attrs['wall_seconds']:.0f} s wall", flush=True)
        for seed in sorted({seed for _, seed, _ in cached_runs(args.cache)}) if args.from_cache else args.seeds:
            history = scale.history(latin_hypercube(args.budget, seed, grid))
            results.append(("lhs (sweep)", seed, len(history), history, None, None))
            print(f"lhs seed {seed}: {history[-1]:.4f} after {len(history)}", flush=True)
        real = real_run("nsga2", args.seeds[0], args.budget, Path(scratch), tables["nsga2", args.seeds[0]]) \
            if args.real else None
    write_report(args, results, scale, len(grid_table), real, uptime_before, _uptime())


KEPT = "<!-- Below this line: written by hand, kept when the script rewrites the file. -->"


def write_report(args, results, scale, grid_size, real, uptime_before, uptime_after) -> None:
    budget = args.budget
    command = (f"nice -n {os.nice(0)} python benchmarks/optimize_pick_and_place.py --seeds "
               f"{' '.join(map(str, args.seeds))} "
               + (f"--samplers {' '.join(args.samplers)} " if list(args.samplers) != list(SAMPLERS) else "")
               + f"--budget {budget}" + (f" --gp-budget {args.gp_budget}" if args.gp_budget else "")
               + (" --real" if args.real else "") + (" --cache DIR" if args.cache else ""))
    if args.from_cache:
        command = f"python benchmarks/optimize_pick_and_place.py --budget {budget} --cache DIR --from-cache"
    lines = [
        "# `cosim optimize` on the pick-and-place grid (thesis 7.2.3)",
        "",
        f"Command: `{command}` (the runs of a sampler and seed already in DIR were reused: their CPU and wall "
        "times are those measured when they ran).",
        "",
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, shared with about six other engineers' work "
        "(tests, builds, benchmarks) the whole time; this script ran at lower priority (nice). "
        f"Date and `uptime` when this invocation started: `{uptime_before}`; when it ended: `{uptime_after}`. "
        f"Optuna {_version('optuna')}" + (f", PyTorch {_version('torch')}" if "gp" in args.samplers else "") + ".",
        "",
        f"The grid: {grid_size} designs (every one ok); its front of `e_total` and `duration` is "
        f"{len(scale.front)} design: (q2[2], q2[4]) = (1, 1), best in both. Budget: {budget} evaluations = "
        f"{100 * budget / grid_size:.1f} % of the grid"
        + (f" ({args.gp_budget} = {100 * args.gp_budget / grid_size:.1f} % for gp)" if args.gp_budget else "")
        + ". Hypervolume: objectives scaled to [0, 1] between the best "
        "and worst value of each over the grid, reference point 1.1; shares are of the grid front's hypervolume "
        "(1.21): 99 % needs a design within about 1 % of the energy range of the least energy at the shortest "
        "time. Samplers run through "
        "`cosim.studies.optimize.Optimization` (batches of 8; NSGA-II 20 = its population) with each design "
        "answered from the grid table; a design proposed twice costs one evaluation. The Latin hypercube is "
        "the design a sweep with `\"method\": \"lhs\", \"samples\": " + str(budget) + "` runs, in its order.",
        "",
        "CPU time is the benchmark process's CPU time during the run (the optimiser's own cost: the objective "
        "is a table look-up); wall time includes waiting for a core on the loaded machine. Neither includes "
        "simulations (see the real run below for those).",
        "",
        "| method | seed | budget | evaluations to 95 % | evaluations to 99 % | share after the budget "
        "| CPU time (s) | wall time (s) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for method, seed, run_budget, history, cpu, wall in results:
        lines.append(f"| {method} | {seed} | {run_budget} | {_n(evaluations_to(history, 0.95))} | "
                     f"{_n(evaluations_to(history, 0.99))} | {100 * history[-1]:.2f} % | "
                     f"{_seconds(cpu)} | {_seconds(wall)} |")
    first = min(r[2] for r in results)  # every run's share at the smallest budget: an equal-budget comparison
    lines += ["", "Over the seeds (median of the seeds that reached the share; the count says how many did):", "",
              "| method | runs | evaluations to 95 % | evaluations to 99 % | 99 % within 5 % of the grid "
              f"({int(0.05 * grid_size)} evaluations) | median share after {first} evaluations "
              "| median share after the budget | median CPU time per run (s) |",
              "|---|---|---|---|---|---|---|---|"]
    for method, budget_of in dict.fromkeys((r[0], r[2] if r[4] is not None else None) for r in results):
        rows = [r for r in results if r[0] == method and (r[4] is None or r[2] == budget_of)]
        within = sum(1 for r in rows if (evaluations_to(r[3], 0.99) or grid_size) <= 0.05 * grid_size)
        cpu = [r[4] for r in rows if r[4] is not None]
        label = method if budget_of is None else f"{method} (budget {budget_of})"
        lines.append(f"| {label} | {len(rows)} | {_median([evaluations_to(r[3], 0.95) for r in rows])} | "
                     f"{_median([evaluations_to(r[3], 0.99) for r in rows])} | {within} of {len(rows)} | "
                     f"{100 * float(np.median([r[3][first - 1] for r in rows])):.2f} % | "
                     f"{100 * float(np.median([r[3][-1] for r in rows])):.2f} % | "
                     f"{_seconds(float(np.median(cpu)) if cpu else None)} |")
    lines += ["", "('—': not reached within the budget.)"]
    if real:
        lines += ["", "## The same with real simulations", "",
                  f"`{real['command']}` (Dask, 2 worker processes, inverse-dynamics level): {real['rows']} "
                  f"evaluations in {real['seconds']:.0f} s wall time (including the cluster start; median "
                  f"{1000 * real['median_run_time']:.1f} ms per simulation in the workers). Same designs in the same "
                  f"order as the grid-table run of that seed: {real['same_designs']}; largest difference of an "
                  f"objective from the grid table: {real['max_abs_difference']:.3g}."]
    kept = ""
    if args.out.exists() and KEPT in args.out.read_text():
        kept = args.out.read_text().split(KEPT, 1)[1]
    args.out.write_text("\n".join(lines) + "\n\n" + KEPT + (kept or "\n"))
    print(f"written: {args.out}")


def _uptime() -> str:
    """The date (UTC) and what `uptime` prints (its load averages over 1, 5 and 15 minutes)."""
    uptime = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    return f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC; {uptime}"


def _seconds(value) -> str:
    return "—" if value is None else f"{value:.1f}"


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
