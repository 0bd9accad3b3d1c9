"""Write the spec variants of the pick-and-place study from ``spec.json``.

``spec.json`` is the master: the full thesis grid (121 x 141 = 17061 points) at
the fast fidelity level (inverse dynamics, 10 ms steps, midpoint sampling of
the reference).  The variants differ only in the lines printed below, so the
objectives and the design space cannot drift apart:

- ``spec_exudyn.json``: the servo-simulated level (``PandaExudyn``, 1 ms
  communication steps, the reference sampled at the communication points);
- ``spec_coarse.json`` / ``spec_coarse_exudyn.json``: the same on a coarse
  grid of 16 x 15 = 240 points (q2[2] every 8 deg, q2[4] every 10 deg).

Run ``python examples/pick_and_place/make_specs.py`` after editing spec.json.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

HERE = Path(__file__).resolve().parent
Q2_2, Q2_4 = "traj.waypoints[9]", "traj.waypoints[11]"  # thesis q2[2] and q2[4]: waypoint 2, joints 2 and 4


def exudyn_level(spec: dict) -> dict:
    """The servo-simulated fidelity level of ``spec``."""
    s = copy.deepcopy(spec)
    s["units"]["robot"]["python"] = "models.panda_exudyn:PandaExudyn"
    s["units"]["traj"]["parameters"]["sampling"] = "instant"
    s["experiment"]["step"] = 0.001
    s["description"] = s["description"].replace("Fidelity level: inverse dynamics", "Fidelity level: Exudyn servo simulation")
    return s


def coarse(spec: dict) -> dict:
    """``spec`` on the 240-point coarse grid."""
    s = copy.deepcopy(spec)
    s["design"]["parameters"][Q2_2]["step"] = 8
    s["design"]["parameters"][Q2_4]["step"] = 10
    return s


def main() -> None:
    base = json.loads((HERE / "spec.json").read_text())
    variants = {
        "spec_exudyn.json": exudyn_level(base),
        "spec_coarse.json": coarse(base),
        "spec_coarse_exudyn.json": coarse(exudyn_level(base)),
    }
    for name, spec in variants.items():
        (HERE / name).write_text(json.dumps(spec, indent=2) + "\n")
        print("wrote", name)


if __name__ == "__main__":
    main()
