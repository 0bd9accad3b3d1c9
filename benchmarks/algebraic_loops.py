"""What solving an algebraic loop costs per communication point, and zero-delay feed-through under Jacobi.

Systems of `algebraic` FMUs (FMI 2.0, built from src/cosim/fmus/algebraic) driven by a `linear_ode` FMU
(w = e^-t, 0.1 e^-t for the nonlinear loop, into the loop's `w` input), run by an Execution without recording, Gauss-Seidel:

- chain:      driver -> ux.w, ux.y -> uy.u (no loop: the baseline);
- linear:     the chain and uy.y -> ux.u, x = 2 + y/2 + w, y = -1 + 3x (Newton; fixed-point diverges here);
- nonlinear:  the chain and uy.y -> ux.u, x = cos(y) + w, y = x^3;

and the sensor -> controller -> limiter chain of tests/master/test_algebraic_loops.py under jacobi and jacobi-delayed.
Prints CPU microseconds per communication point (best of the rounds), the loop's evaluations of G per point
(each: set the tearing variable, run the loop's links, read) and the largest residual of the loop's equations
seen at any communication point.  Usage: python benchmarks/algebraic_loops.py [--steps N] [--repeat R]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from cosim import Execution, build_system, load_spec
from cosim.master import loops

TESTS = Path(__file__).resolve().parent.parent / "tests" / "helpers"


def loop_spec(kind: str, steps: int, h: float) -> dict:
    fmu = "builtin:algebraic_fmi2"
    ux, uy = {"c0": 2.0, "c1": 0.5}, {"c0": -1.0, "c1": 3.0}
    if kind == "nonlinear":
        ux, uy = {"c1": 0.0, "a": 1.0}, {"c1": 0.0, "c3": 1.0}
    connections = [{"from": "driver.y", "to": "ux.w"}, {"from": "ux.y", "to": "uy.u"}]
    if kind != "chain":
        connections.append({"from": "uy.y", "to": "ux.u"})
    # w = 0.1 e^-t keeps the nonlinear loop on one branch (with w = e^-t its root folds away near t = 0.17 and
    # the run fails, naming the loop: Newton follows the branch it starts on)
    driver = {"a": -1.0, "b": 0.0, "x0": 0.1 if kind == "nonlinear" else 1.0}
    return {"units": {"driver": {"fmu": "builtin:linear_ode_fmi2", "parameters": driver},
                      "ux": {"fmu": fmu, "parameters": ux}, "uy": {"fmu": fmu, "parameters": uy}},
            "connections": connections,
            "experiment": {"stop": steps * h, "step": h},
            "objectives": {"x": {"signal": "ux.y", "reduce": "final"}}}


def feedthrough_chain(algorithm: str, steps: int, h: float) -> dict:
    return {
        "units": {
            "plant": {"fmu": "builtin:linear_ode_fmi2", "parameters": {"a": -0.5, "b": 2.0, "x0": 1.0}},
            "sensor": {"fmu": "builtin:algebraic_fmi2", "parameters": {"c0": 0.1, "c1": 2.0}},
            "controller": {"fmu": "builtin:algebraic_fmi2", "parameters": {"c0": 1.0, "c1": -3.0}},
            "limiter": {"python": f"{TESTS / 'units_for_tests.py'}:Saturation"},
        },
        "connections": [{"from": "plant.y", "to": "sensor.u"}, {"from": "sensor.y", "to": "controller.u"},
                        {"from": "controller.y", "to": "limiter.u"}, {"from": "limiter.y", "to": "plant.u"}],
        "experiment": {"stop": steps * h, "step": h, "algorithm": algorithm},
        "objectives": {"x": {"signal": "plant.y", "reduce": "final"}},
    }


class Counting:
    """Counts LoopSolver evaluations and keeps the largest residual |G(x) - x| at the x each solve accepted (the
    solver's last evaluation)."""

    def __init__(self):
        self.evaluations = 0
        self.worst = 0.0
        self.last = np.zeros(1)
        self._evaluate, self._solve = loops.LoopSolver._evaluate, loops.LoopSolver.solve
        counter = self

        def evaluate(solver, x):
            counter.evaluations += 1
            g = counter._evaluate(solver, x)
            counter.last = g - x
            return g

        def solve(solver, t):
            counter._solve(solver, t)
            counter.worst = max(counter.worst, float(np.max(np.abs(counter.last))))

        loops.LoopSolver._evaluate, loops.LoopSolver.solve = evaluate, solve

    def restore(self):
        loops.LoopSolver._evaluate, loops.LoopSolver.solve = self._evaluate, self._solve


def measure(spec: dict, steps: int, repeat: int, count: bool) -> tuple[float, float, float]:
    """(best CPU us per communication point, G evaluations per point, worst loop residual)."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "spec.json"
        path.write_text(json.dumps(spec))
        system = build_system(load_spec(path))
        best = float("inf")
        for _ in range(repeat):
            started = time.process_time()
            result = Execution(system).run()
            best = min(best, time.process_time() - started)
            assert result.ok and result.steps == steps, result.message
        if not count:
            return best / steps * 1e6, 0.0, 0.0
        counter = Counting()
        try:
            assert Execution(system).run().ok
        finally:
            counter.restore()
        return best / steps * 1e6, counter.evaluations / (steps + 1), counter.worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=5000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    h = 1e-3
    load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"# algebraic loops: {args.steps} communication points, best CPU time of {args.repeat} runs; "
          f"{platform.machine()}, {os.cpu_count()} cores, load {load}, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    print(f" {'system':38s} {'us/point':>9s} {'G evals/point':>14s} {'worst residual':>15s}")
    for kind in ("chain", "linear", "nonlinear"):
        us, evaluations, worst = measure(loop_spec(kind, args.steps, h), args.steps, args.repeat, kind != "chain")
        label = {"chain": "chain, no loop (baseline)", "linear": "linear loop (Newton)",
                 "nonlinear": "nonlinear: x = cos(y) + w, y = x^3"}[kind]
        print(f" {label:38s} {us:9.1f} {evaluations:14.2f} {worst:15.1e}" if kind != "chain"
              else f" {label:38s} {us:9.1f} {'-':>14s} {'-':>15s}")
    for algorithm in ("jacobi-delayed", "jacobi", "gauss-seidel"):
        us, _, _ = measure(feedthrough_chain(algorithm, args.steps, h), args.steps, args.repeat, False)
        print(f" {'sensor-controller-limiter, ' + algorithm:38s} {us:9.1f} {'-':>14s} {'-':>15s}")


if __name__ == "__main__":
    main()
