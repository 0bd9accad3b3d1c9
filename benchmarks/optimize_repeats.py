"""TPE on a discrete space whose optimum it finds early (issue 28, item 14): evaluations, proposals, the
sampler's time per proposal and the wall time, with the objectives answered from their formula (no Dask), so
what is measured is the optimiser's own cost.

    PYTHONPATH=src python benchmarks/optimize_repeats.py [BUDGET]
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from tests.helpers.tools import python_unit  # noqa: E402

from cosim.studies.optimize import Optimization  # noqa: E402


class Formula:
    """TwoBowls' objectives from its formula: f1 = x^2 + y^2, f2 = (x - 2)^2 + y^2."""

    def evaluate(self, points):
        return [{"point_id": pid, "status": "ok", "objectives": {
            "f1": v["b.x"] ** 2 + v["b.y"] ** 2, "f2": (v["b.x"] - 2) ** 2 + v["b.y"] ** 2}} for pid, v in points]


def main(budget: int) -> None:
    folder = Path(tempfile.mkdtemp(prefix="cosim_repeats_"))
    try:
        spec = {"name": "bowls", "units": {"b": {"python": python_unit("TwoBowls")}},
                "experiment": {"stop": 1.0, "step": 1.0},
                "objectives": {"f1": {"signal": "b.f1", "reduce": "final", "sense": "minimize"},
                               "f2": {"signal": "b.f2", "reduce": "final", "sense": "minimize"}},
                "design": {"parameters": {"b.x": {"min": -1.0, "max": 3.0, "step": 0.5},
                                          "b.y": {"min": -2.0, "max": 2.0, "step": 0.5}}},
                "optimize": {"budget": budget, "batch": 8, "seed": 3}}
        (folder / "spec.json").write_text(json.dumps(spec))
        run = Optimization(folder / "spec.json", folder / "out", quiet=True)
        started = time.perf_counter()
        run.run(evaluator=Formula())
        wall = time.perf_counter() - started
        df = run.store.table()
        print(f"81 designs, budget {budget}: {len(df)} evaluations ({(df['sampler'] == 'tpe').sum()} tpe, "
              f"{(df['sampler'] == 'random').sum()} random), {run.trials_asked} proposals, sampler "
              f"{run.sampler_seconds:.2f} s ({run.sampler_seconds / run.trials_asked * 1e3:.1f} ms per proposal), "
              f"wall {wall:.1f} s; {run.stop_reason}")
    finally:
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 400)
