"""Wall time of one bin-picking design point: planning vs simulation (see bin_picking.md).

Usage: ``python benchmarks/bin_picking.py [results.parquet]``.  Runs three
points of examples/bin_picking/spec.json (a valid one, one blocked in the box,
one out of reach) REPEATS times each with the units reused (as a sweep worker
does) and prints medians; with a results table it also summarises the sweep's
per-point run times.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.execution.run import Execution  # noqa: E402
from cosim.spec.loader import load_spec  # noqa: E402
from cosim.system.builder import build_system  # noqa: E402

SPEC = ROOT / "examples" / "bin_picking" / "spec.json"
REPEATS = 5
POINTS = {
    "valid (0, 0, 0), simple": {"planner.offset_x": 0.0, "planner.offset_y": 0.0, "planner.offset_z": 0.0, "planner.box_variant": "simple"},
    "blocked by the lip (0.1, 0, 0), complex": {"planner.offset_x": 0.1, "planner.offset_y": 0.0, "planner.offset_z": 0.0, "planner.box_variant": "complex"},
    "start out of reach (-0.4, -0.2, -0.4)": {"planner.offset_x": -0.4, "planner.offset_y": -0.2, "planner.offset_z": -0.4, "planner.box_variant": "simple"},
}


def main() -> None:
    system = build_system(load_spec(str(SPEC)))
    units = {n: su.unit_type.instantiate(n) for n, su in system.units.items()}
    try:
        for label, values in POINTS.items():
            total, plan, steps = [], [], 0
            for _ in range(REPEATS + 1):  # the first run warms caches (model, meshes, FMU)
                for u in units.values():
                    u.reset()
                units["planner"]._plan_key = None  # plan again: a sweep point always has new parameters
                overrides = [system.assignment_for(k, v) for k, v in values.items()]
                t0 = time.perf_counter()
                r = Execution(system, overrides, units=units, record=False).run()
                total.append(time.perf_counter() - t0)
                plan.append(r.objectives["planning_time"])
                steps = r.steps
            t, p = statistics.median(total[1:]), statistics.median(plan[1:])
            print(f"{label:42s} steps={steps:5d}  whole point {t * 1e3:7.1f} ms  planning {p * 1e3:6.1f} ms  "
                  f"simulation+rest {(t - p) * 1e3:7.1f} ms  per step {(t - p) / max(steps, 1) * 1e6:6.1f} us  "
                  f"(fraction {r.objectives['fraction_planned']:.3f}, executed_ok {r.objectives['executed_ok']:.0f})")
    finally:
        for u in units.values():
            u.terminate()
    if len(sys.argv) > 1:
        import pandas as pd

        df = pd.read_parquet(sys.argv[1])
        col = next(c for c in ("elapsed", "run_time", "duration_s", "wall_time") if c in df.columns)
        for name, d in df.groupby(df["executed_ok"] == 1.0):
            print(f"sweep rows executed_ok={name}: {len(d)} points, run time median {d[col].median():.3f} s, "
                  f"mean {d[col].mean():.3f} s, planning median {d['planning_time'].median() * 1e3:.1f} ms")


if __name__ == "__main__":
    main()
