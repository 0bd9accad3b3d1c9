"""Accuracy of Model Exchange integration: the internal step cap, and connected ME units integrated together.

    python benchmarks/model_exchange_accuracy.py [--part cap|coupled|all] [--repeat 3]

``cap`` (issue 25, item 10): y' = -y, y(0) = 1 (``linear_ode`` as Model Exchange, FMI 2.0) at tolerance 1e-4 to
t = 2, for several communication steps, with CVode's internal step capped at the communication step (the
default) and uncapped (``max_step`` 1e9): the largest error at the communication points against e^-t.

Prints Markdown tables for benchmarks/model_exchange.md.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

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


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", choices=["cap", "coupled", "all"], default="all")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    if args.part in ("cap", "all"):
        print("Dahlquist y' = -y at tolerance 1e-4, largest error at the communication points to t = 2:\n")
        print(cap_table())


if __name__ == "__main__":
    main()
