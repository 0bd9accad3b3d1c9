"""Sweep throughput, parallel efficiency, client memory, and cosim vs hand-written fmpy + dask.bag.

    python benchmarks/sweep_throughput.py            # all three parts (several minutes on 2 cores)
    python benchmarks/sweep_throughput.py --part efficiency|memory|bag|pickplace [--repeat 3]

1. efficiency: runs/s of ``cosim sweep`` of an FMU study (fmus/linear_ode, FMI 2.0, 10 000 steps a
   point) on a LocalCluster of 1 and of 2 worker processes; parallel efficiency = rate(2) / (2 rate(1)).
   Clusters are started and warmed up (worker child processes loaded) before timing.
2. memory: peak RSS growth of the sweep client for 10 000 and 100 000 points of a trivial Python unit
   (a gain, one step a point), each size in a fresh process; the final table is included.
3. bag: the same FMU and points through ``cosim sweep`` and through the pattern FMPy documents for
   parameter variation (dask.bag, one FMU2Slave per partition, reset() per point, the output read every
   step), on one 2-worker LocalCluster, alternating, in one run: ratio = rate(cosim) / rate(bag).
4. pickplace: runs/s of the pick-and-place coarse grid (273 points) at both robot fidelity levels
   (examples/pick_and_place/spec_coarse.json and spec_coarse_exudyn.json) on 1 and 2 workers.
5. kernel: designs/s of ``cosim sweep`` of a 2-FMU linear_ode ring (10^3 steps a point) on 2 workers with
   ``experiment.kernel`` python and native, alternating on one cluster (issue 35: >= 5x; the issue's 10^5 designs
   via ``--points``, or ``--native-points`` for one native-only sweep after the pairs), each written to disk as
   ``cosim sweep`` writes it, with the client's peak RSS growth.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

STOP, STEP = 1.0, 1e-4  # 10 000 communication steps a point


def ode_spec(folder: Path, n_points: int, fmu: str) -> Path:
    lo = -2.0
    step = 2.0 / n_points
    spec = {
        "name": "ode_bench", "units": {"ode": {"fmu": fmu}},
        "experiment": {"stop": STOP, "step": STEP},
        "objectives": {"y_end": {"signal": "ode.y", "reduce": "final"}},
        "design": {"parameters": {"ode.a": {"min": lo, "max": lo + step * (n_points - 1) + step / 2,
                                            "step": step}}},
    }
    path = folder / f"ode_{n_points}.json"
    path.write_text(json.dumps(spec))
    return path


def timed_sweep(spec: Path, address: str, out: Path) -> tuple[float, int]:
    from cosim.studies.sweep import Sweep

    shutil.rmtree(out, ignore_errors=True)
    sweep = Sweep(spec, scheduler=address, out=out, quiet=True)
    started = time.perf_counter()
    df = sweep.run()
    elapsed = time.perf_counter() - started
    assert (df["status"] == "ok").all(), df["message"].iloc[0]
    return elapsed, len(df)


def cluster(n: int):
    from distributed import LocalCluster

    return LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                        dashboard_address="127.0.0.1:0", silence_logs=40)


def part_efficiency(folder: Path, repeat: int, n_points: int) -> dict:
    spec = ode_spec(folder, n_points, "builtin:linear_ode_fmi2")
    # Warm up with the same spec: each worker then keeps its child process with
    # the loaded system (a one-off ~1 s per worker and spec), and the timed runs
    # measure the steady throughput a long sweep sees.
    warm = spec
    rates = {}
    for workers in (1, 2):
        with cluster(workers) as c:
            timed_sweep(warm, c.scheduler_address, folder / "warm")
            runs = []
            for _ in range(repeat):
                elapsed, n = timed_sweep(spec, c.scheduler_address, folder / f"eff{workers}")
                runs.append(n / elapsed)
        rates[workers] = runs
        print(f"  {workers} worker(s): {n_points} points, runs/s {', '.join(f'{r:.1f}' for r in runs)}", flush=True)
    med = {w: statistics.median(r) for w, r in rates.items()}
    efficiency = med[2] / (2 * med[1])
    print(f"  median runs/s: 1 worker {med[1]:.1f}, 2 workers {med[2]:.1f}; parallel efficiency {efficiency:.1%}")
    return {"runs_per_s": rates, "median": med, "efficiency": efficiency}


def trivial_spec(folder: Path, n: int) -> Path:
    """A spec of n points (g.k = 0 .. n-1) of the tests' Gain unit, one step each, written into ``folder``; its path."""
    spec = {
        "name": f"trivial_{n}",
        "units": {"g": {"python": f"{ROOT / 'tests' / 'helpers' / 'units_for_tests.py'}:Gain"}},
        "experiment": {"stop": 1.0, "step": 1.0},
        "objectives": {"y": {"signal": "g.y", "reduce": "final"}},
        "design": {"parameters": {"g.k": {"min": 0, "max": n - 1, "step": 1}}},
    }
    path = folder / f"trivial_{n}.json"
    path.write_text(json.dumps(spec))
    return path


