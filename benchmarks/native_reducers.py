"""What computing the objectives in C (cosim.master.native.reducers) saves a native run.

    python benchmarks/native_reducers.py [--repeat 7]

1. The reduction alone: a run's 1001 rows of 8 probed columns reduced to (a) the sweep ring's 2 objectives
   (final, integral) and (b) 11 objectives using all 10 reductions, by the Python ObjectiveReducer (load the rows,
   then results()) and by reduce_rows, alternating; medians of --repeat rounds of 200 calls each.
2. (CPU time, time.process_time, in both parts: less disturbed by other processes than wall time.)
3. A whole native run (the units instantiated and initialized each time, as a fresh point) of the 2-FMU
   linear_ode ring (10^3 steps, FMI 2.0, the 2 objectives, no recording) with
   the C reducers and with the Python ones (the drive told to use ObjectiveReducer.load), alternating.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

REDUCTIONS = ["final", "initial", "min", "max", "mean", "integral", "integral_abs", "rms", "time_of_max",
              "time_of_min"]


def reduction_alone(objectives, repeat: int) -> tuple[float, float]:
    from cosim.master.native.reducers import reduce_rows
    from cosim.master.observers import ObjectiveReducer

    rng = np.random.default_rng(1)
    rows, times = rng.standard_normal((1001, 8)), np.linspace(0.0, 1.0, 1001)
    columns = [f"c{i}" for i in range(8)]
    spent: dict[str, list[float]] = {"python": [], "c": []}
    reducer = ObjectiveReducer(columns, objectives)  # made once: the run makes it either way
    for _ in range(repeat):
        started = time.process_time()
        for _ in range(200):
            reducer.load(times, rows)
            reducer.results()
        spent["python"].append((time.process_time() - started) / 200)
        started = time.process_time()
        for _ in range(200):
            reduce_rows(times, rows, reducer.objectives, reducer.kept, reducer.slices)
        spent["c"].append((time.process_time() - started) / 200)
    return statistics.median(spent["python"]), statistics.median(spent["c"])


def whole_runs(repeat: int) -> tuple[float, float]:
    import cosim.execution.native as native
    from cosim import Execution, build_system, load_spec
    from cosim.master.observers import ObjectiveReducer

    spec = {"units": {"one": {"fmu": "builtin:linear_ode_fmi2"},
                      "two": {"fmu": "builtin:linear_ode_fmi2", "parameters": {"a": -2.0}}},
            "connections": [{"from": "one.y", "to": "two.u"}, {"from": "two.y", "to": "one.u"}],
            "experiment": {"stop": 1.0, "step": 1e-3, "kernel": "native"},
            "objectives": {"y_end": {"signal": "one.y", "reduce": "final"},
                           "y_int": {"signal": "two.y", "reduce": "integral"}}}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "ring.json"
        path.write_text(json.dumps(spec))
        system = build_system(load_spec(path))
        spent: dict[str, list[float]] = {"python": [], "c": []}
        original = native.reduce_rows
        results = {}
        try:
            for _ in range(repeat):
                for way in ("python", "c"):
                    native.reduce_rows = original if way == "c" else _python_reduction(ObjectiveReducer)
                    started = time.process_time()
                    for _ in range(50):
                        result = Execution(system).run()
                    spent[way].append((time.process_time() - started) / 50)
                    results[way] = result.objectives
        finally:
            native.reduce_rows = original
        assert results["python"] == results["c"], results
    return statistics.median(spent["python"]), statistics.median(spent["c"])


def _python_reduction(reducer_class):
    """reduce_rows done by the Python reducer, for the comparison (same arguments, same results)."""
    def reduce(times, rows, objectives, kept, slices):
        columns = [str(i) for i in range(rows.shape[1])]
        python = reducer_class(columns, [(name, how, [columns[k] for k in kept[part]])
                                         for (name, how), part in zip(objectives, slices)])
        python.load(times, rows)
        return python.results()
    return reduce


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args()
    print(f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; {os.cpu_count()} cores; "
          f"load {os.getloadavg()[0]:.1f}")
    ring = [("y_end", "final", ["c0"]), ("y_int", "integral", ["c1"])]
    every = [(f"o_{r}", r, ["c2"]) for r in REDUCTIONS] + [("o_arr", "integral", ["c0", "c1", "c3"])]
    for label, objectives in (("ring's 2 objectives", ring), ("11 objectives, every reduction", every)):
        python, c = reduction_alone(objectives, args.repeat)
        print(f"reduction of 1001 rows, {label}: python {python * 1e6:.1f} us, C {c * 1e6:.1f} us "
              f"(saves {(python - c) * 1e6:.1f} us, {python / c:.1f}x)")
    python, c = whole_runs(args.repeat)
    print(f"whole native run, 2-FMU ring, 10^3 steps: python reducers {python * 1e6:.0f} us, C reducers "
          f"{c * 1e6:.0f} us ({(python - c) / python:.1%} of the run saved)")
    print(f"load at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
