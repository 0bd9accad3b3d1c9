"""`cosim sweep` of the README's main job against a serial in-process loop over the same points.

    python benchmarks/sweep_startup.py                 # 5 interleaved pairs + one timed breakdown
    python benchmarks/sweep_startup.py --repeat 9 --spec examples/pick_and_place/spec_coarse.json

Both sides are whole processes started by this script, timed from the launch to their exit (the sweep's
table is written before it exits), with the same Python (``sys.executable``):

- serial: ``python benchmarks/sweep_startup.py --serial SPEC`` loads the spec, builds the system,
  instantiates the units once and runs every point of the design space one after the other (``reset()``
  between points, as a sweep worker's child does), in one process, writing nothing;
- sweep: ``cosim sweep SPEC --out DIR --workers 2`` (the console script next to ``sys.executable``, else
  ``python -m cosim.cli.main``).

The pairs are interleaved (serial, sweep, serial, sweep, ...), so a shared machine's load hits both alike;
the ratio to trust is the median of the per-pair ratios. Targets (issue 16, 2 cores, idle machine): sweep
<= 0.8x serial and <= 2.5 s. The serial loop's objectives are compared with the sweep's table (they must
be equal to the last bit).

The breakdown runs the sweep once more inside a process that stamps the wall time at its stages (imports,
spec check, cluster start, first rows back, last rows, cluster close, merge, exit), and probes separately
what a worker child costs to start (spawn, imports, payload, first point) and what a Dask worker process
costs to import. To stamp them it imports the client's modules first, so it shows each stage's own cost,
not how much of it the command overlaps with the cluster's start.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from process_cpu import become_subreaper, reap_orphans

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_SPEC = ROOT / "examples" / "pick_and_place" / "spec_coarse.json"
TARGET_RATIO, TARGET_SECONDS = 0.8, 2.5


def env() -> dict[str, str]:
    """This checkout first on the path, for the processes started here and their Dask workers."""
    return dict(os.environ, PYTHONPATH=str(ROOT / "src") + os.pathsep + os.environ.get("PYTHONPATH", ""))


def cosim_command() -> list[str]:
    script = Path(sys.executable).with_name("cosim")
    return [str(script)] if script.exists() else [sys.executable, "-m", "cosim.cli.main"]


def load() -> str:
    return os.popen("uptime").read().strip()


# -- the serial loop (run as its own process) ------------------------------------------------------------


def serial(spec_path: str, out: str | None) -> None:
    """Every point of the spec's design space, one after the other, in this process."""
    from cosim import build_system, load_spec, run_point
    from cosim.spec.design import DesignSpace

    system = build_system(load_spec(spec_path))
    units = {name: su.unit_type.instantiate(name) for name, su in system.units.items()}
    objectives = {}
    for point in DesignSpace.from_spec(system.spec):
        result = run_point(system, point.values, units=units)
        if not result.ok:
            raise SystemExit(f"point {point.id} {result.status}: {result.message}")
        for unit in units.values():
            unit.reset()
        objectives[point.id] = result.objectives
    for unit in units.values():
        unit.terminate()
    if out:
        Path(out).write_text(json.dumps(objectives, default=lambda a: a.tolist() if hasattr(a, "tolist") else a))


CPU: list[float] = []  # CPU seconds of the last timed command and every process it started


