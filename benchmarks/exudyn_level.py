"""The Exudyn level of the pick-and-place study: Python around the solver, time per point, full-study projection.

Runs the study of ``examples/pick_and_place/spec_exudyn.json`` (trajectory -> PandaExudyn -> energy
FMU, 2 ms steps, Gauss-Seidel) at ``--points`` design points with the units reused and reset between
points, as a sweep worker does, for today's ``PandaExudyn`` and, with ``--before REV``, for the unit
as it was at git revision REV (loaded from ``git show REV:models/panda_exudyn.py``).  Implementations
run interleaved (all at one point, then the next point), so a shared machine's load hits them alike:
compare the ratios of one run.

Two passes over the same points:

1. *clean*: nothing wrapped; the wall time of each point (``Execution.run``) -> time per point and
   the projected full study, ``17061 points x mean time per point / 2 workers`` (the sweep runs one
   point at a time per worker; on this machine the measured full sweep was within 2 % of that
   projection, benchmarks/README.md);
2. *split*: the robot unit's ``do_step``, its solver's ``SolveSteps`` and (today's unit) the
   Newton-Jacobian callback that Exudyn calls from inside ``SolveSteps`` wrapped with timers ->
   per communication step: Exudyn's solver (``SolveSteps`` less the callback, plus the numerical
   differentiation the callback asks Exudyn for), the Python work around it (the rest of
   ``do_step``: feed-forward, parameter update, outputs; plus the callback's own Python) and
   their ratio, the *Python share*.  The timer wrappers' own cost is measured
   and subtracted.

With lock-step groups (``--lockstep K``; by default the group size a sweep worker chooses from the time of a
point run alone), the same two passes run the points K at a time through ``PandaExudynBatch`` as well,
interleaved group by group (with ``--before REV``, the twin as it was at REV too, if it had one); its figures
per step are per point and communication step (the group's time divided by the active rows summed over its steps).

Usage::

    python benchmarks/exudyn_level.py                       # today's unit, 24 points, alone and in lock-step
    python benchmarks/exudyn_level.py --lockstep 12         # lock-step groups of 12 points
    python benchmarks/exudyn_level.py --before 0ca756b      # and the unit before issue 16, interleaved
    python benchmarks/exudyn_level.py --full                # then the full 17061-point study via cosim sweep
                                                            # (minutes; its output folder is removed)

Results are recorded in benchmarks/exudyn_level.md.
"""

from __future__ import annotations

import argparse
import datetime
import importlib.util
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.execution.lockstep import GROUP_SIZE, instantiate, run_lockstep  # noqa: E402
from cosim.execution.run import Execution  # noqa: E402
from cosim.spec.loader import load_spec  # noqa: E402
from cosim.system.builder import build_system  # noqa: E402
from cosim.util.limits import limit  # noqa: E402

SPEC = ROOT / "examples" / "pick_and_place" / "spec_exudyn.json"
STUDY_POINTS = 121 * 141  # the full grid of spec_exudyn.json
# the clock of every timer (--clock): wall time, or this process's CPU time (less disturbed by other
# processes on a loaded machine; on an idle one the two agree for this single-threaded work)
CLOCK = [time.perf_counter]
WORKERS = 2


def machine() -> str:
    model = "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{platform.machine()}, {os.cpu_count()} cores ({model}), Python {platform.python_version()}"


def load_avg() -> str:
    return "{:.2f} {:.2f} {:.2f}".format(*os.getloadavg())


def unit_class_at(revision: str):
    """``PandaExudyn`` as it was at git ``revision``, imported as a sibling of cosim.models.panda_exudyn."""
    source = subprocess.run(["git", "-C", str(ROOT), "show", f"{revision}:models/panda_exudyn.py"],
                            capture_output=True, text=True, check=True).stdout
    folder = Path(tempfile.mkdtemp(prefix="exudyn_before_"))
    path = folder / "panda_exudyn_before.py"
    path.write_text(source)
    name = "cosim.models._panda_exudyn_at_" + revision.replace("-", "_").replace(".", "_")
    spec = importlib.util.spec_from_file_location(name, path)  # parent package cosim.models: relative imports work
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module.PandaExudyn


def design_points(n: int, seed: int = 16) -> list[tuple[float, float]]:
    """``n`` grid points of the study (q2[2] in -100..20, q2[4] in 0..140, degrees), uniformly at random."""
    rng = np.random.default_rng(seed)
    return [(float(rng.integers(-100, 21)), float(rng.integers(0, 141))) for _ in range(n)]


