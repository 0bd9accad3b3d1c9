"""Times of the analysis steps the tests once asserted with wall-clock limits (now measured here instead).

- ``len()`` of a 100 000-point grid (computed from the axes, never enumerated);
- the Pareto mask of 200 000 random points in 2 objectives and of 17 061 points in 3;
- drawing and saving a 17 061-point cloud (two scatter artists) to PNG.

Prints the median of ``--repeat`` runs of each, with the machine's load.
Usage: python benchmarks/analysis_speed.py [--repeat R]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.test_analysis_table import make_sweep_table  # noqa: E402

from cosim.analysis.pareto import pareto_mask  # noqa: E402
from cosim.analysis.plots import new_figure, save, scatter_cloud  # noqa: E402
from cosim.analysis.table import load_results  # noqa: E402
from cosim.spec.design import DesignSpace  # noqa: E402
from cosim.spec.loader import spec_from_dict  # noqa: E402


def median_time(action, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        action()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    repeat = parser.parse_args().repeat

    spec = spec_from_dict({"units": {"ode": {"fmu": "builtin:linear_ode_fmi2"}}, "experiment": {"stop": 1, "step": 0.1},
                           "design": {"parameters": {"ode.a": {"min": 0, "max": 999, "step": 1},
                                                     "ode.x0": {"min": 0, "max": 99, "step": 1}}}})
    grid_len = median_time(lambda: len(DesignSpace.from_spec(spec)), repeat)
    rng = np.random.default_rng(0)
    v2, v3 = rng.random((200_000, 2)), rng.random((17_061, 3))
    pareto2 = median_time(lambda: pareto_mask(v2), repeat)
    pareto3 = median_time(lambda: pareto_mask(v3), repeat)
    with tempfile.TemporaryDirectory() as folder:
        table = load_results(make_sweep_table(Path(folder) / "big", n2=121, n4=141, failed=0))

        def draw() -> None:
            fig = new_figure()
            scatter_cloud(fig, table, "traj.q_via[2]", "traj.q_via[4]", color="energy",
                          active=table.where("energy < 60"))
            save(fig, Path(folder) / "big.png")

        cloud = median_time(draw, repeat)
    print(f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
          f"load average {os.getloadavg()[0]:.1f}, median of {repeat}")
    print(f"len() of a 100 000-point grid (incl. building it)  {grid_len * 1e3:8.2f} ms")
    print(f"Pareto mask, 200 000 points x 2 objectives      {pareto2 * 1e3:8.1f} ms")
    print(f"Pareto mask, 17 061 points x 3 objectives       {pareto3 * 1e3:8.1f} ms")
    print(f"17 061-point cloud drawn and saved as PNG        {cloud * 1e3:8.1f} ms")


if __name__ == "__main__":
    main()