def timed(command: list[str]) -> float:
    """Wall seconds of ``command``; its CPU seconds (with its children's) appended to CPU."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run(command, env=env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    elapsed = time.perf_counter() - started
    reap_orphans()  # any process the command left behind (process_cpu.py)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    CPU.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed ({done.returncode}):\n{done.stderr[-3000:]}")
    return elapsed


def same_results(serial_json: Path, table: Path) -> tuple[int, float]:
    """(points compared, largest absolute difference over every objective column)."""
    import numpy as np
    import pandas as pd

    df = pd.read_parquet(table).set_index("point_id")
    expected = json.loads(serial_json.read_text())
    worst = 0.0
    for pid, objectives in expected.items():
        for name, value in objectives.items():
            values = np.atleast_1d(np.asarray(value, dtype=float))
            got = [df.at[pid, name]] if values.size == 1 and name in df.columns else \
                [df.at[pid, f"{name}[{i}]"] for i in range(values.size)]
            diff = np.abs(np.asarray(got, dtype=float) - values)
            if np.any(np.isnan(diff) & ~(np.isnan(values))):
                return len(expected), float("inf")
            worst = max(worst, float(np.nanmax(diff)) if diff.size else 0.0)
    return len(expected), worst


# -- the breakdown --------------------------------------------------------------------------------------

TIMELINE = r'''
import functools, sys, time
T0 = time.perf_counter()
STAMPS = []

def mark(name):
    STAMPS.append((time.perf_counter() - T0, name))

def wrap(owner, attr, name):
    original = getattr(owner, attr)
    @functools.wraps(original)
    def stamped(*args, **kwargs):
        mark(name + " begins")
        try:
            return original(*args, **kwargs)
        finally:
            mark(name + " ends")
    setattr(owner, attr, stamped)

def main():
    import cosim.cli.main as cli
    mark("cli imported")
    import cosim.studies.sweep
    sweep = sys.modules["cosim.studies.sweep"]
    import distributed
    import cosim.results.store as results
    import cosim.system.validate as validate
    mark("sweep, results, distributed imported")
    wrap(validate, "check_spec", "spec check")
    wrap(distributed.LocalCluster, "__init__", "cluster start")
    wrap(distributed.LocalCluster, "close", "cluster close")
    wrap(results.ResultsStore, "compact", "merge into results.parquet")
    original_append, seen = results.ResultsStore.append, []
    def append(self, rows):
        if not seen:
            mark("first rows back")
        seen.append(len(rows))
        return original_append(self, rows)
    results.ResultsStore.append = append
    wrap(sweep.Sweep, "_evaluate", "points")
    original_evaluate = sweep.Sweep._evaluate
    def evaluate(self, *args, **kwargs):
        try:
            return original_evaluate(self, *args, **kwargs)
        finally:
            cpu_census()
    sweep.Sweep._evaluate = evaluate
    sys.argv = ["cosim", "sweep", *sys.argv[1:]]
    code = cli.main()  # as the console script calls it (the program's exit path)
    mark("command done")
    for t, name in STAMPS:
        print(f"{t:8.3f} s  {name}")
    for line in CENSUS:
        print(line)
    sys.stdout.flush()
    return code

CENSUS = []

def cpu_census():
    """CPU seconds of this process and of every process it started, once the last rows are back."""
    import psutil, resource
    me = resource.getrusage(resource.RUSAGE_SELF)
    CENSUS.append(f"cpu client (imports, spec check, scheduler and workers, results): {me.ru_utime + me.ru_stime:.2f} s")
    for proc in psutil.Process().children(recursive=True):
        try:
            line = " ".join(proc.cmdline())
            times = proc.cpu_times()
        except psutil.Error:
            continue
        if "child_main" in line:
            kind = "point child"
        elif "resource_tracker" in line:
            kind = "multiprocessing's resource tracker"
        else:
            kind = line[:60]
        CENSUS.append(f"cpu {kind} pid {proc.pid}: {times.user + times.system:.2f} s")

if __name__ == "__main__":
    sys.exit(main())
'''

CHILD_PROBE = r'''
import sys, time
from cosim.system.validate import check_spec
from cosim.parallel.isolation.payload import make_payload
from cosim.parallel.isolation.runner import IsolatedRunner
from cosim.spec.design import DesignSpace
system = check_spec(sys.argv[1])
payload = make_payload(system)
point = next(iter(DesignSpace.from_spec(system.spec)))
runner = IsolatedRunner(payload)
started = time.perf_counter()
row = runner.run([(point.id, point.values)])[0]
first = time.perf_counter() - started
started = time.perf_counter()
runner.run([(point.id, point.values)])
second = time.perf_counter() - started
runner.close()
print(f"{first:.3f} {second:.3f} {row.status}")
'''


SERIAL_PROBE = r'''
import sys, time
t0, c0 = time.perf_counter(), time.process_time()
from cosim import build_system, load_spec, run_point
from cosim.spec.design import DesignSpace
t1, c1 = time.perf_counter(), time.process_time()
system = build_system(load_spec(sys.argv[1]))
units = {name: su.unit_type.instantiate(name) for name, su in system.units.items()}
points = list(DesignSpace.from_spec(system.spec))
t2, c2 = time.perf_counter(), time.process_time()
for point in points:
    run_point(system, point.values, units=units)
    for unit in units.values():
        unit.reset()
t3, c3 = time.perf_counter(), time.process_time()
print(f"{t1 - t0:.3f} {c1 - c0:.3f} {t2 - t1:.3f} {c2 - c1:.3f} {t3 - t2:.3f} {c3 - c2:.3f} {len(points)}")
'''


def breakdown(spec: Path, folder: Path) -> None:
    script = folder / "timeline.py"
    script.write_text(TIMELINE)
    out = folder / "breakdown"
    shutil.rmtree(out, ignore_errors=True)
    started = time.perf_counter()
    done = subprocess.run([sys.executable, str(script), str(spec), "--out", str(out), "--workers", "2"],
                          env=env(), capture_output=True, text=True)
    total = time.perf_counter() - started
    if done.returncode != 0:
        raise SystemExit(done.stderr[-3000:])
    print("  stages of one `cosim sweep` (wall time since the interpreter started running the command):")
    for line in done.stdout.splitlines():
        if " s  " in line:
            print("    " + line)
    print("  CPU of each process once the last rows are back (before the cluster closes):")
    for line in done.stdout.splitlines():
        if line.startswith("cpu "):
            print("    " + line[4:])
    print(f"    {total:8.3f} s  process exited (as seen from outside, incl. interpreter start and exit)")
    probe = subprocess.run([sys.executable, "-c", CHILD_PROBE, str(spec)], env=env(), capture_output=True,
                           text=True, check=True).stdout.split()
    print(f"  a worker's child process: start + imports + payload + units + first point {float(probe[0]):.3f} s; "
          f"one more point {float(probe[1]):.3f} s")
    w = [float(x) for x in subprocess.run([sys.executable, "-c", SERIAL_PROBE, str(spec)], env=env(),
                                          capture_output=True, text=True, check=True).stdout.split()]
    print(f"  the serial loop in one process: imports {w[0]:.3f} s ({w[1]:.3f} s CPU), spec + system + units "
          f"{w[2]:.3f} s ({w[3]:.3f} s CPU), {int(w[6])} points {w[4]:.3f} s ({w[5]:.3f} s CPU, "
          f"{w[5] / w[6] * 1e3:.2f} ms a point)")
    for what in ("import distributed", "import cosim.parallel.isolation, cosim.execution.point",
                 "import cosim.studies.sweep, cosim.results.store, distributed"):
        seconds = min(timed([sys.executable, "-c", what]) for _ in range(3))
        print(f"  python -c '{what}': {seconds:.3f} s (best of 3, incl. interpreter start)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spec", default=str(DEFAULT_SPEC))
    parser.add_argument("--repeat", type=int, default=5, help="interleaved pairs (serial, sweep)")
    parser.add_argument("--no-breakdown", action="store_true")
    parser.add_argument("--serial", nargs="+", metavar=("SPEC", "OUT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.serial:
        serial(args.serial[0], args.serial[1] if len(args.serial) > 1 else None)
        return
    become_subreaper()
    from cosim.fmus.build import ensure_built

    ensure_built("motor_gear_energy", 3)  # the FMU is built before timing (the target says so)
    spec = Path(args.spec).resolve()
    print(f"machine: {os.cpu_count()} cores, {os.uname().machine}; {time.strftime('%Y-%m-%d %H:%M %Z')}")
    print(f"load before: {load()}")
    with tempfile.TemporaryDirectory(prefix="cosim_startup_") as tmp:
        folder = Path(tmp)
        serial_cmd = [sys.executable, __file__, "--serial", str(spec)]
        sweep_out = folder / "sweep"
        sweep_cmd = [*cosim_command(), "sweep", str(spec), "--out", str(sweep_out), "--workers", "2"]
        # warm-up (file cache, compiled bytecode), and the check that both give the same numbers
        timed([*serial_cmd, str(folder / "serial.json")])
        timed(sweep_cmd)
        n, worst = same_results(folder / "serial.json", sweep_out / "results.parquet")
        print(f"same results: {n} points, largest objective difference serial vs sweep {worst:g}")
        serial_s, sweep_s, serial_cpu, sweep_cpu = [], [], [], []
        for i in range(args.repeat):
            serial_s.append(timed(serial_cmd))
            serial_cpu.append(CPU[-1])
            shutil.rmtree(sweep_out, ignore_errors=True)
            sweep_s.append(timed(sweep_cmd))
            sweep_cpu.append(CPU[-1])
            print(f"  pair {i + 1}: serial {serial_s[-1]:.2f} s ({serial_cpu[-1]:.2f} s CPU), sweep {sweep_s[-1]:.2f} s "
                  f"({sweep_cpu[-1]:.2f} s CPU), ratio {sweep_s[-1] / serial_s[-1]:.2f}", flush=True)
        ratio = statistics.median(w / s for w, s in zip(sweep_s, serial_s))
        seconds = statistics.median(sweep_s)
        print(f"median: serial {statistics.median(serial_s):.2f} s, sweep {seconds:.2f} s; CPU serial "
              f"{statistics.median(serial_cpu):.2f} s, sweep {statistics.median(sweep_cpu):.2f} s (all its processes)")
        print(f"sweep / serial (median of pairs): {ratio:.2f}  target <= {TARGET_RATIO}: "
              f"{'met' if ratio <= TARGET_RATIO else 'NOT met'}")
        print(f"sweep, command to written table: {seconds:.2f} s  target <= {TARGET_SECONDS} s: "
              f"{'met' if seconds <= TARGET_SECONDS else 'NOT met'}")
        print(f"load after: {load()}")
        if not args.no_breakdown:
            print("breakdown:")
            breakdown(spec, folder)


if __name__ == "__main__":
    main()
