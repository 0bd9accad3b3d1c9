"""Cost of one pick-and-place point per fidelity level, split into unit work and orchestration.

For each configuration (a spec of ``examples/pick_and_place`` with the robot
unit, communication step and reference sampling it names) this builds the
system once, instantiates the units once and runs ``POINTS`` design points
through :class:`cosim.Execution` with the units reused (``reset()``
between points), as a sweep worker does.  The configurations run interleaved
(all of them at one point, then the next point) so that a shared machine's
changing load hits them alike: compare ratios within one run.  Every unit's ``do_step``, ``get``,
``set`` and lifecycle calls are wrapped with a timer, so

    unit work     = time inside the units' own calls (FMU calls, Exudyn, pinocchio, the trajectory)
    orchestration = Execution wall time - unit work (master loop, transfers, probes, reducers, setup)

The timer wrappers themselves cost ``WRAP_COST`` per call, measured below and
subtracted from the unit work (they are part of neither).  The energy of each
configuration is compared with the inverse-dynamics 0.25 ms run at the same
points (for Exudyn this includes what the servo adds, mostly at joints that
stand still under load, see examples/pick_and_place/README.md).

Usage::

    python benchmarks/fidelity_levels.py            # all configurations, 12 points each
    python benchmarks/fidelity_levels.py --points 30

Results are recorded in benchmarks/fidelity_levels.md.
"""

from __future__ import annotations

import argparse
import copy
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.execution.run import Execution  # noqa: E402
from cosim.spec.loader import spec_from_dict  # noqa: E402
from cosim.system.builder import build_system  # noqa: E402

SPEC = ROOT / "examples" / "pick_and_place" / "spec.json"
ID = "models.panda_inverse_dynamics:PandaInverseDynamics"
EXUDYN = "models.panda_exudyn:PandaExudyn"
TIMED = ("do_step", "get", "set", "setup", "enter_initialization", "exit_initialization", "reset")

# name -> (robot unit, communication step, trajectory sampling, robot parameters)
BEFORE_EXUDYN = {"substep": 0.001, "ref_timing": "step_start", "ref_phase": 0.5}  # the units' defaults
AFTER_EXUDYN = {"substep": 0.002, "ref_timing": "step_end", "ref_phase": 1.0}  # spec_exudyn.json
CONFIGS = {
    "ID, 1 ms, instant (before)": (ID, 0.001, "instant", {}),
    "ID, 10 ms, step_midpoint (after, spec.json)": (ID, 0.01, "step_midpoint", {}),
    "Exudyn, 1 ms steps (before)": (EXUDYN, 0.001, "instant", BEFORE_EXUDYN),
    "Exudyn, 2 ms steps (after, spec_exudyn.json)": (EXUDYN, 0.002, "instant", AFTER_EXUDYN),
}
REFERENCE = (ID, 0.00025, "step_midpoint", {})


def make_raw(robot: str, step: float, sampling: str, parameters: dict) -> dict:
    """The study spec (as a dict) at one fidelity level."""
    raw = copy.deepcopy(json.loads(SPEC.read_text()))
    raw["units"]["robot"]["python"] = robot
    raw["units"]["robot"]["parameters"] = dict(parameters)
    raw["experiment"]["step"] = step
    raw["units"]["traj"]["parameters"]["sampling"] = sampling
    return raw


def design_points(n: int, seed: int = 7) -> list[tuple[float, float]]:
    """``n`` grid points of the study (q2[2], q2[4]) in degrees: the four corners, then random ones."""
    rng = np.random.default_rng(seed)
    corners = [(0.0, 0.0), (-100.0, 140.0), (20.0, 140.0), (-100.0, 0.0)]
    rest = [(float(rng.integers(-100, 21)), float(rng.integers(0, 141))) for _ in range(max(0, n - 4))]
    return (corners + rest)[:n]


class UnitClock:
    """Wraps the protocol methods of live units with one accumulating timer."""

    def __init__(self, units: dict):
        self.total = 0.0
        self.calls = 0
        for unit in units.values():
            for name in TIMED:
                setattr(unit, name, self._wrap(getattr(unit, name)))

    def _wrap(self, method):
        clock = time.perf_counter

        def timed(*args):
            t0 = clock()
            try:
                return method(*args)
            finally:
                self.total += clock() - t0
                self.calls += 1
        return timed