def memory_child(spec: str, out: str) -> None:
    """Run one sweep here, sampling this process's RSS; print JSON with baseline and peak."""
    import psutil

    from cosim.studies.sweep import Sweep

    proc = psutil.Process()
    sweep = Sweep(spec, workers=2, out=out, quiet=True)
    baseline = proc.memory_info().rss
    peak = [baseline]
    stop = threading.Event()

    def sample() -> None:
        while not stop.is_set():
            peak[0] = max(peak[0], proc.memory_info().rss)
            time.sleep(0.05)

    thread = threading.Thread(target=sample, daemon=True)
    thread.start()
    started = time.perf_counter()
    counts = sweep.run_to_disk()  # as `cosim sweep` does: the table stays on disk
    elapsed = time.perf_counter() - started
    stop.set()
    thread.join()
    print(json.dumps({"points": sum(counts.values()), "ok": counts["ok"], "baseline_mb": baseline / 1e6,
                      "peak_mb": peak[0] / 1e6, "seconds": elapsed}))


def part_memory(folder: Path, sizes: list[int]) -> dict:
    results = {}
    for n in sizes:
        spec = trivial_spec(folder, n)
        out = folder / f"mem_{n}"
        shutil.rmtree(out, ignore_errors=True)
        text = subprocess.run([sys.executable, __file__, "--memory-child", str(spec), str(out)], check=True,
                              capture_output=True, text=True).stdout.strip().splitlines()[-1]
        r = json.loads(text)
        r["growth_mb"] = r["peak_mb"] - r["baseline_mb"]
        results[n] = r
        print(f"  {n} points ({r['ok']} ok) in {r['seconds']:.1f} s: client RSS {r['baseline_mb']:.0f} MB -> peak "
              f"{r['peak_mb']:.0f} MB (+{r['growth_mb']:.0f} MB)", flush=True)
    return results