class TimedSolver:
    """Stands in for the unit's Exudyn solver and times ``SolveSteps``; everything else is passed on."""

    def __init__(self, solver):
        self._solver = solver
        self.it = solver.it
        self.seconds = 0.0
        self.calls = 0

    def SolveSteps(self, mbs, settings):  # noqa: N802 (Exudyn's name)
        t0 = CLOCK[0]()
        ok = self._solver.SolveSteps(mbs, settings)
        self.seconds += CLOCK[0]() - t0
        self.calls += 1
        return ok

    def __getattr__(self, name):
        return getattr(self._solver, name)


def timed_jacobian_class(base, level: "Level"):
    """A subclass of the unit's ``NewtonJacobian`` whose calls add their time to ``level.callback_s``."""
    clock = CLOCK[0]

    class TimedNewtonJacobian(base):
        def __call__(self, solver, mbs, settings):
            t0 = clock()
            try:
                return super().__call__(solver, mbs, settings)
            finally:
                level.callback_s += clock() - t0
                level.callback_calls += 1

        def _differentiate(self, solver, mbs, h):  # Exudyn's C++ differentiation: solver work, not Python
            t0 = clock()
            try:
                return super()._differentiate(solver, mbs, h)
            finally:
                level.differentiate_s += clock() - t0
                level.differentiate_calls += 1
    return TimedNewtonJacobian


class Level:
    """One implementation of the robot unit in the study system, its units built once and reused."""

    def __init__(self, label: str, robot_class):
        self.label = label
        self.system = build_system(load_spec(SPEC))
        self.units = {n: su.unit_type.instantiate(n) for n, su in self.system.units.items()}
        self.units["robot"] = robot_class("robot")
        self.walls: list[float] = []
        self.do_step_s = 0.0
        self.do_step_calls = 0
        self.solver: TimedSolver | None = None
        self.callback_s = 0.0  # inside the unit's Newton-Jacobian callback (Python, called by SolveSteps)
        self.callback_calls = 0
        self.differentiate_s = 0.0  # of which in Exudyn's numerical differentiation (C++, solver work)
        self.differentiate_calls = 0

    def run(self, q22: float, q24: float):
        for unit in self.units.values():
            unit.reset()
        overrides = [self.system.assignment_for("traj.waypoints[9]", q22),
                     self.system.assignment_for("traj.waypoints[11]", q24)]
        result = Execution(self.system, overrides, units=self.units).run()
        if not result.ok:
            raise RuntimeError(f"{self.label} at {(q22, q24)}: {result.message}")
        return result

    def time_do_step(self) -> None:
        """Wrap the robot's do_step and its solver with timers (after a first run built the solver)."""
        robot = self.units["robot"]
        self._wrap_with_timers(robot, sys.modules[type(robot).__module__])

    def _wrap_with_timers(self, robot, module) -> None:
        """Time ``robot``'s Newton-Jacobian callback (when it has one), its solver and its do_step."""
        jacobian = getattr(robot, "_jacobian", None)
        if jacobian is not None:  # today's unit: time the callback Exudyn makes into Python
            jacobian.__class__ = timed_jacobian_class(module.NewtonJacobian, self)
        self.solver = TimedSolver(robot._solver)
        robot._solver = self.solver
        plain = robot.do_step
        clock = CLOCK[0]

        def do_step(t, h):
            t0 = clock()
            try:
                return plain(t, h)
            finally:
                self.do_step_s += clock() - t0
                self.do_step_calls += 1
                self._count_step(robot)
        robot.do_step = do_step

    def _count_step(self, robot) -> None:
        """After each timed do_step; one point per step here (a lock-step level counts its active rows)."""


