"""What a warm start saves: points of a study started from one saved warm-up instead of from the start time.

A damped oscillator split into two `linear_ode` FMUs (FMI 2.0 and 3.0, built from src/cosim/fmus/linear_ode)
exchanging position and velocity, Gauss-Seidel, step 1 ms, 10 s; the points vary the spring (vel.b, tunable) from
t = 9 s on.  Cold: every point runs 0 -> 10 s.  Warm: `"warm_start": 9`, the warm-up (0 -> 9 s, saved and
serialized) made once, then every point restores it and runs 9 -> 10 s.  Both in this process through
run_point, as a sweep's point child runs them (no Dask: the points' own cost).  Prints CPU seconds per point
(best of the rounds), the warm-up's cost, the steps each point took, the bytes of the serialized states, and the
largest difference between a warm and a cold point with the spec's own values (0: bit for bit).
Usage: python benchmarks/warm_start.py [--points N] [--repeat R]
"""

from __future__ import annotations

import argparse
import math
import os
import pickle
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from cosim.execution.point import run_point
from cosim.execution.warm_up import warmed
from cosim.spec.loader import spec_from_dict
from cosim.system.builder import build_system

K, C = 4 * math.pi ** 2, 0.5


def spec(warm: float | None) -> dict:
    experiment = {"stop": 10.0, "step": 1e-3, **({"warm_start": warm} if warm is not None else {})}
    return {"units": {"pos": {"fmu": "builtin:linear_ode_fmi2", "parameters": {"a": 0.0, "b": 1.0, "x0": 1.0}},
                      "vel": {"fmu": "builtin:linear_ode_fmi3", "parameters": {"a": -C, "b": -K, "x0": 0.0}}},
            "connections": [{"from": "vel.y", "to": "pos.u"}, {"from": "pos.y", "to": "vel.u"}],
            "experiment": experiment,
            "objectives": {"x_end": {"signal": "pos.y", "reduce": "final"},
                           "x_rms": {"signal": "pos.y", "reduce": "rms"}}}


def cpu(fn) -> tuple[float, object]:
    started = time.process_time()
    out = fn()
    return time.process_time() - started, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--points", type=int, default=8)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="warm_start_bench_"))
    cold_system = build_system(spec_from_dict(spec(None), folder / "spec.json"))
    warm_spec = build_system(spec_from_dict(spec(9.0), folder / "spec.json"))
    springs = -K * np.linspace(0.5, 2.0, args.points)
    cold_best = warm_best = warmup_best = math.inf
    for _ in range(args.repeat):
        seconds, cold = cpu(lambda: [run_point(cold_system, {"vel.b": b}) for b in springs])
        cold_best = min(cold_best, seconds / args.points)
        seconds, system = cpu(lambda: warmed(warm_spec))
        warmup_best = min(warmup_best, seconds)
        seconds, warm = cpu(lambda: [run_point(system, {"vel.b": b}) for b in springs])
        warm_best = min(warm_best, seconds / args.points)
    assert all(r.ok for r in cold + warm)
    same = run_point(system, None).objectives, run_point(cold_system, None).objectives
    difference = max(abs(same[0][k] - same[1][k]) for k in same[0])
    state_bytes = sum(len(b) for _, b in system.warm_start.states)
    load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"# warm start: {args.points} points, best CPU time of {args.repeat} rounds; {platform.machine()}, "
          f"{os.cpu_count()} cores, load {load}, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    print(f" cold point (0 -> 10 s, {cold[0].steps} steps):  {cold_best * 1e3:8.1f} ms CPU")
    print(f" warm point (9 -> 10 s, {warm[0].steps} steps):  {warm_best * 1e3:8.1f} ms CPU")
    print(f" warm-up, once (0 -> 9 s, saved):      {warmup_best * 1e3:8.1f} ms CPU; serialized states "
          f"{state_bytes} bytes, the whole warm state pickled {len(pickle.dumps(system.warm_start))} bytes")
    print(f" {args.points} points: cold {cold_best * args.points:.2f} s, warm {warmup_best + warm_best * args.points:.2f} s"
          f" (warm-up included); speed-up per point {cold_best / warm_best:.1f}x")
    print(f" spec's own values, warm vs cold: largest objective difference {difference:g}")


if __name__ == "__main__":
    main()