def bag_partition(values: list[float], fmu_path: str) -> list[float]:
    """The FMPy parameter-variation pattern: one instance per partition, reset() per point."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(fmu_path)
    vrs = {v.name: v.valueReference for v in md.modelVariables}
    unzipdir = extract(fmu_path)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="instance")
    fmu.instantiate()
    out = []
    n_steps = round(STOP / STEP)
    try:
        for a in values:
            fmu.setupExperiment(startTime=0.0, stopTime=STOP)
            fmu.setReal([vrs["a"]], [a])
            fmu.enterInitializationMode()
            fmu.exitInitializationMode()
            y = fmu.getReal([vrs["y"]])[0]
            for k in range(n_steps):
                fmu.doStep(currentCommunicationPoint=k * STEP, communicationStepSize=STEP)
                y = fmu.getReal([vrs["y"]])[0]  # read every step, as a recording or a reduction must
            out.append(y)
            fmu.reset()
    finally:
        fmu.terminate()
        fmu.freeInstance()
        shutil.rmtree(unzipdir, ignore_errors=True)
    return out


def part_bag(folder: Path, repeat: int, n_points: int) -> dict:
    import dask.bag as db
    from distributed import Client

    from cosim.fmus.build import ensure_built
    from cosim.spec.design import DesignSpace
    from cosim.spec.loader import load_spec

    fmu = str(ensure_built("linear_ode", 2))
    spec = ode_spec(folder, n_points, fmu)
    values = [p.values["ode.a"] for p in DesignSpace.from_spec(load_spec(spec))]
    cosim_rates, bag_rates = [], []
    with cluster(2) as c, Client(c):
        timed_sweep(spec, c.scheduler_address, folder / "warm_bag")  # same spec: the workers keep its child
        db.from_sequence(values[:8], npartitions=2).map_partitions(bag_partition, fmu).compute()
        for _ in range(repeat):
            started = time.perf_counter()
            ys = db.from_sequence(values, npartitions=4).map_partitions(bag_partition, fmu).compute()
            bag_rates.append(len(ys) / (time.perf_counter() - started))
            elapsed, n = timed_sweep(spec, c.scheduler_address, folder / "bag_cosim")
            cosim_rates.append(n / elapsed)
            print(f"  bag {bag_rates[-1]:.1f} runs/s, cosim sweep {cosim_rates[-1]:.1f} runs/s, "
                  f"ratio {cosim_rates[-1] / bag_rates[-1]:.2f}", flush=True)
    ratio = statistics.median(c / b for c, b in zip(cosim_rates, bag_rates))
    print(f"  median ratio cosim / bag: {ratio:.2f}")
    return {"bag": bag_rates, "cosim": cosim_rates, "ratio": ratio}


def ring_spec(folder: Path, n_points: int, kernel: str) -> Path:
    """Two linear_ode FMUs in a feedback ring, 10^3 steps, ``n_points`` designs of one.a; ``kernel`` as asked."""
    fmu = "builtin:linear_ode_fmi2"
    spec = {
        "name": f"ring_{kernel}", "units": {"one": {"fmu": fmu}, "two": {"fmu": fmu, "parameters": {"a": -2.0}}},
        "connections": [{"from": "one.y", "to": "two.u"}, {"from": "two.y", "to": "one.u"}],
        "experiment": {"stop": 1.0, "step": 1e-3, "kernel": kernel},
        "objectives": {"y_end": {"signal": "one.y", "reduce": "final"},
                       "y_int": {"signal": "two.y", "reduce": "integral"}},
        "design": {"parameters": {"one.a": {"min": -3.0, "max": -1.0}},
                   "method": "lhs", "samples": n_points, "seed": 1},
    }
    path = folder / f"ring_{kernel}_{n_points}.json"
    path.write_text(json.dumps(spec))
    return path


def sweep_to_disk(spec: Path, address: str, out: Path, curve: list | None = None) -> tuple[float, int, float, float]:
    """(seconds, rows, client RSS before in MB, client RSS peak in MB) of one sweep written to disk as
    ``cosim sweep`` writes it (the table stays on disk), the client's RSS sampled every 50 ms; ``curve`` (if
    given) gets the (seconds since the start, RSS in MB) samples."""
    import psutil

    from cosim.studies.sweep import Sweep

    shutil.rmtree(out, ignore_errors=True)
    proc = psutil.Process()
    sweep = Sweep(spec, scheduler=address, out=out, quiet=True)
    baseline = proc.memory_info().rss
    peak = [baseline]
    stop = threading.Event()

    started = time.perf_counter()

    def sample() -> None:
        while not stop.is_set():
            rss = proc.memory_info().rss
            peak[0] = max(peak[0], rss)
            if curve is not None:
                curve.append((time.perf_counter() - started, rss / 1e6))
            time.sleep(0.05)

    thread = threading.Thread(target=sample, daemon=True)
    thread.start()
    counts = sweep.run_to_disk()
    elapsed = time.perf_counter() - started
    stop.set()
    thread.join()
    assert counts.get("ok", 0) == sum(counts.values()), counts
    return elapsed, sum(counts.values()), baseline / 1e6, peak[0] / 1e6


def part_kernel(folder: Path, repeat: int, n_points: int, native_points: int = 0) -> dict:
    """Interleaved python/native pairs of ``n_points`` designs, then (``native_points`` > 0) one native sweep of
    that many designs alone: designs/s, the ratio per pair, and the client's RSS growth during each sweep."""
    rates: dict[str, list[float]] = {"python": [], "native": []}
    specs = {k: ring_spec(folder, n_points, k) for k in rates}
    out: dict = {"rates": rates}
    with cluster(2) as c:
        for kernel, spec in specs.items():  # warm up: worker children loaded, kernel compiled
            timed_sweep(ring_spec(folder, 8, kernel), c.scheduler_address, folder / f"warm_{kernel}")
        for _ in range(repeat):
            for kernel, spec in specs.items():
                load = os.getloadavg()[0]
                elapsed, n, before, peak = sweep_to_disk(spec, c.scheduler_address, folder / f"k_{kernel}")
                rates[kernel].append(n / elapsed)
                print(f"  {kernel}: {n} designs in {elapsed:.1f} s, {n / elapsed:.0f} designs/s; client RSS "
                      f"{before:.0f} -> peak {peak:.0f} MB (+{peak - before:.0f}); load {load:.1f}", flush=True)
        if native_points:
            big = ring_spec(folder, native_points, "native")
            load = os.getloadavg()[0]
            curve: list[tuple[float, float]] = []
            elapsed, n, before, peak = sweep_to_disk(big, c.scheduler_address, folder / "k_big", curve)
            print(f"  native alone: {n} designs in {elapsed:.1f} s, {n / elapsed:.0f} designs/s; client RSS "
                  f"{before:.0f} -> peak {peak:.0f} MB (+{peak - before:.0f}); load {load:.1f}", flush=True)
            at = {f: max((rss for t, rss in curve if t <= f * elapsed), default=before) for f in (0.2, 0.5, 0.8, 1.0)}
            print("  client RSS (highest so far) at " + ", ".join(f"{f:.0%} of the time: {rss:.0f} MB"
                                                                 for f, rss in at.items()), flush=True)
            out["native_alone"] = {"designs": n, "seconds": elapsed, "rss_growth_mb": peak - before}
    if repeat:
        ratio = statistics.median(b / a for a, b in zip(rates["python"], rates["native"]))
        print(f"  native / python designs per second: {ratio:.1f}x (median of {repeat} interleaved pairs)")
        out["ratio"] = ratio
    return out


