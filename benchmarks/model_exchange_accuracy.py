"""Accuracy of Model Exchange integration: the internal step cap, and connected ME units integrated together.

    python benchmarks/model_exchange_accuracy.py [--part cap|coupled|all] [--repeat 3]

``cap`` (issue 25, item 10): y' = -y, y(0) = 1 (``linear_ode`` as Model Exchange, FMI 2.0) at tolerance 1e-4 to
t = 2, for several communication steps, with CVode's internal step capped at the communication step (the
default) and uncapped (``max_step`` 1e9): the largest error at the communication points against e^-t.

``coupled`` (issue 26, item 2): the two-mass oscillator of tests/master/test_coupled_model_exchange.py split into two
``mass_spring`` Model Exchange FMUs (FMI 2.0, tolerance 1e-8), 1 s, at several communication steps, integrated
together (the default) and one by one (``"coupled_model_exchange": false``): the largest position error against
the matrix exponential relative to the largest displacement, and the wall and CPU time of the run (median of
``--repeat``).

Prints Markdown tables for benchmarks/model_exchange.md.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.linalg import expm

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from cosim import Execution, build_system, load_spec  # noqa: E402
from cosim.fmus.build import ensure_built  # noqa: E402
from cosim.units.fmu.description import FmuUnitType  # noqa: E402
from cosim.units.fmu.model_exchange import SolverSettings  # noqa: E402


def dahlquist_error(h: float, max_step: float | None, tolerance: float = 1e-4, stop: float = 2.0) -> float:
    """Largest |y - e^-t| at the communication points of one run."""
    unit = FmuUnitType(ensure_built("linear_ode", 2), interface="model-exchange",
                       solver_settings=SolverSettings(tolerance, max_step)).instantiate("dahlquist")
    try:
        unit.setup(0.0, stop)
        unit.set_values({"a": -1.0, "b": 0.0, "x0": 1.0})
        unit.enter_initialization()
        unit.exit_initialization()
        error = 0.0
        for k in range(round(stop / h)):
            unit.do_step(k * h, h)
            error = max(error, abs(unit.get_values(["y"])["y"] - math.exp(-(k + 1) * h)))
    finally:
        unit.terminate()
    return error


def cap_table() -> str:
    rows = ["| communication step | capped at the step (default) | uncapped (`max_step` 1e9) |", "|---|---|---|"]
    for h in (0.2, 0.1, 0.05, 0.01, 0.001):
        rows.append(f"| {h:g} s | {dahlquist_error(h, None):.1e} | {dahlquist_error(h, 1e9):.1e} |")
    return "\n".join(rows)


M1, M2, K1, K2, KC, DC = 1.0, 2.0, 10.0, 20.0, 1000.0, 0.5  # as in tests/master/test_coupled_model_exchange.py
A = np.array([[0.0, 1.0, 0.0, 0.0], [-(K1 + KC) / M1, -DC / M1, KC / M1, DC / M1],
              [0.0, 0.0, 0.0, 1.0], [KC / M2, DC / M2, -(K2 + KC) / M2, -DC / M2]])


def oscillator_run(step: float, together: bool, folder: Path) -> tuple[float, float, float]:
    """(relative position error, wall s, CPU s) of one run of the split two-mass oscillator."""
    spec = {
        "units": {
            "left": {"fmu": "builtin:mass_spring_fmi2", "tolerance": 1e-8, "parameters": {"m": M1, "k": K1, "x0": 1.0}},
            "right": {"fmu": "builtin:mass_spring_fmi2", "tolerance": 1e-8,
                      "parameters": {"m": M2, "k": K2, "kc": KC, "dc": DC}},
        },
        "connections": [{"from": "left.x", "to": "right.x_in"}, {"from": "left.v", "to": "right.v_in"},
                        {"from": "right.F_c", "to": "left.F"}],
        "experiment": {"stop": 1.0, "step": step, "coupled_model_exchange": together},
        "record": ["left.x", "right.x"],
    }
    path = folder / f"oscillator_{step}_{together}.json"
    path.write_text(json.dumps(spec))
    system = build_system(load_spec(path))
    wall, cpu = time.perf_counter(), time.process_time()
    result = Execution(system, record=True).run()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    assert result.ok, result.message
    times = result.traces["time"].to_numpy()
    reference = np.array([(expm(A * t) @ [1.0, 0.0, 0.0, 0.0])[[0, 2]] for t in times[:: max(1, len(times) // 500)]])
    got = result.traces[["left.x", "right.x"]].to_numpy()[:: max(1, len(times) // 500)]
    return float(np.max(np.abs(got - reference)) / np.max(np.abs(reference))), wall, cpu


def coupled_table(repeat: int) -> str:
    rows = ["| communication step | together: error | wall | CPU | one by one: error | wall | CPU |",
            "|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as folder:
        for step in (1e-4, 1e-3, 1e-2):
            cells = [f"{step:g} s"]
            for together in (True, False):
                runs = [oscillator_run(step, together, Path(folder)) for _ in range(repeat)]
                cells += [f"{runs[0][0]:.1e}", f"{statistics.median(r[1] for r in runs):.2f} s",
                          f"{statistics.median(r[2] for r in runs):.2f} s"]
            rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", choices=["cap", "coupled", "all"], default="all")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    if args.part in ("cap", "all"):
        print("Dahlquist y' = -y at tolerance 1e-4, largest error at the communication points to t = 2:\n")
        print(cap_table())
    if args.part in ("coupled", "all"):
        print("\nTwo-mass oscillator split into two Model Exchange FMUs, 1 s, tolerance 1e-8:\n")
        print(coupled_table(args.repeat))


if __name__ == "__main__":
    main()
