"""The Panda's inverse dynamics as CasADi symbols and as a generated-C FMU.

Checked against independent computations: pinocchio's own RNEA and forward
kinematics (the symbolic model is written separately, in
models/panda_symbolic.py), the Python inverse-dynamics unit on the whole coarse
pick-and-place grid, and a second co-simulation engine (libcosim, through its
PyPI wrapper libcosimpy; FMI 2.0 only).  fmpy's validation of both FMI
versions is in tests/fmus/test_fmu_build.py, with every FMU we ship.
"""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest
from fmpy.fmi1 import FMICallException

from cosim.fmus.build import ensure_built
from cosim.fmus.testing import FmuInstance
from cosim.models.panda_model import FRANKA_DOC_LIMITS, ee_position, panda_model, thesis_to_urdf
from cosim.models.panda_symbolic import symbolic_inverse_dynamics
from cosim.models.trajectory import plan_parabolic_blend
from tests.models.test_pick_and_place import FOLDER, run_points

PAYLOADS = [  # (mass, com in the TCP frame, Ixx Iyy Izz Ixy Ixz Iyz)
    (0.0, (0.0, 0.0, 0.0), (0.0,) * 6),
    (1.5, (0.01, -0.02, 0.05), (0.010, 0.020, 0.015, 0.001, -0.002, 0.003)),
    (3.0, (0.0, 0.0, 0.1), (0.02, 0.02, 0.01, 0.0, 0.0, 0.0)),
    (0.4, (-0.03, 0.04, 0.0), (0.001, 0.002, 0.003, 0.0, 0.0004, 0.0)),
]