def part_pickplace(repeat: int) -> dict:
    specs = {"inverse dynamics": ROOT / "examples" / "pick_and_place" / "spec_coarse.json",
             "Exudyn": ROOT / "examples" / "pick_and_place" / "spec_coarse_exudyn.json"}
    out = {}
    with tempfile.TemporaryDirectory(prefix="cosim_pp_") as tmp:
        for level, spec in specs.items():
            rates = {}
            for workers in (1, 2):
                with cluster(workers) as c:
                    timed_sweep(spec, c.scheduler_address, Path(tmp) / "warm")  # workers keep the loaded system
                    runs = [timed_sweep(spec, c.scheduler_address, Path(tmp) / "run") for _ in range(repeat)]
                rates[workers] = statistics.median(n / seconds for seconds, n in runs)
            efficiency = rates[2] / (2 * rates[1])
            print(f"  {level}: 273 points, runs/s 1 worker {rates[1]:.1f}, 2 workers {rates[2]:.1f}; "
                  f"parallel efficiency {efficiency:.1%}; 17061 points would take "
                  f"{17061 / rates[2] / 60:.1f} min on 2 workers", flush=True)
            out[level] = rates
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--part", choices=["efficiency", "memory", "bag", "pickplace", "kernel", "all"], default="all")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--points", type=int, default=200, help="FMU points for efficiency and bag")
    parser.add_argument("--sizes", default="10000,100000", help="point counts for the memory part")
    parser.add_argument("--native-points", type=int, default=0,
                        help="kernel part: one more native-only sweep of this many designs (the issue's 10^5)")
    parser.add_argument("--memory-child", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.memory_child:
        memory_child(*args.memory_child)
        return
    print(f"machine: {os.cpu_count()} cores; {time.strftime('%Y-%m-%d')}")
    with tempfile.TemporaryDirectory(prefix="cosim_bench_") as tmp:
        folder = Path(tmp)
        if args.part in ("efficiency", "all"):
            print("efficiency:")
            part_efficiency(folder, args.repeat, args.points)
        if args.part in ("memory", "all"):
            print("client memory:")
            part_memory(folder, [int(s) for s in args.sizes.split(",")])
        if args.part in ("bag", "all"):
            print("cosim sweep vs fmpy + dask.bag:")
            part_bag(folder, args.repeat, args.points)
        if args.part in ("pickplace", "all"):
            print("pick-and-place coarse grid:")
            part_pickplace(args.repeat)
        if args.part in ("kernel", "all"):
            print(f"native kernel vs python master, 2-FMU ring, 10^3 steps, 2 workers, load {os.getloadavg()[0]:.1f}:")
            part_kernel(folder, args.repeat, args.points, args.native_points)


if __name__ == "__main__":
    main()