class LockstepLevel(Level):
    """The study's points in lock-step groups of ``rows`` (``PandaExudynBatch``), as a sweep worker runs them."""

    def __init__(self, rows: int, robot_class=None, label: str = ""):
        """``robot_class``: the single unit whose twin (its ``batch_class``) runs the robot; default today's."""
        self.label = label or f"lock-step K={rows}"
        self.rows = rows
        self.system = build_system(load_spec(SPEC))
        self.batches = instantiate(self.system, rows)
        if robot_class is not None:
            self.batches["robot"].terminate()
            self.batches["robot"] = robot_class.batch_class(robot_class, "robot", rows)
        self.units = self.batches
        self.walls = []  # per point: its group's time / the group's size
        self.do_step_s = 0.0
        self.do_step_calls = 0
        self.row_steps = 0  # active rows summed over do_step calls: the points' own communication steps
        self.solver = None
        self.callback_s = 0.0
        self.callback_calls = 0
        self.differentiate_s = 0.0
        self.differentiate_calls = 0

    def run_group(self, points) -> None:
        overrides = [[self.system.assignment_for("traj.waypoints[9]", q22),
                      self.system.assignment_for("traj.waypoints[11]", q24)] for q22, q24 in points]
        for result in run_lockstep(self.system, overrides, self.batches):
            if not result.ok:
                raise RuntimeError(f"{self.label}: {result.message}")
        for batch in self.batches.values():
            batch.reset()

    def time_do_step(self) -> None:
        robot = self.batches["robot"]
        self._wrap_with_timers(robot, sys.modules[robot.single_class.__module__])

    def _count_step(self, robot) -> None:
        self.row_steps += len(robot.active)


def wrapper_cost(n: int = 200_000) -> float:
    """Seconds a timing wrapper like the ones above adds to one call (its clock reads and bookkeeping)."""
    class Target:
        def call(self, a, b):
            return True
    target = Target()
    t0 = CLOCK[0]()
    for _ in range(n):
        target.call(0.0, 0.0)
    bare = CLOCK[0]() - t0
    seconds = [0.0]
    clock = CLOCK[0]

    def wrapped(a, b):
        s = clock()
        try:
            return target.call(a, b)
        finally:
            seconds[0] += clock() - s
    t0 = CLOCK[0]()
    for _ in range(n):
        wrapped(0.0, 0.0)
    return max(0.0, (CLOCK[0]() - t0 - bare) / n)


def full_study(out_parent: Path) -> float:
    """Wall seconds of ``cosim sweep spec_exudyn.json`` (2 workers) from the command to the written table."""
    out = out_parent / "exudyn_full_study"
    command = [sys.executable, "-m", "cosim.cli.main", "sweep", str(SPEC), "--out", str(out), "--workers", str(WORKERS)]
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    print(f"full study: {' '.join(command[1:])}  (load before: {load_avg()})", flush=True)
    t0 = time.perf_counter()
    done = subprocess.run(command, env=env, cwd=str(ROOT))
    seconds = time.perf_counter() - t0
    print(f"full study: exit {done.returncode}, {seconds:.0f} s = {seconds / 60:.1f} min (load after: {load_avg()})")
    shutil.rmtree(out, ignore_errors=True)
    return seconds


def split(level: Level, per_call: float) -> tuple[float, float]:
    """(solver seconds, Python seconds) of a timed level's robot unit (see the module docstring)."""
    calls, steps = level.solver.calls, level.do_step_calls
    differentiate_s = level.differentiate_s - level.differentiate_calls * per_call
    callback_s = level.callback_s - level.callback_calls * per_call - level.differentiate_s  # its Python part
    # Exudyn's own time: SolveSteps less the Python callback it makes (but with the differentiation)
    solver_s = level.solver.seconds - level.callback_s + differentiate_s
    # do_step's own time less both wrappers (around do_step and around SolveSteps) and SolveSteps,
    # plus the Python part of the callback made from inside SolveSteps
    python_s = level.do_step_s - steps * per_call - calls * per_call - level.solver.seconds + callback_s
    return solver_s, python_s


