"""The master's cost per unit per step against raw fmpy calls on the same FMU.

Two linear_ode FMUs coupled in a loop (each step: one get, one set, one doStep
per unit) are run three ways for the same number of steps:

- raw fmpy: the loop a user would write by hand with fmpy's FMU2Slave/FMU3Slave
  (getReal/setReal/doStep, or getFloat64/setFloat64/doStep);
- cosim Execution, no recording;
- cosim Execution with every output recorded;
- the same Executions stepped by the native kernel (``experiment.kernel``: python / native);
- FMI 2.0: a C harness (benchmarks/c_harness.c, compiled here with gcc on first use) stepping the same two
  instances by hand in C, no master: the floor.  ``native loop`` is the kernel's own call (every step, the
  transfers and the probe) timed alone, as the harness times its loop.

Prints microseconds per unit per step and the ratio to raw fmpy, the median
of several interleaved rounds (wall and CPU time).  Usage: python benchmarks/master_overhead.py [--steps N] [--repeat R]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from cosim import Execution, build_system, load_spec
from cosim.fmus.build import c_compiler, ensure_built
from cosim.master.native.algorithm import NativeFixedStep

HARNESS = Path(__file__).resolve().parent / "c_harness.c"


def c_harness(steps: int, h: float) -> tuple[float, float]:
    """(loop seconds, loop seconds) of benchmarks/c_harness.c on two FMI 2.0 linear_ode instances."""
    binary = Path(tempfile.gettempdir()) / f"cosim_c_harness_{int(HARNESS.stat().st_mtime)}"
    if not binary.exists():
        subprocess.run([c_compiler(), "-O2", "-std=c99", "-o", str(binary), str(HARNESS), "-ldl"], check=True)
    path = str(ensure_built("linear_ode", 2))
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    folder = extract(path)
    library = Path(folder) / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
    out = subprocess.run([str(binary), Path(folder, "resources").as_uri(), str(library), md.guid, str(steps),
                          repr(h), str(vr["y"]), str(vr["u"])], check=True, capture_output=True, text=True)
    seconds = float(out.stdout.split()[0])
    return seconds, seconds


class _TimedNative(NativeFixedStep):
    """The kernel, its run() call timed (the loop alone, as the C harness times its own)."""

    loop = 0.0

    def run(self, *args, **kwargs):
        started = time.perf_counter()
        try:
            return super().run(*args, **kwargs)
        finally:
            _TimedNative.loop = time.perf_counter() - started


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


def cosim(version: int, steps: int, h: float, record: bool, algorithm: str, kernel: str = "python",
          loop_only: bool = False) -> tuple[float, float]:
    """(wall, CPU) seconds of the stepping loop of an Execution of the same system (plus its set-up); with
    ``loop_only`` (native) the kernel's run() call alone."""
    spec = {
        "units": {"one": {"fmu": f"builtin:linear_ode_fmi{version}"},
                  "two": {"fmu": f"builtin:linear_ode_fmi{version}"}},
        "connections": [{"from": "one.y", "to": "two.u"}, {"from": "two.y", "to": "one.u"}],
        "experiment": {"stop": steps * h, "step": h, "algorithm": algorithm, "kernel": kernel},
        "record": ["one.y", "two.y"] if record else [],
        "objectives": {"y": {"signal": "one.y", "reduce": "final"}},
    }
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "spec.json"
        path.write_text(json.dumps(spec))
        system = build_system(load_spec(path))
        algorithm_object = _TimedNative(system.spec.experiment, algorithm) if loop_only else None
        started_cpu = time.process_time()
        result = Execution(system, record=record, algorithm=algorithm_object).run()
        cpu = time.process_time() - started_cpu
    assert result.ok and result.steps == steps, result.message
    if loop_only:
        return _TimedNative.loop, _TimedNative.loop
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
    worst = 0.0
    native_vs_c: list[float] = []
    for version in (2, 3):
        cosim(version, 100, h, False, "gauss-seidel")  # warm up: build, extract, import, compile the kernel
        cosim(version, 100, h, False, "gauss-seidel", "native")
        variants = {"raw fmpy (get/set/doStep)": lambda: raw_fmpy(version, args.steps, h)}
        if version == 2:
            variants["C harness (get/set/doStep)"] = lambda: c_harness(args.steps, h)
        for algorithm in ("gauss-seidel", "jacobi"):
            for kernel in ("python", "native"):
                for record in (False, True):
                    label = f"{kernel} {algorithm}{' +record' if record else ''}"
                    variants[label] = lambda a=algorithm, r=record, k=kernel: cosim(version, args.steps, h, r, a, k)
            variants[f"native {algorithm} loop"] = lambda a=algorithm: cosim(version, args.steps, h, False, a,
                                                                              "native", loop_only=True)
        wall: dict[str, list[float]] = {name: [] for name in variants}
        cpu: dict[str, list[float]] = {name: [] for name in variants}
        for _ in range(args.repeat):  # interleaved: every variant once per round
            for name, run in variants.items():
                w, c = run()
                wall[name].append(w)
                cpu[name].append(c)
        raw = "raw fmpy (get/set/doStep)"
        harness = "C harness (get/set/doStep)"
        print(f"{'FMI':>4} {'variant':<30} {'us/unit/step':>12} {'x raw':>7} {'x raw (CPU)':>12} {'x C':>7}")
        for name in variants:
            ratio = statistics.median(a / b for a, b in zip(wall[name], wall[raw]))
            ratio_cpu = statistics.median(a / b for a, b in zip(cpu[name], cpu[raw]))
            per = statistics.median(wall[name]) / args.steps / 2 * 1e6
            to_c = (f"{statistics.median(a / b for a, b in zip(wall[name], wall[harness])):>7.2f}"
                    if harness in wall else f"{'':>7}")
            print(f"{version:>4} {name:<30} {per:>12.3f} {ratio:>7.2f} {ratio_cpu:>12.2f} {to_c}")
            if name in ("python gauss-seidel", "python jacobi"):
                worst = max(worst, ratio)
            if harness in wall and name.endswith(" loop"):
                native_vs_c.append(statistics.median(a / b for a, b in zip(wall[name], wall[harness])))
    print(f"target: the Python master (no recording) costs at most a hand-written fmpy loop (<= 1x): "
          f"{'met' if worst <= 1.0 else 'NOT met'} (worst {worst:.2f}x, median of per-round wall ratios)")
    if native_vs_c:
        print(f"target: the native kernel's loop costs at most 4x the C harness's (FMI 2.0): "
              f"{'met' if max(native_vs_c) <= 4.0 else 'NOT met'} (worst {max(native_vs_c):.2f}x)")

if __name__ == "__main__":
    main()
