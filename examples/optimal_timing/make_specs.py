"""Write the specs of the optimal-timing study from the pick-and-place study's coarse spec.

The system and the objectives are those of
``examples/pick_and_place/spec_coarse.json``; the trajectory unit is swapped by one line for
``models.optimal_timing:OptimalTimingTrajectory``, and the design space gets two
more axes:

- ``traj.max_duration_factor``: the duration bound, a multiple of each design's
  full-speed parabolic-blend duration;
- ``traj.optimize``: true = the energy-optimal timing, false = the reference, the
  parabolic blend uniformly slowed down to that bound (same path, same duration).

``spec.json``: the 273 designs of the coarse grid (q2[2] every 10 deg, q2[4] every 7 deg) at 1.25 x (546 points).
``spec_full.json``: the same on the thesis's full 1-degree grid (17061 designs, 34122 points), from
``examples/pick_and_place/spec.json``.
``spec_tradeoff.json``: 9 designs at bounds 1.0 .. 2.0 x (144 points), the time-energy trade-off.

Run ``python examples/optimal_timing/make_specs.py`` after editing the pick-and-place spec.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

HERE = Path(__file__).resolve().parent
SOURCE = HERE.parent / "pick_and_place" / "spec_coarse.json"
FULL_SOURCE = HERE.parent / "pick_and_place" / "spec.json"
Q2_2, Q2_4 = "traj.waypoints[9]", "traj.waypoints[11]"
EXTRA_OBJECTIVES = {
    "blend_duration": {"signal": "traj.blend_duration", "reduce": "final", "unit": "s",
                       "description": "duration of the full-speed parabolic blend of this design"},
    "planned_energy": {"signal": "traj.planned_energy", "reduce": "final", "unit": "J",
                       "description": "the planner's energy of its timing on its grid (drive model, midpoint rule)"},
    "solve_time": {"signal": "traj.solve_time", "reduce": "final", "unit": "s",
                   "description": "time spent planning the timing (path data + IPOPT passes)"},
}


def optimal_timing(spec: dict) -> dict:
    s = copy.deepcopy(spec)
    s["name"] = "optimal_timing"
    s["description"] = ("Energy-optimal timing vs the parabolic blend on the pick-and-place paths (thesis 7.2.3): "
                        "the trajectory unit of examples/pick_and_place/spec_coarse.json swapped for "
                        "models.optimal_timing:OptimalTimingTrajectory; optimize=false plays the blend uniformly "
                        "slowed down to the same duration bound. Written by make_specs.py.")
    s["units"]["traj"]["python"] = "models.optimal_timing:OptimalTimingTrajectory"
    s["objectives"].update(copy.deepcopy(EXTRA_OBJECTIVES))
    return s


def main_study(spec: dict) -> dict:
    """The grid of ``spec`` (coarse or full) at a bound of 1.25 x, optimal timing and slowed blend."""
    s = optimal_timing(spec)
    s["design"]["parameters"]["traj.max_duration_factor"] = {"values": [1.25]}
    s["design"]["parameters"]["traj.optimize"] = {"bool": True}
    return s


def tradeoff(spec: dict) -> dict:
    s = optimal_timing(spec)
    s["design"]["parameters"] = {
        Q2_2: {"values": [-100, -45, 0], "unit": "deg"},
        Q2_4: {"values": [0, 70, 140], "unit": "deg"},
        "traj.max_duration_factor": {"values": [1.0, 1.1, 1.2, 1.3, 1.4, 1.5, 1.75, 2.0]},
        "traj.optimize": {"bool": True},
    }
    return s


def main() -> None:
    base = json.loads(SOURCE.read_text())
    specs = {"spec.json": main_study(base), "spec_tradeoff.json": tradeoff(base),
             "spec_full.json": main_study(json.loads(FULL_SOURCE.read_text()))}
    for name, spec in specs.items():
        (HERE / name).write_text(json.dumps(spec, indent=2) + "\n")
        print("wrote", name)


if __name__ == "__main__":
    main()
