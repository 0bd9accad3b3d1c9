"""Cost per point of the worker's child process channel (cosim.parallel.isolation), one code tree against another.

    python benchmarks/isolation_overhead.py --against /path/to/other/checkout [--points 2000] [--repeat 5]

A trivial Python unit (one output, one communication step a point) is run through ``IsolatedRunner.run``
in batches of 100 points: what is timed is the parent <-> child round trip per point (send, the child's
run of one step, the row back, the parent's read), which is where the reader thread with deadlines, the
child's memory checks and the recycling checks of issue 18 cost something.  Each repetition runs this
tree and the other one alternately, each in a fresh interpreter with PYTHONPATH set to that tree; the
figures are the median and the fastest run in µs per point (on a loaded machine the fastest run is the
closest to the cost itself), and the ratio is taken within the same repetition.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

UNIT = '''
from cosim import PythonUnit, Variable

class Gain(PythonUnit):
    variables = (Variable("k", "parameter", start=1.0), Variable("y", "output", start=0.0))

    def do_step(self, t, h):
        self.y = 2.0 * self.k
'''

MEASURE = '''
import json, sys, time
from cosim.parallel.isolation.payload import make_payload
from cosim.parallel.isolation.runner import IsolatedRunner
from cosim.system.validate import check_spec

spec, points = sys.argv[1], int(sys.argv[2])
runner = IsolatedRunner(make_payload(check_spec(spec)))
batch = [(f"p{i}", {"g.k": float(i)}) for i in range(100)]
runner.run(batch, 60.0)  # start the child and warm up
started = time.perf_counter()
for _ in range(points // 100):
    rows = runner.run(batch, 60.0)
    assert all(r.status == "ok" for r in rows), rows[0]
elapsed = time.perf_counter() - started
runner.close()
print(json.dumps(elapsed / (points // 100 * 100) * 1e6))
'''


def measure(tree: Path, spec: Path, points: int) -> float:
    env = dict(os.environ, PYTHONPATH=str(tree))
    done = subprocess.run([sys.executable, "-c", MEASURE, str(spec), str(points)], env=env, capture_output=True,
                          text=True, check=True, cwd=spec.parent)
    return float(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", required=True, help="another checkout of cosim (its root folder)")
    parser.add_argument("--points", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        (Path(folder) / "gain.py").write_text(UNIT)
        spec = Path(folder) / "spec.json"
        spec.write_text(json.dumps({"units": {"g": {"python": "gain.py:Gain"}},
                                    "experiment": {"stop": 0.1, "step": 0.1},
                                    "objectives": {"y": {"signal": "g.y", "reduce": "final"}}}))
        trees = {"this": ROOT, "other": Path(args.against).resolve()}
        times: dict[str, list[float]] = {name: [] for name in trees}
        for _ in range(args.repeat):
            for name, tree in trees.items():
                times[name].append(measure(tree, spec, args.points))
        ratios = [a / b for a, b in zip(times["this"], times["other"])]
    for name, tree in trees.items():
        print(f"{name} ({tree}): median {statistics.median(times[name]):.0f}, fastest {min(times[name]):.0f} "
              f"µs per point "
              f"(runs: {', '.join(f'{t:.0f}' for t in times[name])})")
    print(f"this / other: median {statistics.median(ratios):.3f} (per-run ratios: "
          f"{', '.join(f'{r:.3f}' for r in ratios)})")


if __name__ == "__main__":
    main()