def wrap_cost(n: int = 200_000) -> float:
    """Seconds one timer wrapper adds per call (its own two clock reads and bookkeeping)."""
    class Dummy:
        def do_step(self, *a):
            return None
    plain = Dummy()
    t0 = time.perf_counter()
    for _ in range(n):
        plain.do_step(0.0, 0.0)
    bare = time.perf_counter() - t0
    wrapped = Dummy()
    clock = UnitClock.__new__(UnitClock)
    clock.total, clock.calls = 0.0, 0
    wrapped.do_step = clock._wrap(wrapped.do_step)
    t0 = time.perf_counter()
    for _ in range(n):
        wrapped.do_step(0.0, 0.0)
    return max(0.0, (time.perf_counter() - t0 - bare) / n)


class Bench:
    """One configuration, built once: its system, live units (reused) and their clock."""

    def __init__(self, robot: str, step: float, sampling: str, parameters: dict, timed: bool = True):
        self.system = build_system(spec_from_dict(make_raw(robot, step, sampling, parameters), SPEC))
        self.units = {n: su.unit_type.instantiate(n) for n, su in self.system.units.items()}
        self.clock = UnitClock(self.units) if timed else None
        self.rows: list[tuple[float, float, int, float]] = []

    def run(self, q22: float, q24: float, keep: bool = True) -> None:
        """Run one point; keep (wall s, unit s, unit calls, e_total J) unless it is a warm-up."""
        for u in self.units.values():
            u.reset()
        system = self.system
        overrides = [system.assignment_for("traj.waypoints[9]", q22), system.assignment_for("traj.waypoints[11]", q24)]
        unit0, calls0 = (self.clock.total, self.clock.calls) if self.clock else (0.0, 0)
        result = Execution(system, overrides, units=self.units).run()
        if not result.ok:
            raise RuntimeError(result.message)
        if keep:
            unit_s = (self.clock.total - unit0) if self.clock else float("nan")
            calls = (self.clock.calls - calls0) if self.clock else 0
            self.rows.append((result.elapsed, unit_s, calls, result.objectives["e_total"]))

    def close(self) -> None:
        for u in self.units.values():
            u.terminate()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--points", type=int, default=12)
    args = parser.parse_args()
    points = design_points(args.points)
    per_call = wrap_cost()
    print(f"timer wrapper cost {per_call * 1e6:.2f} us per call (subtracted from unit work)")
    reference = Bench(*REFERENCE, timed=False)
    benches = {name: Bench(*config) for name, config in CONFIGS.items()}
    for bench in [reference, *benches.values()]:
        bench.run(*points[0], keep=False)  # warm-up: imports, model build, first allocation
    # Interleaved (every configuration at one point, then the next point), so that the
    # load of a shared machine drifts over all configurations alike and ratios hold.
    for q22, q24 in points:
        for bench in [reference, *benches.values()]:
            bench.run(q22, q24)
    ref = [r[3] for r in reference.rows]
    first = None
    print(f"{'configuration':46s} {'wall/point':>10s} {'units':>9s} {'orchestr.':>9s} {'ratio':>6s} "
          f"{'vs first':>8s} {'max |dE| vs ID 0.25 ms':>22s}")
    for name, bench in benches.items():
        rows = bench.rows
        wall = statistics.median(r[0] for r in rows)
        unit = statistics.median(r[1] - r[2] * per_call for r in rows)
        err = max(abs(r[3] - e) / e for r, e in zip(rows, ref))
        first = first or wall
        print(f"{name:46s} {wall * 1e3:8.1f}ms {unit * 1e3:7.1f}ms {(wall - unit) * 1e3:7.1f}ms "
              f"{wall / unit:6.2f} {wall / first:8.3f} {err * 100:20.2f} %", flush=True)
        bench.close()
    reference.close()
    print(f"points: {points}")


if __name__ == "__main__":
    main()
