"""Client memory and time per point of `cosim sweep` over many trivial points.

    python benchmarks/sweep_memory.py                         # 10 000, 100 000 and 1 000 000 points
    python benchmarks/sweep_memory.py --sizes 10000,100000    # quicker

Each size runs in a fresh process, the way ``cosim sweep`` runs (``Sweep.run_to_disk``: the table stays
on disk; default local cluster of 2 workers, which with its Dask scheduler lives in the client process).
The unit is a gain (tests/helpers/units_for_tests.py:Gain) with one step a point, so a point's time is nearly all
overhead: design point, Dask task share, child process, row, part file, merge. A thread samples the
client's resident memory (RSS) every 20 ms, separately while the points run and during the final merge
into results.parquet.

Targets (issue 16): the client's memory stays flat during the sweep (here: its RSS while the largest size
runs, sampled every second against the points stored, within 25 MB from 20 % to 100 % of the points; the peak
growth over the baseline of every size, while running, while the cluster closes and during the final merge, is
printed too), and the overhead per point <= 1 ms: the marginal wall time per point between the smallest and
the largest size, on 2 workers (so 2 points are in progress at once). Under load the wall time says little, so the CPU time
of the whole sweep (client with its workers, their child processes: ``getrusage(RUSAGE_CHILDREN)``, orphans
reaped too: process_cpu.py) is printed
too, and its marginal cost per point.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from process_cpu import become_subreaper, reap_orphans
from sweep_throughput import trivial_spec

ROOT = Path(__file__).resolve().parent.parent
FLAT_MB, TARGET_MS = 25.0, 1.0
CURVE_SECONDS = 1.0  # the client's RSS is recorded this often with the number of rows stored so far


def measure(spec: str, out: str) -> None:
    """One sweep in this process; prints JSON: baseline, peaks while running and while merging, seconds."""
    import psutil

    sys.path.insert(0, str(ROOT))
    from cosim.results import store as results
    from cosim.studies.sweep import Sweep

    proc = psutil.Process()
    sweep = Sweep(spec, workers=2, out=out, quiet=True)
    stage = ["run"]
    peaks = {"run": 0, "close": 0, "merge": 0}
    stop = threading.Event()

    def sample() -> None:
        next_point = 0.0
        while not stop.is_set():
            rss = proc.memory_info().rss
            peaks[stage[0]] = max(peaks[stage[0]], rss)
            now = time.perf_counter() - started
            if now >= next_point:
                curve.append((now, rows_done[0], rss / 1e6, stage[0]))
                next_point += CURVE_SECONDS
            time.sleep(0.02)

    original_compact = results.ResultsStore.compact
    original_append = results.ResultsStore.append
    merge_started = []
    rows_done = [0]
    curve: list[tuple[float, int, float, str]] = []  # (seconds, rows stored, client RSS MB, stage) every CURVE_SECONDS

    def append(self, rows):
        rows_done[0] += len(rows)
        return original_append(self, rows)

    def compact(self, *args, **kwargs):
        stage[0] = "merge"
        merge_started.append(time.perf_counter())
        return original_compact(self, *args, **kwargs)

    results.ResultsStore.compact = compact
    results.ResultsStore.append = append
    original_evaluate = Sweep._evaluate

    def evaluate(self, *args, **kwargs):
        try:
            return original_evaluate(self, *args, **kwargs)
        finally:
            stage[0] = "close"  # every row is back: the cluster closes next

    Sweep._evaluate = evaluate
    baseline = proc.memory_info().rss
    started = time.perf_counter()
    thread = threading.Thread(target=sample, daemon=True)
    thread.start()
    counts = sweep.run_to_disk()
    ended = time.perf_counter()
    stop.set()
    thread.join()
    not_ok = []
    if counts["ok"] < sum(counts.values()):
        from cosim.cli.sweep import first_not_ok

        not_ok = [f"{row['status']}: {row['message']}"[:300] for row in first_not_ok(sweep.store.table_path, 3)]
    print(json.dumps({"points": sum(counts.values()), "ok": counts["ok"], "counts": counts, "not_ok": not_ok, "baseline_mb": baseline / 1e6,
                      "run_peak_mb": peaks["run"] / 1e6, "close_peak_mb": peaks["close"] / 1e6,
                      "merge_peak_mb": peaks["merge"] / 1e6,
                      "seconds": ended - started, "merge_seconds": ended - merge_started[0], "curve": curve}))


def rss_by_share(curve: list[list[Any]], n: int) -> list[tuple[int, float]]:
    """The client's RSS while the points run, when 10 %, 20 %, ... 100 % of the ``n`` points were stored
    (the first sample at or after; 100 %: the last sample before the cluster closes)."""
    running = [(rows, rss) for _, rows, rss, stage in curve if stage == "run"]
    out = []
    for share in range(10, 101, 10):
        later = [rss for rows, rss in running if rows >= n * share / 100] or \
            ([running[-1][1]] if share == 100 and running else [])
        if later:
            out.append((share, later[0]))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", default="10000,100000,1000000")
    parser.add_argument("--measure", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.measure:
        measure(*args.measure)
        return
    sizes = sorted(int(s) for s in args.sizes.split(","))
    become_subreaper()
    print(f"machine: {os.cpu_count()} cores, {os.uname().machine}; {time.strftime('%Y-%m-%d %H:%M %Z')}")
    print(f"load before: {os.popen('uptime').read().strip()}")
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    results = {}
    with tempfile.TemporaryDirectory(prefix="cosim_memory_") as tmp:
        folder = Path(tmp)
        for n in sizes:
            spec, out = trivial_spec(folder, n), folder / f"out_{n}"
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            done = subprocess.run([sys.executable, __file__, "--measure", str(spec), str(out)], env=env,
                                  capture_output=True, text=True)
            reap_orphans()  # the fork server, with the workers' and their children's CPU time
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            if done.returncode != 0:
                raise SystemExit(done.stderr[-3000:])
            r = json.loads(done.stdout.strip().splitlines()[-1])
            r["growth_mb"] = max(r["run_peak_mb"], r["close_peak_mb"], r["merge_peak_mb"]) - r["baseline_mb"]
            r["cpu_seconds"] = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
            results[n] = r
            shutil.rmtree(out, ignore_errors=True)
            print(f"  {n:>8} points ({r['ok']} ok) in {r['seconds']:7.1f} s (merge {r['merge_seconds']:.1f} s): "
                  f"client RSS {r['baseline_mb']:.0f} MB, peak while running {r['run_peak_mb']:.0f} MB, "
                  f"while the cluster closes {r['close_peak_mb']:.0f} MB, "
                  f"while merging {r['merge_peak_mb']:.0f} MB (growth +{r['growth_mb']:.0f} MB); "
                  f"CPU {r['cpu_seconds']:.1f} s", flush=True)
            for line in r["not_ok"]:
                print(f"    not ok ({r['counts']}): {line}")
            print("    RSS while running (share of points stored: MB): " + ", ".join(
                f"{share}%: {rss:.0f}" for share, rss in rss_by_share(r["curve"], n)), flush=True)
    small, large = sizes[0], sizes[-1]
    shares = dict(rss_by_share(results[large]["curve"], large))
    if 20 in shares and 100 in shares:
        drift = shares[100] - shares[20]
        print(f"client RSS while the {large} points ran: {shares[20]:.0f} MB at 20 %, {shares[100]:.0f} MB at 100 % "
              f"({drift:+.0f} MB)  target flat (within {FLAT_MB:g} MB): {'met' if drift <= FLAT_MB else 'NOT met'}")
    spread = results[large]["growth_mb"] - results[small]["growth_mb"]
    print(f"peak growth over the baseline, {large} vs {small} points: {spread:+.0f} MB (larger tasks, up to "
          f"2048 points, and the final merge of more part files raise the high-water mark once)")
    if large > small:
        per_point = (results[large]["seconds"] - results[small]["seconds"]) / (large - small) * 1e3
        print(f"marginal wall time per point, 2 workers: {per_point:.3f} ms  target <= {TARGET_MS:g} ms: "
              f"{'met' if per_point <= TARGET_MS else 'NOT met'}")
        cpu = (results[large]["cpu_seconds"] - results[small]["cpu_seconds"]) / (large - small) * 1e3
        print(f"marginal CPU time per point (all processes): {cpu:.3f} ms (on 2 cores, wall >= half of it)")
    print(f"load after: {os.popen('uptime').read().strip()}")


if __name__ == "__main__":
    main()
