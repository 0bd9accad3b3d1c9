"""Write tests/data/optimal_timing_reference.json: outputs of the energy-optimal timing planner
(models/optimal_timing.py) for a few designs and modes, kept from the revision before its speed work
(session 2) so that tests/models/test_optimal_timing_reference.py can check that the faster planner returns
the same timings.

    python tests/data/make_optimal_timing_reference.py    # only to re-baseline, on purpose
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from cosim.models.optimal_timing import plan_optimal_timing
from cosim.models.panda_model import FRANKA_DOC_LIMITS as LIMITS
from cosim.models.panda_model import panda_model, thesis_to_urdf
from cosim.models.trajectory import plan_parabolic_blend

HERE = Path(__file__).resolve().parent
DESIGNS = [(-45.0, 70.0), (20.0, 42.0), (-100.0, 0.0), (-80.0, 140.0), (0.0, 140.0), (-60.0, 28.0)]
MODES = {"1.0": dict(factor=1.0), "1.25": dict(factor=1.25), "1.5": dict(factor=1.5), "tw20": dict(time_weight=20.0)}


def waypoints(q2_2: float, q2_4: float):
    return thesis_to_urdf([[0] * 7, [-90, q2_2, 0, q2_4, 0, 0, 0], [-180, 0, 0, 0, 0, 0, 0]])


def plan(design, mode, solver="ipopt"):
    """The reference plans are IPOPT's (tol 1e-8); ``solver="fatrop"`` is the planner's default."""
    blend = plan_parabolic_blend(waypoints(*design), LIMITS.qd_max, LIMITS.qdd_max)
    options = MODES[mode]
    bound = options["factor"] * blend.duration if "factor" in options else None
    return blend, plan_optimal_timing(blend, panda_model(), LIMITS.qd_max, LIMITS.qdd_max, LIMITS.tau_max,
                                      max_duration=bound, time_weight=options.get("time_weight", 0.0),
                                      solver=solver)


def main() -> None:
    revision = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              cwd=HERE).stdout.strip()
    rows = []
    for design in DESIGNS:
        for mode in MODES:
            blend, timing = plan(design, mode)
            rows.append({"design": list(design), "mode": mode, "blend_duration": blend.duration,
                         "duration": timing.duration, "planned_energy": timing.planned_energy,
                         "s": timing.s.tolist(), "b": timing.b.tolist()})
            print(design, mode, round(timing.duration, 4), round(timing.planned_energy, 4), timing.passes)
    out = {"revision": revision, "rows": rows}
    (HERE / "optimal_timing_reference.json").write_text(json.dumps(out) + "\n")


if __name__ == "__main__":
    main()
