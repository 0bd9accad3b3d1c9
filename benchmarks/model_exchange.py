"""Cost per communication step of a Model Exchange unit (CVode inside each step) against co-simulation.

    python benchmarks/model_exchange.py [--steps 2000] [--repeat 5]

Cases, each run through cosim's unit API (setup, initialize, do_step loop; one output read per step):

* ``linear_ode`` CS: the FMU's own exact doStep (the floor: one FMI call per step);
* ``linear_ode`` ME, input constant: CVode continues across steps (no restart);
* ``linear_ode`` ME, input changed every step: the solver restarts at every communication point, which is
  what a unit coupled to others sees;
* ``bouncing_ball`` ME: state events (11 bounces in 3 s) and the resting ball;
* ``square_lag`` ME: a time event every 0.1 s;
* fmpy's ``simulate_fmu`` (ModelExchange, CVode) on ``linear_ode`` with the same output interval, as the
  reference for what an ME loop in Python costs.

Prints a Markdown table: microseconds per communication step (median of ``--repeat`` runs).
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cosim.fmus.build import ensure_built  # noqa: E402
from cosim.units.fmu.description import FmuUnitType  # noqa: E402
from cosim.units.fmu.model_exchange import SolverSettings  # noqa: E402
from cosim.units.protocol import ElementRef  # noqa: E402

STEP = 1e-3


def per_step(fmu: str, version: int, steps: int, interface: str | None, change_input: bool = False,
             parameters: dict | None = None, tolerance: float = 1e-6) -> float:
    """Seconds per communication step of one run of ``steps`` steps."""
    settings = SolverSettings(tolerance) if interface != "co-simulation" else None
    unit = FmuUnitType(ensure_built(fmu, version), interface=interface, solver_settings=settings).instantiate("u")
    unit.setup(0.0, steps * STEP)
    unit.set_values(parameters or {})
    unit.enter_initialization()
    unit.exit_initialization()
    output = unit.select([ElementRef(unit.description.outputs()[0].name)])
    has_input = bool(unit.description.inputs())
    if has_input:
        input_ = unit.select([ElementRef(unit.description.inputs()[0].name)])
    started = time.perf_counter()
    for k in range(steps):
        if has_input:
            unit.set(input_, [math.sin(k * STEP) if change_input else 0.5])
        unit.do_step(k * STEP, STEP)
        unit.get(output)
    elapsed = time.perf_counter() - started
    unit.terminate()
    return elapsed / steps


def fmpy_per_step(steps: int, tolerance: float = 1e-6) -> float:
    from fmpy import simulate_fmu

    path = str(ensure_built("linear_ode", 3))
    started = time.perf_counter()
    simulate_fmu(path, fmi_type="ModelExchange", stop_time=steps * STEP, output_interval=STEP,
                 relative_tolerance=tolerance, record_events=False, start_values={"u": 0.5})
    return (time.perf_counter() - started) / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    cases = [
        ("linear_ode", "co-simulation (exact doStep)", dict(fmu="linear_ode", interface="co-simulation")),
        ("linear_ode", "model exchange, input constant", dict(fmu="linear_ode", interface="model-exchange")),
        ("linear_ode", "model exchange, input changed every step",
         dict(fmu="linear_ode", interface="model-exchange", change_input=True)),
        ("bouncing_ball", "model exchange, state events", dict(fmu="bouncing_ball", interface=None)),
        ("square_lag", "model exchange, time event every 0.1 s", dict(fmu="square_lag", interface=None)),
    ]
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    print(f"`python benchmarks/model_exchange.py --steps {args.steps} --repeat {args.repeat}` - "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {os.cpu_count()} cores, uptime: {load}\n")
    print("| FMU | FMI | case | µs per step |")
    print("|---|---|---|---|")
    for version in (2, 3):
        for fmu, label, kwargs in cases:
            times = [per_step(version=version, steps=args.steps, **kwargs) for _ in range(args.repeat)]
            print(f"| {fmu} | {version}.0 | {label} | {statistics.median(times) * 1e6:.1f} |", flush=True)
    times = [fmpy_per_step(args.steps) for _ in range(args.repeat)]
    print(f"| linear_ode | 3.0 | fmpy simulate_fmu, ModelExchange (CVode), input constant | "
          f"{statistics.median(times) * 1e6:.1f} |")
    print(f"\nstep {STEP:g} s, tolerance 1e-6; after: `uptime`: "
          f"{subprocess.run(['uptime'], capture_output=True, text=True).stdout.strip()}")


if __name__ == "__main__":
    main()
