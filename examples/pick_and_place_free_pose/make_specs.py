"""Writes spec.json and spec_motor_sobol.json of this example from ../pick_and_place/spec.json.

spec.json: the thesis's pick-and-place (q1 = 0, q3 = (-180, 0, ...), thesis degrees, inverse-dynamics level,
10 ms steps) with the intermediate pose q2 free in all seven joints within the Panda's joint limits, plus a
velocity scaling of the trajectory; `optimize` minimises energy and execution time with the torque limits as a
constraint, and the design method is a Latin hypercube of the same budget (what `cosim sweep` runs).

spec_motor_sobol.json: the thesis's base pose q2 = (-90, -45, 0, 70, 0, 0, 0) with the motor/gear parameters
(equal on all joints) as the design space, for `cosim sensitivity`.

    python examples/pick_and_place_free_pose/make_specs.py
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

HERE = Path(__file__).resolve().parent
BASE = HERE.parent / "pick_and_place" / "spec.json"
BUDGET = 1000

# The Panda's joint limits (models.panda_model.FRANKA_DOC_LIMITS) in the thesis's degrees
# (models.panda_model.urdf_to_thesis), rounded inwards to 0.1 degree.
JOINT_RANGES = [(-166.0, 166.0), (-191.0, 11.0), (-166.0, 166.0), (4.0, 176.0), (-166.0, 166.0), (-91.0, 124.9),
                (-166.0, 166.0)]

# The motor/gear parameters around the energy FMU's defaults, equal on all joints.
MOTOR_RANGES = {
    "energy.gear_ratio": (60.0, 160.0, "", "gear ratio R"),
    "energy.r_terminal": (0.1, 0.4, "Ohm", "terminal resistance R_T"),
    "energy.k_m": (0.08, 0.2, "N.m/A", "torque constant k_M"),
    "energy.eta_motor": (0.8, 0.98, "", "motor efficiency"),
    "energy.eta_gear_value": (0.55, 0.85, "", "gear efficiency (constant over speed here)"),
}


def free_pose_spec(base: dict) -> dict:
    spec = copy.deepcopy(base)
    spec["name"] = "pick_and_place_free_pose"
    spec["description"] = (
        "Pick-and-place of thesis 7.2.3 with the intermediate pose free in all seven joints (thesis degrees, "
        "within the joint limits) and a velocity scaling; minimise energy and execution time with the torque "
        "limits as constraints. Inverse-dynamics level, 10 ms. Written by make_specs.py.")
    spec["objectives"]["duration"]["sense"] = "minimize"
    spec["experiment"]["stop"] = 40.0  # the slowest design (velocity scale 0.2, long swings) takes about 25 s
    parameters = {f"traj.waypoints[{8 + j}]": {"min": lo, "max": hi, "unit": "deg"}
                  for j, (lo, hi) in enumerate(JOINT_RANGES)}
    parameters["traj.velocity_scale"] = {"min": 0.2, "max": 1.0}
    spec["design"] = {"method": "lhs", "samples": BUDGET, "seed": 1, "parameters": parameters}
    spec["optimize"] = {"objectives": {"e_total": "minimize", "duration": "minimize"},
                        "constraints": ["peak_tau_ratio <= 1"], "sampler": "tpe", "budget": BUDGET, "batch": 16,
                        "seed": 1}
    return spec


def motor_sobol_spec(base: dict) -> dict:
    spec = copy.deepcopy(base)
    spec["name"] = "pick_and_place_motor_sobol"
    spec["description"] = (
        "Pick-and-place of thesis 7.2.3 at the base pose q2 = (-90, -45, 0, 70, 0, 0, 0): the motor and gear "
        "parameters (equal on all joints) as the design space, for cosim sensitivity. Written by make_specs.py.")
    spec["design"] = {"method": "lhs", "samples": 64, "seed": 1, "parameters": {
        target: {"min": lo, "max": hi, **({"unit": unit} if unit else {})}
        for target, (lo, hi, unit, _) in MOTOR_RANGES.items()}}
    return spec


def main() -> None:
    base = json.loads(BASE.read_text())
    for name, spec in (("spec.json", free_pose_spec(base)), ("spec_motor_sobol.json", motor_sobol_spec(base))):
        (HERE / name).write_text(json.dumps(spec, indent=2) + "\n")
        print(f"written: {HERE / name}")


if __name__ == "__main__":
    main()
