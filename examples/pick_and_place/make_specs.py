"""Write the spec variants of the pick-and-place study from ``spec.json``.

``spec.json`` is the master: the full thesis grid (121 x 141 = 17061 points) at
the fast fidelity level (inverse dynamics, 10 ms steps, midpoint sampling of
the reference).  The variants differ only in the lines printed below, so the
objectives and the design space cannot drift apart:

- ``spec_exudyn.json``: the servo-simulated level (``PandaExudyn``, 2 ms
  communication and solver steps, the reference sampled at the communication
  points and known to be the step end's);
- ``spec_coarse.json`` / ``spec_coarse_exudyn.json``: the same on a coarse
  grid of 13 x 21 = 273 points (q2[2] every 10 deg, q2[4] every 7 deg; both
  include 0, the thesis's optimum, and the corners);
- ``spec_datasheet.json``: the thesis replication with the Panda datasheet's
  joint speeds (150 deg/s joints 1-4, 180 deg/s joints 5-7) instead of Franka's
  documentation limits, for the trajectory and the robot's limit checks, and
  ``spec_coarse_datasheet.json`` on the coarse grid.

Run ``python examples/pick_and_place/make_specs.py`` after editing spec.json.
"""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

HERE = Path(__file__).resolve().parent
Q2_2, Q2_4 = "traj.waypoints[9]", "traj.waypoints[11]"  # thesis q2[2] and q2[4]: waypoint 2, joints 2 and 4


def exudyn_level(spec: dict) -> dict:
    """The servo-simulated fidelity level of ``spec``."""
    s = copy.deepcopy(spec)
    s["units"]["robot"]["python"] = "models.panda_exudyn:PandaExudyn"
    # 2 ms solver steps (energies within 0.3 % of 1 ms, README); under Gauss-Seidel the
    # robot sees the reference of the step's end, which ref_timing tells it; the servo
    # evaluates its reference at the end of each solver step, where Exudyn's
    # generalized-alpha solver satisfies the equations of motion (mid-step: a lag of dt/2)
    s["units"]["robot"]["parameters"] = {"substep": 0.002, "ref_timing": "step_end", "ref_phase": 1.0}
    s["units"]["traj"]["parameters"]["sampling"] = "instant"
    s["experiment"]["step"] = 0.002
    s["description"] = s["description"].replace("Fidelity level: inverse dynamics", "Fidelity level: Exudyn servo simulation")
    return s


# Franka Emika Panda datasheet joint speeds (models/panda_model.py DATASHEET_VELOCITY), rad/s
DATASHEET_VELOCITY = [math.radians(v) for v in (150.0, 150.0, 150.0, 150.0, 180.0, 180.0, 180.0)]


def datasheet_speeds(spec: dict) -> dict:
    """``spec`` with the datasheet's joint speeds for the trajectory and the robot's limit checks."""
    s = copy.deepcopy(spec)
    s["units"]["traj"]["parameters"]["v_max"] = list(DATASHEET_VELOCITY)
    s["units"]["robot"].setdefault("parameters", {})["qd_max"] = list(DATASHEET_VELOCITY)
    s["description"] += (" Variant: the Panda datasheet's joint speeds (150 deg/s joints 1-4, 180 deg/s joints 5-7) "
                         "for the trajectory and the robot's limit checks (thesis replication of table 8-1's times).")
    return s


def coarse(spec: dict) -> dict:
    """``spec`` on the 273-point coarse grid."""
    s = copy.deepcopy(spec)
    s["design"]["parameters"][Q2_2]["step"] = 10
    s["design"]["parameters"][Q2_4]["step"] = 7
    return s


def main() -> None:
    base = json.loads((HERE / "spec.json").read_text())
    variants = {
        "spec_exudyn.json": exudyn_level(base),
        "spec_coarse.json": coarse(base),
        "spec_coarse_exudyn.json": coarse(exudyn_level(base)),
        "spec_datasheet.json": datasheet_speeds(base),
        "spec_coarse_datasheet.json": coarse(datasheet_speeds(base)),
    }
    for name, spec in variants.items():
        (HERE / name).write_text(json.dumps(spec, indent=2) + "\n")
        print("wrote", name)


if __name__ == "__main__":
    main()
