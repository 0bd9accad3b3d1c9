"""Lock-step groups of one spec's design points, this tree against another, interleaved.

    python benchmarks/lockstep_group.py --against /tmp/old/src            # 5 pairs, every master algorithm
    python benchmarks/lockstep_group.py --against /tmp/old/src --pairs 9 --group 32 --spec SPEC

Each side is a process of its own (``python benchmarks/lockstep_group.py --child``) run with ``PYTHONPATH``
set to a ``src`` folder: this tree's, or the one given by ``--against`` (e.g. an older commit extracted with
``git archive REV src | tar -x -C /tmp/old``). A child builds the system of ``--spec`` (the pick-and-place
coarse spec by default) under one master algorithm, instantiates its batches once
(:func:`cosim.execution.lockstep.instantiate`) and runs the design space's points in groups of ``--group``
through :func:`~cosim.execution.lockstep.run_lockstep`, resetting the batches between groups as a sweep
child's :class:`~cosim.execution.lockstep.LockstepRunner` does. It reports the wall time of the groups
and their CPU time (instantiation and spec loading excluded) and every point's objectives.

The sides run alternately (this tree, the other, this tree, ...) so a shared machine's load hits both alike;
the figure to trust is the median of the per-pair ratios (of CPU time: on a loaded machine the wall time
mostly measures the wait for a core). Both sides' objectives must be equal bit for bit.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_SPEC = ROOT / "examples" / "pick_and_place" / "spec_coarse.json"
ALGORITHMS = ("gauss-seidel", "jacobi", "jacobi-delayed")


def child(spec_path: str, algorithm: str, group: int) -> None:
    """Run every design point in lock-step groups; print {"seconds": ..., "objectives": {...}} as JSON."""
    from cosim import build_system, load_spec
    from cosim.execution.lockstep import instantiate, run_lockstep
    from cosim.execution.point import assignments_for
    from cosim.spec.design import DesignSpace

    raw = json.loads(Path(spec_path).read_text())
    raw["experiment"]["algorithm"] = algorithm
    copy = Path(spec_path).with_name(f".lockstep_group_{os.getpid()}.json")  # beside it: relative paths hold
    copy.write_text(json.dumps(raw))
    try:
        system = build_system(load_spec(copy))
    finally:
        copy.unlink()
    points = list(DesignSpace.from_spec(system.spec))
    batches = instantiate(system, group)
    objectives: dict[str, dict] = {}
    seconds = cpu = 0.0
    try:
        for first in range(0, len(points) - group + 1, group):  # whole groups only: one batch size
            chunk = points[first:first + group]
            overrides = [assignments_for(system, p.values) for p in chunk]
            started, started_cpu = time.perf_counter(), time.process_time()
            results = run_lockstep(system, overrides, batches)
            seconds += time.perf_counter() - started
            cpu += time.process_time() - started_cpu
            for point, result in zip(chunk, results):
                if not result.ok:
                    raise SystemExit(f"point {point.id} {result.status}: {result.message}")
                objectives[point.id] = {k: float(v).hex() for k, v in result.objectives.items()}
            for batch in batches.values():
                batch.reset()
    finally:
        for batch in batches.values():
            batch.terminate()
    print(json.dumps({"seconds": seconds, "cpu": cpu, "points": len(objectives), "objectives": objectives}))


def run_side(src: Path, spec: str, algorithm: str, group: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src))
    done = subprocess.run([sys.executable, __file__, "--child", "--spec", spec, "--algorithm", algorithm,
                           "--group", str(group)], env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"child with PYTHONPATH={src} failed ({done.returncode}):\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--against", type=Path, help="the other tree's src folder")
    parser.add_argument("--spec", default=str(DEFAULT_SPEC))
    parser.add_argument("--pairs", type=int, default=5)
    parser.add_argument("--group", type=int, default=32)
    parser.add_argument("--algorithm", action="append", choices=ALGORITHMS,
                        help="master algorithm(s) to time (default: all)")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.spec, (args.algorithm or ["gauss-seidel"])[0], args.group)
        return
    if args.against is None:
        parser.error("--against SRC is required (the other tree's src folder)")
    here = ROOT / "src"
    print(f"{os.popen('uptime').read().strip()}; this tree {here} against {args.against}")
    for algorithm in args.algorithm or ALGORITHMS:
        ratios, mine, theirs, cpu_ratios = [], [], [], []
        for _ in range(args.pairs):
            a = run_side(here, args.spec, algorithm, args.group)
            b = run_side(args.against, args.spec, algorithm, args.group)
            if a["objectives"] != b["objectives"]:
                differ = [p for p in a["objectives"] if a["objectives"][p] != b["objectives"].get(p)]
                raise SystemExit(f"{algorithm}: objectives differ at {len(differ)} points, e.g. {differ[:3]}")
            mine.append(a["seconds"])
            theirs.append(b["seconds"])
            ratios.append(a["seconds"] / b["seconds"])
            cpu_ratios.append(a["cpu"] / b["cpu"])
        print(f"{algorithm}: {a['points']} points in groups of {args.group}, objectives equal bit for bit; "
              f"groups' time this tree median {statistics.median(mine):.3f} s, "
              f"other {statistics.median(theirs):.3f} s, "
              f"median wall ratio {statistics.median(ratios):.3f}, CPU ratio {statistics.median(cpu_ratios):.3f} "
              f"(CPU pairs: {', '.join(f'{r:.3f}' for r in cpu_ratios)})")


if __name__ == "__main__":
    main()
