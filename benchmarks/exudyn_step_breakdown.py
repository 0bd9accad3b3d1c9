"""Where the Python around Exudyn's solver goes, statement by statement, per communication step.

Complements ``benchmarks/exudyn_level.py`` (which measures the whole split in the running study):
runs one study point (-45, 70) to its end, alone (``PandaExudyn``) and as a lock-step group
(``PandaExudynBatch``, ``--rows`` K points), then times each statement of the unit's per-step path
in that end state with ``timeit`` (best of 3 x 5000 loops), the statements written as in
``models/panda_exudyn.py`` (where timeit needs it, ``x += y`` on a name is ``np.add(x, y, out=x)``).  In the running study the costs are higher than in these hot loops (the
other units evict the caches): compare the sum with exudyn_level.py's "Python/step".

Usage::

    python benchmarks/exudyn_step_breakdown.py              # single unit and lock-step K=6
    python benchmarks/exudyn_step_breakdown.py --rows 12

Results are recorded in benchmarks/exudyn_level.md.
"""

from __future__ import annotations

import argparse
import math  # noqa: F401 (used by the timed statements)
import os
import sys
import timeit
from operator import gt, lt, sub  # noqa: F401 (used by the timed statements)
from pathlib import Path

import numpy as np  # noqa: F401 (used by the timed statements)
import pinocchio as pin  # noqa: F401 (used by the timed statements)

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import exudyn_level  # noqa: E402

# NewtonJacobian.__call__ at a step without re-differentiation
JACOBIAN = ("jacobian = solver.GetSystemMassMatrix(); jacobian *= jac._mass_factor; jacobian += jac._rhs_part; "
            "solver.SetSystemJacobian(jacobian)")

# (group, statement): the single unit's do_step in the study's configuration, then _read_outputs,
# then the Newton-Jacobian callback made from inside SolveSteps (a step without re-differentiation)
SINGLE = [
    ("feed-forward", "tau = u._kp * q_ref; tau += u._kd * qd_ref"),
    ("feed-forward", "np.add(tau, pin.rnea(u._model, u._data, q_ref, qd_ref, qdd_ref), out=tau)"),
    ("force parameter", "u._mbs.SetObjectParameter(u._tree, 'jointForceVector', tau)"),
    ("solver call", "it.startTime = t; it.endTime = t + h"),
    ("state", "sd = u._mbs.systemData; q, qd, qdd = sd.GetODE2Coordinates(), sd.GetODE2Coordinates_t(), "
              "sd.GetODE2Coordinates_tt()"),
    ("outputs", "u.q[:], u.qd[:], u.qdd[:] = q, qd, qdd"),
    ("outputs", "u.tau[:] = u._tau_const - u._kp * q - u._kd * qd"),
    ("TCP kinematics", "pin.forwardKinematics(u._model, u._data, q); "
                       "ee = pin.updateFramePlacement(u._model, u._data, u._ee).translation; u.ee_pos[:] = ee"),
    ("outputs", "ee_now = ee.tolist(); u.ee_path_length += math.dist(ee_now, u._ee_last); u._ee_last = ee_now"),
    ("outputs", "q_list, qd_list, tau_list = q.tolist(), qd.tolist(), u.tau.tolist(); "
                "u.tracking_error = max(map(abs, map(sub, q_list, q_ref.tolist())))"),
    ("outputs", "ratio = [abs(x) / m for x, m in zip(tau_list, u._tau_max_list)]; u.tau_ratio[:] = ratio"),
    ("outputs", "u.limit_violated = (max(ratio) > 1.0 or any(map(lt, q_list, u._q_min_list)) "
                "or any(map(gt, q_list, u._q_max_list)) or any(abs(v) > m for v, m in zip(qd_list, u._qd_max_list))); "
                "math.isfinite(sum(q_list))"),
    ("Jacobian callback", JACOBIAN),
]

# the twin's do_step, per lock-step step (all rows active)
BATCH = [
    ("feed-forward: RNEA + servo constant, all rows (one compiled call)",
     "b._kernels.servo(b._active_count, b._active_address)"),
    ("force parameter: one forceVector for all rows", "b._mbs.SetObjectParameter(b._forces, 'forceVector', b._force_flat)"),
    ("solver call", "it.startTime = t; it.endTime = t + h"),
    ("state", "sd = b._mbs.systemData; b._q_flat[:] = sd.GetODE2Coordinates(); "
              "b._qd_flat[:] = sd.GetODE2Coordinates_t(); b._qdd_flat[:] = sd.GetODE2Coordinates_tt()"),
    ("outputs: TCP kinematics, tau, path, errors, limits, all rows (one compiled call)",
     "b._kernels.outputs(b._active_count, b._active_address)"),
    ("Jacobian callback", JACOBIAN),
]


def time_statements(statements, namespace) -> list[tuple[str, str, float]]:
    rows = []
    for group, statement in statements:
        exec(statement, namespace)  # defines the names later statements use
        seconds = min(timeit.repeat(statement, globals=namespace, number=5000, repeat=3)) / 5000
        rows.append((group, statement, seconds))
    return rows


def report(title: str, rows, per: int = 1) -> float:
    print(f"\n{title}")
    groups: dict[str, float] = {}
    for group, statement, seconds in rows:
        groups[group] = groups.get(group, 0.0) + seconds
        print(f"  {seconds * 1e6:7.2f} us  {statement[:110]}")
    total = sum(groups.values())
    print("  by part" + ("" if per == 1 else f" (per lock-step step; / {per} rows)"))
    for group, seconds in groups.items():
        extra = "" if per == 1 else f"  {seconds / per * 1e6:6.2f} us per row"
        print(f"  {seconds * 1e6:7.2f} us  {group}{extra}")
    print(f"  {total * 1e6:7.2f} us  total" + ("" if per == 1 else f"  {total / per * 1e6:6.2f} us per row"))
    return total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rows", type=int, default=6, help="lock-step group size (default 6, what a sweep worker chooses)")
    args = parser.parse_args()
    print("load average: {:.2f} {:.2f} {:.2f}".format(*os.getloadavg()))
    from cosim.models.panda_exudyn import PandaExudyn

    level = exudyn_level.Level("single", PandaExudyn)
    level.run(-45.0, 70.0)
    u = level.units["robot"]
    solver = u._solver
    namespace = dict(globals(), u=u, q_ref=u.q_ref, qd_ref=u.qd_ref, qdd_ref=u.qdd_ref, solver=solver, it=solver.it,
                     jac=u._jacobian, t=1.0, h=0.002)
    report("single unit (PandaExudyn), per communication step", time_statements(SINGLE, namespace))

    group = exudyn_level.LockstepLevel(args.rows)
    points = [(-45.0, 70.0)] + exudyn_level.design_points(args.rows - 1)
    overrides = [[group.system.assignment_for("traj.waypoints[9]", a),
                  group.system.assignment_for("traj.waypoints[11]", c)] for a, c in points]
    exudyn_level.run_lockstep(group.system, overrides, group.batches)  # left in its end state
    b = group.batches["robot"]
    b.active = np.arange(args.rows)  # every row, as in most steps of a group
    solver = b._solver
    namespace = dict(globals(), b=b, solver=solver, it=solver.it,
                     jac=b._jacobian, t=1.0, h=0.002)
    report(f"lock-step twin (PandaExudynBatch), K={args.rows}, all rows active", time_statements(BATCH, namespace),
           per=args.rows)
    for unit in level.units.values():
        unit.terminate()
    for batch in group.batches.values():
        batch.terminate()


if __name__ == "__main__":
    main()
