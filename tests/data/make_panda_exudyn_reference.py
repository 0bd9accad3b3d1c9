"""Write panda_exudyn_reference.json: outputs of ``PandaExudyn`` to check faster versions against.

The committed JSON was written with the unit as it was at commit 0ca756b (before the
speed work of issue 16), so ``tests/models/test_panda_exudyn_reference.py`` asserts that later
versions still give the same results.  Re-running this script overwrites the reference
with the *current* unit's results: do it only for a deliberate change of the model, and
say so in the commit.

    python tests/data/make_panda_exudyn_reference.py

Cases
    ``study``    objectives of ``examples/pick_and_place/spec_exudyn.json`` at five design
                 points (the study's own settings: 2 ms, ``ref_timing = "step_end"``,
                 ``ref_phase = 1``), run as a sweep worker does (units reused, reset between);
    ``trace``    the recorded ``robot.q``, ``robot.tau``, ``energy.e_total`` of one point, every
                 25th communication point;
    ``unit_*``   the unit driven directly along the pick-and-place trajectory with 2 ms
                 communication steps: its defaults (two 1 ms solver steps per communication
                 step, ``ref_timing = "step_start"``, ``ref_phase = 0.5``), and with the
                 bin-picking pendulum; outputs every 20th step.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from cosim.execution.run import Execution  # noqa: E402
from cosim.models.panda_exudyn import PandaExudyn  # noqa: E402
from cosim.models.panda_model import FRANKA_DOC_LIMITS, thesis_to_urdf  # noqa: E402
from cosim.models.trajectory import plan_parabolic_blend  # noqa: E402
from cosim.spec.loader import load_spec  # noqa: E402
from cosim.system.builder import build_system  # noqa: E402

OUT = Path(__file__).with_name("panda_exudyn_reference.json")
SPEC = ROOT / "examples" / "pick_and_place" / "spec_exudyn.json"
POINTS = [(-45.0, 70.0), (0.0, 0.0), (-100.0, 140.0), (20.0, 140.0), (-74.0, 85.0)]
TRACE_POINT = (-45.0, 70.0)
TRACE_SIGNALS = ["robot.q[2]", "robot.q[4]", "robot.tau[2]", "robot.tau[4]", "robot.tau[7]", "energy.e_total"]
UNIT_STEP = 0.002  # s, communication step of the unit-level cases
UNIT_OUTPUTS = ["q", "qd", "qdd", "tau", "ee_pos", "ee_path_length", "tracking_error", "tau_ratio",
                "limit_violated", "pendulum_angle"]
PENDULUM = {"pendulum_bob_mass": 0.25, "pendulum_rod_mass": 0.02, "pendulum_length": 0.2}


def study_cases() -> tuple[list[dict], dict]:
    system = build_system(load_spec(SPEC))
    units = {n: su.unit_type.instantiate(n) for n, su in system.units.items()}
    rows, trace = [], {}
    for q22, q24 in POINTS:
        for unit in units.values():
            unit.reset()
        overrides = [system.assignment_for("traj.waypoints[9]", q22), system.assignment_for("traj.waypoints[11]", q24)]
        record = (q22, q24) == TRACE_POINT
        result = Execution(system, overrides, units=units, record=record).run()
        assert result.ok, result.message
        rows.append({"point": [q22, q24], "objectives": {k: float(v) for k, v in result.objectives.items()}})
        if record:
            tr = result.traces.iloc[::25]
            trace = {"point": [q22, q24], "time": tr["time"].tolist(),
                     **{s: tr[s].tolist() for s in TRACE_SIGNALS}}
    for unit in units.values():
        unit.terminate()
    return rows, trace


def unit_case(params: dict) -> dict:
    """Drive PandaExudyn along the thesis trajectory (q2 = (-90, -45, 0, 70, 0, 0, 0)) with 2 ms steps."""
    wp = thesis_to_urdf([[0, 0, 0, 0, 0, 0, 0], [-90, -45, 0, 70, 0, 0, 0], [-180, 0, 0, 0, 0, 0, 0]])
    traj = plan_parabolic_blend(wp, FRANKA_DOC_LIMITS.qd_max, FRANKA_DOC_LIMITS.qdd_max)
    unit = PandaExudyn("robot")
    unit.set_values(params)
    q, qd, qdd = traj.sample(0.0)
    unit.set_values({"q_ref": q, "qd_ref": qd, "qdd_ref": qdd})
    unit.setup(0.0, None)
    unit.exit_initialization()
    n = int(round((traj.duration + 0.1) / UNIT_STEP))
    samples = []
    for k in range(n):
        q, qd, qdd = traj.sample(k * UNIT_STEP)
        unit.set_values({"q_ref": q, "qd_ref": qd, "qdd_ref": qdd})
        unit.do_step(k * UNIT_STEP, UNIT_STEP)
        if k % 20 == 19 or k == n - 1:
            values = unit.get_values(UNIT_OUTPUTS)
            samples.append({"t": (k + 1) * UNIT_STEP,
                            **{name: np.asarray(v, dtype=float).tolist() for name, v in values.items()}})
    unit.terminate()
    return {"parameters": params, "step": UNIT_STEP, "samples": samples}


def main() -> None:
    import subprocess
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    study, trace = study_cases()
    data = {"written_at_commit": commit, "spec": "examples/pick_and_place/spec_exudyn.json",
            "study": study, "trace": trace,
            "unit_defaults": unit_case({}), "unit_pendulum": unit_case(PENDULUM)}
    OUT.write_text(json.dumps(data, separators=(",", ":")) + "\n")
    print(f"wrote {OUT} ({OUT.stat().st_size // 1024} kB) at commit {commit}")


if __name__ == "__main__":
    main()
