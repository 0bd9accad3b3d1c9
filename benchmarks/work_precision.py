"""Work against precision: fixed communication steps and the adaptive algorithm on a stiffly coupled system.

Two ``linear_ode`` FMUs (FMI 2.0, built from ``src/cosim/fmus/linear_ode``) coupled both ways:

    slow:  x1' = -x1 + x2            (a = -1,   b = 1,  u = x2)
    fast:  x2' = -100 x2 + 50 x1     (a = -100, b = 50, u = x1)

eigenvalues -0.4975 and -100.5 (a stiffness ratio of 200), from x1 = 1, x2 = 20 over 10 s: the fast unit
relaxes within a few hundredths of a second, then both decay slowly.  Each FMU integrates exactly for its
held input, so every error is the coupling's.  The error of a run is the largest deviation of x1 or x2 from
the exact solution (the matrix exponential) over its recorded communication points.

Runs, all in this one process, one after another:

- fixed steps, Gauss-Seidel, N = 100 .. 51200 steps;
- ``adaptive`` with step doubling (the FMUs save and restore their states), rtol = 1e-1 .. 1e-5;
- ``adaptive`` with ``restore: never`` (the signal-change estimate, only adapting), the same tolerances;
- for every adaptive run with step doubling, a fixed-step run with 5x as many steps as the adaptive run's
  base steps (every step of Gauss-Seidel it took: the full step and the two half steps of each try,
  rejected tries included): the claim is that its error is still larger.

Prints the tables (Markdown) and writes ``benchmarks/work_precision.png`` (error against steps and against
CPU time).  Usage: python benchmarks/work_precision.py [--png PATH]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from cosim.execution.point import run_point
from cosim.fmus.build import ensure_built
from cosim.spec.loader import spec_from_dict
from cosim.system.builder import build_system

A1, B1, A2, B2 = -1.0, 1.0, -100.0, 50.0
X0 = np.array([1.0, 20.0])
A = np.array([[A1, B1], [B2, A2]])
STOP = 10.0
FIXED = [100 * 2 ** i for i in range(10)]  # 100 .. 51200 steps
TOLERANCES = [1e-1, 1e-2, 1e-3, 1e-4, 1e-5]
HERE = Path(__file__).resolve().parent


def exact(t: np.ndarray) -> np.ndarray:
    """The states at times ``t``: expm(A t) X0 through A's eigenvectors."""
    values, vectors = np.linalg.eig(A)
    weights = np.linalg.solve(vectors, X0)
    return np.real(np.exp(np.outer(t, values)) * weights @ vectors.T)


def system_for(experiment: dict):
    fmu = str(ensure_built("linear_ode", 2))
    spec = {"units": {"slow": {"fmu": fmu, "parameters": {"a": A1, "b": B1, "x0": X0[0]}},
                      "fast": {"fmu": fmu, "parameters": {"a": A2, "b": B2, "x0": X0[1]}}},
            "connections": [{"from": "fast.y", "to": "slow.u"}, {"from": "slow.y", "to": "fast.u"}],
            "experiment": {"stop": STOP, **experiment}, "record": ["slow.y", "fast.y"]}
    return build_system(spec_from_dict(spec, HERE / "work_precision_spec.json"))


def measure(experiment: dict) -> dict:
    """One run: its error, accepted steps, base steps (doStep calls per unit) and CPU seconds."""
    system = system_for(experiment)
    started = time.process_time()
    result = run_point(system, record=True)
    cpu = time.process_time() - started
    assert result.ok, result.message
    t = result.traces["time"].to_numpy()
    error = float(np.abs(result.traces[["slow.y", "fast.y"]].to_numpy() - exact(t)).max())
    stats = result.step_stats or {}
    return {"error": error, "steps": result.steps, "base_steps": stats.get("base_steps", result.steps),
            "rejected": stats.get("rejected", 0), "exceeded": stats.get("exceeded", 0),
            "smallest": stats.get("smallest", STOP / max(result.steps, 1)),
            "largest": stats.get("largest", STOP / max(result.steps, 1)), "cpu": cpu}


