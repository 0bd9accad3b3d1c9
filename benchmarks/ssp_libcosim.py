"""cosim against libcosim (libcosimpy from PyPI) on the same exported SSP: values and time per run.

    python benchmarks/ssp_libcosim.py [--stop 100] [--step 0.01] [--repeat 5]

The system is the ring of three FMI 2.0 ``linear_ode`` FMUs of
tests/export/test_ssp_libcosim.py (one connection with a LinearTransformation; here
with c.a = -0.3 and b.b = -0.2 so that long runs stay bounded),
exported by ``cosim export`` and run

* by cosim: ``Execution(system).run()`` on the system read from the archive
  once (instantiate, initialize, step with Jacobi, reduce, terminate), and
  the same including reading the SSP (``check_spec``) every time;
* by libcosim: ``CosimExecution.from_ssp_file`` (reads the SSD, loads the
  FMUs) and ``simulate_until(stop)`` with its fixed-step algorithm.

It prints the largest difference of the final outputs and, per engine, the
median wall-clock and CPU time per run (CPU time of every thread of the
process: libcosim steps its units on a thread pool) and their ratios to
libcosim.  Wall-clock figures need a quiet machine; CPU time suffers less
from other processes.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--stop", type=float, default=100.0)
    parser.add_argument("--step", type=float, default=0.01)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()

    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    from tests.test_ssp_libcosim import RING

    from cosim.execution.run import Execution
    from cosim.export.ssp import export_ssp
    from cosim.system.validate import check_spec

    log_output_level(CosimLogLevel.ERROR)
    scratch = Path(tempfile.mkdtemp(prefix="cosim_bench_ssp_"))
    units = json.loads(json.dumps(RING["units"]))
    units["c"]["parameters"]["a"] = -0.3  # a ring that stays bounded over long runs
    units["b"]["parameters"]["b"] = -0.2
    spec = {**RING, "units": units, "experiment": {"stop": args.stop, "step": args.step, "algorithm": "jacobi"},
            "objectives": {n: {"signal": f"{n}.y", "reduce": "final"} for n in "abc"}}
    (scratch / "ring.json").write_text(json.dumps(spec))
    archive = export_ssp(check_spec(scratch / "ring.json"), scratch / "ring.ssp")
    with zipfile.ZipFile(archive) as zf:
        zf.extractall(scratch / "unpacked")
    companion = scratch / "ring.spec.json"  # written by export_ssp: the objectives on top of the SSP
    system = check_spec(companion)

    def cosim_run():
        return Execution(system).run()

    def cosim_with_reading():
        return Execution(check_spec(companion)).run()

    def libcosim_run():
        execution = CosimExecution.from_ssp_file(str(scratch / "unpacked"), step_size=round(args.step * 1e9))
        observer = CosimObserver.create_last_value()
        execution.add_observer(observer)
        execution.simulate_until(round(args.stop * 1e9))
        index = {s.name.decode(): s.index for s in execution.slave_infos()}
        return [observer.last_real_values(index[n], [5])[0] for n in "abc"]  # y is value reference 5

    names = ("cosim", "cosim incl. reading the SSP", "libcosim")
    timings: dict[str, list[float]] = {name: [] for name in names}
    cpu: dict[str, list[float]] = {name: [] for name in names}
    results = {}
    for _ in range(args.repeat):
        for name, fn in zip(names, (cosim_run, cosim_with_reading, libcosim_run)):
            started, started_cpu = time.perf_counter(), time.process_time()
            results[name] = fn()
            timings[name].append(time.perf_counter() - started)
            cpu[name].append(time.process_time() - started_cpu)  # all threads of this process
    ours = [results["cosim"].objectives[n] for n in "abc"]
    theirs = results["libcosim"]
    n_steps = round(args.stop / args.step)
    print(f"ring of 3 FMI 2.0 linear_ode FMUs, {n_steps} steps of {args.step} s, {args.repeat} runs each")
    print(f"final outputs cosim {ours}\n              libcosim {theirs}")
    print(f"largest difference: {max(abs(a - b) for a, b in zip(ours, theirs)):.3g} "
          f"(relative {max(abs(a - b) / max(abs(a), 1e-300) for a, b in zip(ours, theirs)):.3g})")
    base = statistics.median(timings["libcosim"])
    base_cpu = statistics.median(cpu["libcosim"])
    for name in names:
        median, median_cpu = statistics.median(timings[name]), statistics.median(cpu[name])
        print(f"{name:28s} wall {median * 1e3:7.1f} ms per run ({median / n_steps / 3 * 1e6:5.2f} µs per unit "
              f"per step, {median / base:4.2f} x libcosim); CPU {median_cpu * 1e3:7.1f} ms "
              f"({median_cpu / base_cpu:4.2f} x libcosim)")
    wall_ratio = statistics.median(a / b for a, b in zip(timings["cosim"], timings["libcosim"]))
    cpu_ratio = statistics.median(a / b for a, b in zip(cpu["cosim"], cpu["libcosim"]))
    load = os.getloadavg()
    print(f"load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}, {time.strftime('%Y-%m-%d %H:%M %Z')}; target: cosim "
          f"costs less than libcosim per run: wall {wall_ratio:.2f}x ({'met' if wall_ratio < 1 else 'NOT met'}), "
          f"CPU {cpu_ratio:.2f}x ({'met' if cpu_ratio < 1 else 'NOT met'}) (medians of per-round ratios)")


if __name__ == "__main__":
    main()