def group_size(single_point_seconds: float) -> int:
    """The lock-step group size a sweep worker chooses for points that take this long alone (cosim.execution.lockstep)."""
    return max(1, min(GROUP_SIZE, int(limit("lockstep_seconds") / max(single_point_seconds, 1e-6))))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--points", type=int, default=24, help="design points per pass (default 24)")
    parser.add_argument("--before", metavar="REV", help="also run PandaExudyn as it was at this git revision")
    parser.add_argument("--lockstep", metavar="K", type=int, default=0,
                        help="lock-step groups of K points (default: the size a sweep worker chooses); 1: none")
    parser.add_argument("--full", action="store_true", help="then run the full study with cosim sweep and time it")
    parser.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                        help="time with the wall clock (default; an idle machine) or this process's CPU time (a loaded one)")
    args = parser.parse_args()
    CLOCK[0] = time.perf_counter if args.clock == "wall" else time.process_time

    print(f"date {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC; machine {machine()}")
    print(f"load average at start: {load_avg()}; clock: {args.clock}")
    from cosim.models.panda_exudyn import PandaExudyn
    levels = [Level("today, one by one", PandaExudyn)]
    if args.before:
        levels.insert(0, Level(f"at {args.before}", unit_class_at(args.before)))
    points = design_points(args.points)
    for level in levels:
        level.run(*points[0])  # warm-up: imports, Exudyn system and solver, FMU instance
    t0 = CLOCK[0]()
    levels[-1].run(*points[1])
    rows = args.lockstep or group_size(CLOCK[0]() - t0)
    groups = [points[i:i + rows] for i in range(0, len(points), rows)] if rows > 1 else []
    groups = [g for g in groups if len(g) == rows]  # whole groups only: one size, one system
    lockstep_levels = [LockstepLevel(rows)] if groups else []
    if groups and args.before and "batch_class" in vars(levels[0].units["robot"].__class__):
        # the twin as it was at REV, interleaved group by group with today's
        lockstep_levels.insert(0, LockstepLevel(rows, type(levels[0].units["robot"]), f"lock-step K={rows} at {args.before}"))
    for lockstep in lockstep_levels:
        lockstep.run_group(groups[0])  # warm-up

    def interleaved(timed: bool) -> None:
        """Every level at each point (lock-step: each group) in turn, so the machine's load hits them alike."""
        for i, group in enumerate(groups or [points]):
            for q22, q24 in group:
                for level in levels:
                    t0 = CLOCK[0]()
                    level.run(q22, q24)
                    if not timed:
                        level.walls.append(CLOCK[0]() - t0)
            for lockstep in lockstep_levels:
                t0 = CLOCK[0]()
                lockstep.run_group(group)
                if not timed:
                    lockstep.walls.extend([(CLOCK[0]() - t0) / rows] * rows)

    interleaved(timed=False)  # pass 1: clean time per point
    per_call = wrapper_cost()
    every = levels + lockstep_levels
    for level in every:
        level.time_do_step()
    interleaved(timed=True)  # pass 2: do_step and SolveSteps timed

    n = sum(len(g) for g in groups) if groups else len(points)
    print(f"{n} points, seed 16; timer wrapper {per_call * 1e6:.2f} us per call (subtracted)")
    print(f"{'unit':22s} {'point mean':>10s} {'median':>8s} {'full study (proj.)':>18s} "
          f"{'solver/step':>11s} {'Python/step':>11s} {'Python share':>12s}")
    first_mean = None
    for level in every:
        mean = statistics.fmean(level.walls)
        first_mean = first_mean or mean
        solver_s, python_s = split(level, per_call)
        # per point and communication step: a lock-step step advances every active row (and integrates the
        # rows that have ended: solver work no point needs, counted in the solver's time)
        steps = getattr(level, "row_steps", level.do_step_calls)
        projected = STUDY_POINTS * mean / WORKERS
        print(f"{level.label:22s} {mean * 1e3:8.1f}ms {statistics.median(level.walls) * 1e3:6.1f}ms "
              f"{projected:8.0f} s = {projected / 60:4.1f} min "
              f"{solver_s / steps * 1e6:9.1f}us {python_s / steps * 1e6:9.1f}us {python_s / solver_s * 100:10.1f} %")
        if level in lockstep_levels:
            print(f"{'':22s} (per point and step; {steps / level.do_step_calls:.2f} of {rows} rows active per step "
                  f"on average; per lock-step step: solver {solver_s / level.do_step_calls * 1e6:.0f} us, "
                  f"Python {python_s / level.do_step_calls * 1e6:.0f} us)")
    for level in every[1:]:
        print(f"time per point, {level.label} / {every[0].label}: {statistics.fmean(level.walls) / first_mean:.3f}")
    print(f"load average at end: {load_avg()}")
    for level in levels:
        for unit in level.units.values():
            unit.terminate()
    for lockstep in lockstep_levels:
        for batch in lockstep.batches.values():
            batch.terminate()
    if args.full:
        with tempfile.TemporaryDirectory(prefix="exudyn_study_") as folder:
            full_study(Path(folder))


if __name__ == "__main__":
    main()
