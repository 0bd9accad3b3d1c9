"""The master's cost per unit per step against raw fmpy calls on the same FMU.

Two linear_ode FMUs coupled in a loop (each step: one get, one set, one doStep
per unit) are run three ways for the same number of steps:

- raw fmpy: the loop a user would write by hand with fmpy's FMU2Slave/FMU3Slave
  (getReal/setReal/doStep, or getFloat64/setFloat64/doStep);
- cosim Execution, no recording;
- cosim Execution with every output recorded.

Prints microseconds per unit per step and the ratio to raw fmpy, the median
of several interleaved rounds (wall and CPU time).  Usage: python benchmarks/master_overhead.py [--steps N] [--repeat R]
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

from cosim import Execution, build_system, load_spec
from cosim.fmus.build import ensure_built


def raw_fmpy(version: int, steps: int, h: float) -> tuple[float, float]:
    """(wall, CPU) seconds for `steps` steps of two coupled FMUs driven directly through fmpy."""
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
    started, started_cpu = time.perf_counter(), time.process_time()
    for k in range(steps):
        t = k * h
        ya = getattr(a, get)(y)
        yb = getattr(b, get)(y)
        getattr(a, put)(u, yb)
        getattr(b, put)(u, ya)
        a.doStep(t, h)
        b.doStep(t, h)
    elapsed, cpu = time.perf_counter() - started, time.process_time() - started_cpu
    for s in slaves:
        s.terminate()
        s.freeInstance()
    return elapsed, cpu


def cosim(version: int, steps: int, h: float, record: bool, algorithm: str) -> tuple[float, float]:
    """(wall, CPU) seconds of the stepping loop of an Execution of the same system (plus its set-up)."""
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
        started_cpu = time.process_time()
        result = Execution(system, record=record).run()
        cpu = time.process_time() - started_cpu
    assert result.ok and result.steps == steps, result.message
    return result.elapsed, cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    h = 1e-3
    load = os.getloadavg()
    print(f"# master overhead: 2 coupled linear_ode FMUs, {args.steps} steps, median of {args.repeat} interleaved "
          f"rounds; {platform.machine()}, {os.cpu_count()} cores, load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}, "
          f"{time.strftime('%Y-%m-%d %H:%M %Z')}")
    print(f"{'FMI':>4} {'variant':<28} {'us/unit/step':>12} {'x raw':>7} {'x raw (CPU)':>12}")
    worst = 0.0
    for version in (2, 3):
        cosim(version, 100, h, False, "gauss-seidel")  # warm up: build, extract, import
        variants = {"raw fmpy (get/set/doStep)": lambda: raw_fmpy(version, args.steps, h)}
        for algorithm in ("gauss-seidel", "jacobi"):
            for record in (False, True):
                label = f"cosim {algorithm}{' +record' if record else ''}"
                variants[label] = lambda a=algorithm, r=record: cosim(version, args.steps, h, r, a)
        wall: dict[str, list[float]] = {name: [] for name in variants}
        cpu: dict[str, list[float]] = {name: [] for name in variants}
        for _ in range(args.repeat):  # interleaved: every variant once per round
            for name, run in variants.items():
                w, c = run()
                wall[name].append(w)
                cpu[name].append(c)
        raw = "raw fmpy (get/set/doStep)"
        for name in variants:
            ratio = statistics.median(a / b for a, b in zip(wall[name], wall[raw]))
            ratio_cpu = statistics.median(a / b for a, b in zip(cpu[name], cpu[raw]))
            per = statistics.median(wall[name]) / args.steps / 2 * 1e6
            print(f"{version:>4} {name:<28} {per:>12.2f} {ratio:>7.2f} {ratio_cpu:>12.2f}")
            if name in ("cosim gauss-seidel", "cosim jacobi"):
                worst = max(worst, ratio)
    print(f"target: the master (no recording) costs at most a hand-written fmpy loop (<= 1x): "
          f"{'met' if worst <= 1.0 else 'NOT met'} (worst {worst:.2f}x, median of per-round wall ratios)")


if __name__ == "__main__":
    main()