def adaptive(rtol: float, restore: str) -> dict:
    return measure({"step": 1e-3, "algorithm": "adaptive",
                    "adaptive": {"rtol": rtol, "atol": 1e-9, "restore": restore}})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--png", default=str(HERE / "work_precision.png"))
    args = parser.parse_args()
    started = datetime.now(timezone.utc)
    load = os.getloadavg()
    measure({"step": STOP / 100})  # once unmeasured: the FMU is extracted and its library loaded
    fixed = {n: measure({"step": STOP / n}) for n in FIXED}
    doubling = {r: adaptive(r, "auto") for r in TOLERANCES}
    adapting = {r: adaptive(r, "never") for r in TOLERANCES}
    checks = {r: measure({"step": STOP / (5 * doubling[r]["base_steps"])}) for r in TOLERANCES}
    load_after = os.getloadavg()

    print(f"{started:%Y-%m-%d %H:%M} UTC, {platform.machine()} with {os.cpu_count()} cores, Python "
          f"{platform.python_version()}, load average {load[0]:.2f} before, {load_after[0]:.2f} after\n")
    print("Fixed steps (Gauss-Seidel):\n")
    print("| steps | step (s) | max error | CPU (s) |\n|---|---|---|---|")
    for n, m in fixed.items():
        print(f"| {n} | {STOP / n:.3g} | {m['error']:.3g} | {m['cpu']:.3f} |")
    for title, runs in (("Adaptive, step doubling (FMU states saved and restored)", doubling),
                        ("Adaptive, restore: never (signal-change estimate, only adapting)", adapting)):
        print(f"\n{title}:\n")
        print("| rtol | accepted steps | base steps | rejected | over tolerance | step (s) | max error | CPU (s) |")
        print("|---|---|---|---|---|---|---|---|")
        for r, m in runs.items():
            print(f"| {r:g} | {m['steps']} | {m['base_steps']} | {m['rejected']} | {m['exceeded']} | "
                  f"{m['smallest']:.2g} .. {m['largest']:.2g} | {m['error']:.3g} | {m['cpu']:.3f} |")
    print("\nThe claim: a fixed step with 5x the adaptive run's base steps is still less accurate:\n")
    print("| rtol | adaptive: base steps, error | fixed: steps, error | fixed error / adaptive error | holds |")
    print("|---|---|---|---|---|")
    held = True
    for r in TOLERANCES:
        a, f = doubling[r], checks[r]
        ok = f["error"] > a["error"]
        held &= ok
        print(f"| {r:g} | {a['base_steps']}, {a['error']:.3g} | {f['steps']}, {f['error']:.3g} | "
              f"{f['error'] / a['error']:.3g} | {'yes' if ok else 'NO'} |")
    print(f"\nclaim holds for every tolerance: {held}")
    plot(fixed, doubling, adapting, Path(args.png), f"{started:%Y-%m-%d %H:%M} UTC, load {load[0]:.1f}")
    print(f"figure: {args.png}")


def plot(fixed: dict, doubling: dict, adapting: dict, path: Path, when: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (by_steps, by_cpu) = plt.subplots(1, 2, figsize=(10, 4.2))
    curves = [("fixed step", fixed, "o-", "C0", "steps"),
              ("adaptive, step doubling: accepted steps", doubling, "s-", "C1", "steps"),
              ("adaptive, step doubling: base steps", doubling, "s--", "C1", "base_steps"),
              ("adaptive, only adapting (restore: never)", adapting, "^-", "C3", "steps")]
    for label, runs, style, color, key in curves:
        runs = list(runs.values())
        by_steps.loglog([m[key] for m in runs], [m["error"] for m in runs], style, color=color, label=label)
        if key != "base_steps":
            by_cpu.loglog([m["cpu"] for m in runs], [m["error"] for m in runs], style, color=color, label=label)
    by_steps.set_xlabel("communication steps")
    by_cpu.set_xlabel("CPU time of the run (s)")
    for axes in (by_steps, by_cpu):
        axes.set_ylabel("max |error| of x1, x2")
        axes.grid(True, which="both", alpha=0.3)
    by_steps.legend(fontsize=7)
    figure.suptitle(f"Work-precision, two linear_ode FMUs stiffly coupled (eigenvalues -0.5, -100.5); {when}",
                    fontsize=9)
    figure.tight_layout()
    figure.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
