"""The master's cost per unit per step against raw fmpy calls on the same FMU.

Two linear_ode FMUs coupled in a loop (each step: one get, one set, one doStep
per unit) are run three ways for the same number of steps:

- raw fmpy: the loop a user would write by hand with fmpy's FMU2Slave/FMU3Slave
  (getReal/setReal/doStep, or getFloat64/setFloat64/doStep);
- cosim Execution, no recording;
- cosim Execution with every output recorded.

Prints microseconds per unit per step and the ratio to raw fmpy, the median
of several repetitions.  Usage: python benchmarks/master_overhead.py [--steps N] [--repeat R]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from cosim.fmus.build import ensure_built
from orchestrator import Execution, build_system, load_spec


def raw_fmpy(version: int, steps: int, h: float) -> float:
    """Seconds for `steps` steps of two coupled FMUs driven directly through fmpy."""
    path = str(ensure_built("linear_ode", version))
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    folder = extract(path)
    slaves = []
    for name in ("one", "two"):
        cls = FMU2Slave if version == 2 else FMU3Slave
        s = cls(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                instanceName=name)
        s.instantiate()
        if version == 2:
            s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.exitInitializationMode()
        slaves.append(s)
    get = "getReal" if version == 2 else "getFloat64"
    put = "setReal" if version == 2 else "setFloat64"
    a, b = slaves
    y, u = [vr["y"]], [vr["u"]]
    started = time.perf_counter()
    for k in range(steps):
        t = k * h
        ya = getattr(a, get)(y)
        yb = getattr(b, get)(y)
        getattr(a, put)(u, yb)
        getattr(b, put)(u, ya)
        a.doStep(t, h)
        b.doStep(t, h)
    elapsed = time.perf_counter() - started
    for s in slaves:
        s.terminate()
        s.freeInstance()
    return elapsed


def cosim(version: int, steps: int, h: float, record: bool, algorithm: str) -> float:
    """Seconds spent in the stepping loop of an Execution of the same system."""
    spec = {
        "units": {"one": {"fmu": f"builtin:linear_ode_fmi{version}"},
                  "two": {"fmu": f"builtin:linear_ode_fmi{version}"}},
        "connections": [{"from": "one.y", "to": "two.u"}, {"from": "two.y", "to": "one.u"}],
        "experiment": {"stop": steps * h, "step": h, "algorithm": algorithm},
        "record": ["one.y", "two.y"] if record else [],
        "objectives": {"y": {"signal": "one.y", "reduce": "final"}},
    }
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "spec.json"
        path.write_text(json.dumps(spec))
        system = build_system(load_spec(path))
        result = Execution(system, record=record).run()
    assert result.ok and result.steps == steps, result.message
    return result.elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    h = 1e-3
    print(f"# master overhead: 2 coupled linear_ode FMUs, {args.steps} steps, median of {args.repeat}; "
          f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, {time.strftime('%Y-%m-%d')}")
    print(f"{'FMI':>4} {'variant':<28} {'us/unit/step':>12} {'x raw':>7}")
    for version in (2, 3):
        cosim(version, 100, h, False, "gauss-seidel")  # warm up: build, extract, import
        raw = statistics.median(raw_fmpy(version, args.steps, h) for _ in range(args.repeat))
        per = lambda seconds: seconds / args.steps / 2 * 1e6  # noqa: E731
        print(f"{version:>4} {'raw fmpy (get/set/doStep)':<28} {per(raw):>12.2f} {1.0:>7.2f}")
        for algorithm in ("gauss-seidel", "jacobi"):
            for record in (False, True):
                t = statistics.median(cosim(version, args.steps, h, record, algorithm) for _ in range(args.repeat))
                label = f"cosim {algorithm}{' +record' if record else ''}"
                print(f"{version:>4} {label:<28} {per(t):>12.2f} {t / raw:>7.2f}")


if __name__ == "__main__":
    main()