def random_states(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint states over the whole range (positions in the limits, 2x the speed limits, 2x the accelerations)."""
    lim = FRANKA_DOC_LIMITS
    q = rng.uniform(lim.q_min, lim.q_max, (n, 7))
    qd = rng.uniform(-2 * lim.qd_max, 2 * lim.qd_max, (n, 7))
    qdd = rng.uniform(-2 * lim.qdd_max, 2 * lim.qdd_max, (n, 7))
    return q, qd, qdd


def test_symbolic_rnea_matches_pinocchio_at_1000_random_states():
    f = symbolic_inverse_dynamics()
    rng = np.random.default_rng(13)
    per_payload = 250
    worst_tau = worst_ee = 0.0
    for mass, com, inertia in PAYLOADS:
        model = panda_model(mass, com, inertia)
        data = model.createData()
        q, qd, qdd = random_states(rng, per_payload)
        tau, ee = f.map(per_payload)(q.T, qd.T, qdd.T, mass, com, inertia)
        tau, ee = np.array(tau).T, np.array(ee).T
        for k in range(per_payload):
            worst_tau = max(worst_tau, np.abs(tau[k] - pin.rnea(model, data, q[k], qd[k], qdd[k])).max())
            worst_ee = max(worst_ee, np.abs(ee[k] - ee_position(model, data, q[k])).max())
    assert worst_tau < 1e-10  # N.m
    assert worst_ee < 1e-12  # m


def test_generated_c_is_up_to_date_with_the_urdf_and_the_symbolic_model():
    """The text exactly, every numeric literal to 4 ulp (a constant's last bit follows the CPU's BLAS kernel)."""
    from cosim.models.panda_inverse_dynamics_codegen import stale_files

    assert stale_files() == [], "run python -m cosim.models.panda_inverse_dynamics_codegen"


@pytest.mark.parametrize("version", [2, 3])
def test_fmu_torques_with_payload_match_pinocchio(version, tmp_path):
    mass, com, inertia = PAYLOADS[1]
    model = panda_model(mass, com, inertia)
    data = model.createData()
    q, qd, qdd = random_states(np.random.default_rng(7), 20)
    with FmuInstance(ensure_built("panda_inverse_dynamics", version), unzip_parent=tmp_path) as fmu:
        fmu.instantiate()
        fmu.initialize(payload_mass=mass, payload_com=com, payload_inertia=inertia)
        for k in range(len(q)):
            fmu.set("q_ref", q[k]), fmu.set("qd_ref", qd[k]), fmu.set("qdd_ref", qdd[k])
            tau = fmu.get("tau")
            assert np.abs(tau - pin.rnea(model, data, q[k], qd[k], qdd[k])).max() < 1e-10
            assert fmu.get("ee_pos") == pytest.approx(ee_position(model, data, q[k]), abs=1e-12)
            assert fmu.get("tau_ratio") == pytest.approx(np.abs(tau) / FRANKA_DOC_LIMITS.tau_max)
            fmu.step(0.01 * k, 0.01)


def test_fmu_refuses_bad_parameters_and_inputs(tmp_path):
    with FmuInstance(ensure_built("panda_inverse_dynamics", 3), unzip_parent=tmp_path) as fmu:
        fmu.instantiate()
        with pytest.raises(FMICallException):
            fmu.initialize(payload_mass=-1.0)
        assert any("payload_mass" in text for _, text in fmu.messages)
        fmu.reset()
        fmu.initialize()
        fmu.set("qd_ref", [0, 0, float("nan"), 0, 0, 0, 0])
        with pytest.raises(FMICallException):
            fmu.get("tau")
        assert any("qd_ref[3]" in text for _, text in fmu.messages)


def test_fmu_objectives_equal_the_python_units_on_the_coarse_grid():
    """All 273 designs of spec_coarse.json, the robot swapped by one line: every objective to 1e-9."""
    spec = FOLDER / "spec_coarse.json"
    grid = json.loads(spec.read_text())["design"]["parameters"]
    axes = [np.arange(p["min"], p["max"] + p["step"] / 2, p["step"]) for p in grid.values()]
    points = [(float(a), float(b)) for a in axes[0] for b in axes[1]]
    assert len(points) == 273
    python = run_points(spec, points)
    fmu = run_points(spec, points, robot_unit={"fmu": "builtin:panda_inverse_dynamics_fmi3"})
    for p, o_py, o_fmu in zip(points, python, fmu):
        assert o_fmu.keys() == o_py.keys()
        for name in o_py:
            assert np.allclose(o_fmu[name], o_py[name], rtol=0, atol=1e-9), (p, name, o_fmu[name], o_py[name])


def test_fmu_runs_in_libcosim_with_pinocchios_values():
    """libcosim (a second engine) steps the FMI 2.0 FMU along the pick-and-place reference."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.WARNING)
    h = 0.01
    execution = CosimExecution.from_step_size(int(round(h * 1e9)))
    robot = execution.add_local_slave(CosimLocalSlave(fmu_path=str(ensure_built("panda_inverse_dynamics", 2)),
                                                      instance_name="robot"))
    vr = {v.name.decode(): v.reference for v in execution.slave_variables(robot)}
    manipulator, observer = CosimManipulator.create_override(), CosimObserver.create_last_value()
    execution.add_manipulator(manipulator)
    execution.add_observer(observer)

    def refs(name: str) -> list[int]:
        return [vr[f"{name}[{j}]"] for j in range(1, 8)]

    trajectory = plan_parabolic_blend(thesis_to_urdf([[0] * 7, [-90, -45, 0, 70, 0, 0, 0], [-180, 0, 0, 0, 0, 0, 0]]),
                                      FRANKA_DOC_LIMITS.qd_max, FRANKA_DOC_LIMITS.qdd_max)
    q0 = trajectory.sample(0.0)[0]
    for j, ref in enumerate(refs("q_ref")):
        execution.real_initial_value(robot, ref, float(q0[j]))
    model = panda_model()
    data = model.createData()
    previous, length = ee_position(model, data, q0), 0.0
    steps = int(np.ceil(trajectory.duration / h))
    for k in range(1, steps + 1):
        q, qd, qdd = trajectory.sample(k * h)
        manipulator.slave_real_values(robot, refs("q_ref") + refs("qd_ref") + refs("qdd_ref"),
                                      [float(x) for x in np.concatenate([q, qd, qdd])])
        assert execution.step()
        tau = np.array(observer.last_real_values(robot, refs("tau")))
        assert np.abs(tau - pin.rnea(model, data, q, qd, qdd)).max() < 1e-10, k
        ee = ee_position(model, data, q)
        length += np.linalg.norm(ee - previous)
        previous = ee
        assert observer.last_real_values(robot, [vr["ee_path_length"]])[0] == pytest.approx(length, abs=1e-12)
    assert length > 1.0  # the TCP really travelled (m)
