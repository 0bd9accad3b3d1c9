"""The compiled row kernels of the Exudyn lock-step twin (models/panda_rows.py) against independent computations.

The feed-forward against pinocchio's RNEA (a separate implementation of the
same model), the TCP against pinocchio's forward kinematics, the outputs
against the numpy formulas of the single unit's outputs, row by row, over
random states and several payloads; inactive rows are left alone.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from cosim.models import panda_rows
from cosim.models.panda_model import FRANKA_DOC_LIMITS, ee_position, panda_model
from cosim.models.panda_rows import PandaRowKernels

PAYLOADS = [  # (mass, com in the TCP frame, Ixx Iyy Izz Ixy Ixz Iyz), one per row
    (0.0, (0.0, 0.0, 0.0), (0.0,) * 6),
    (1.5, (0.01, -0.02, 0.05), (0.010, 0.020, 0.015, 0.001, -0.002, 0.003)),
    (3.0, (0.0, 0.0, 0.1), (0.02, 0.02, 0.01, 0.0, 0.0, 0.0)),
    (0.4, (-0.03, 0.04, 0.0), (0.001, 0.002, 0.003, 0.0, 0.0004, 0.0)),
]
K = len(PAYLOADS)


def _arrays(rng: np.random.Generator) -> dict[str, np.ndarray]:
    """A twin's arrays for K rows: random references and states over the whole range, random gains, the limits."""
    lim = FRANKA_DOC_LIMITS
    a = {
        "q_ref": rng.uniform(lim.q_min, lim.q_max, (K, 7)),
        "qd_ref": rng.uniform(-lim.qd_max, lim.qd_max, (K, 7)),
        "qdd_ref": rng.uniform(-lim.qdd_max, lim.qdd_max, (K, 7)),
        "kp": rng.uniform(50, 600, (K, 7)), "kd": rng.uniform(10, 50, (K, 7)),
        "payload_mass": np.array([p[0] for p in PAYLOADS]),
        "payload_com": np.array([p[1] for p in PAYLOADS]),
        "payload_inertia": np.array([p[2] for p in PAYLOADS]),
        "q_min": np.tile(lim.q_min, (K, 1)), "q_max": np.tile(lim.q_max, (K, 1)),
        "qd_max": np.tile(lim.qd_max, (K, 1)), "tau_max": np.tile(lim.tau_max, (K, 1)),
        "force": np.zeros((K, 7)), "tau": np.zeros((K, 7)), "ee_pos": np.zeros((K, 3)), "ee_last": np.zeros((K, 3)),
        "ee_path_length": np.zeros(K), "tracking_error": np.zeros(K), "tau_ratio": np.zeros((K, 7)),
        "limit_violated": np.zeros(K, dtype=bool),
    }
    a["q"] = a["q_ref"] + rng.normal(0.0, 0.2, (K, 7))  # some rows leave their limits
    a["qd"] = a["qd_ref"] + rng.normal(0.0, 0.5, (K, 7))
    return a


def _rows(*rows: int) -> np.ndarray:
    return np.array(rows, dtype=np.int64)


def test_the_feed_forward_is_pinocchios_rnea_and_the_tcp_its_forward_kinematics():
    rng = np.random.default_rng(16)
    worst_force = worst_ee = 0.0
    for _ in range(50):
        a = _arrays(rng)
        kernels = PandaRowKernels(a, K)
        everyone = _rows(*range(K))
        kernels.servo(K, everyone.ctypes.data)
        kernels.outputs(K, everyone.ctypes.data, first=True)
        for k, payload in enumerate(PAYLOADS):
            model = panda_model(*payload)
            data = model.createData()
            rnea = pin.rnea(model, data, a["q_ref"][k], a["qd_ref"][k], a["qdd_ref"][k])
            expected = a["kp"][k] * a["q_ref"][k] + a["kd"][k] * a["qd_ref"][k] + rnea
            worst_force = max(worst_force, np.abs(a["force"][k] - expected).max())
            worst_ee = max(worst_ee, np.abs(a["ee_pos"][k] - ee_position(model, data, a["q"][k])).max())
    assert worst_force < 1e-10  # N.m
    assert worst_ee < 1e-12  # m


def test_the_outputs_are_the_single_units_formulas_row_by_row():
    rng = np.random.default_rng(7)
    a = _arrays(rng)
    a["q"][1, 3] = a["q_max"][1, 3] + 0.1  # a position limit
    a["q"][2] = a["q_ref"][2]  # on its reference, within every limit, small torque
    a["qd"][2] = a["qd_ref"][2] = 0.0
    a["tau_max"][2] = 1e6
    kernels = PandaRowKernels(a, K)
    everyone = _rows(*range(K))
    kernels.servo(K, everyone.ctypes.data)
    kernels.outputs(K, everyone.ctypes.data, first=True)
    first_ee = a["ee_pos"].copy()
    np.testing.assert_array_equal(a["ee_path_length"], 0.0)  # no chord at the first point
    a["q"] += 0.01
    assert kernels.outputs(K, everyone.ctypes.data) == 0
    tau = a["force"] - a["kp"] * a["q"] - a["kd"] * a["qd"]
    np.testing.assert_array_equal(a["tau"], tau)
    np.testing.assert_allclose(a["ee_path_length"], np.linalg.norm(a["ee_pos"] - first_ee, axis=1), rtol=1e-14)
    np.testing.assert_allclose(a["ee_last"], a["ee_pos"], rtol=0, atol=0)
    np.testing.assert_array_equal(a["tracking_error"], np.abs(a["q"] - a["q_ref"]).max(axis=1))
    np.testing.assert_array_equal(a["tau_ratio"], np.abs(tau) / a["tau_max"])
    violated = ((a["tau_ratio"] > 1) | (a["q"] < a["q_min"]) | (a["q"] > a["q_max"])
                | (np.abs(a["qd"]) > a["qd_max"])).any(axis=1)
    np.testing.assert_array_equal(a["limit_violated"], violated)
    assert violated[1] and not violated[2]


def test_only_the_listed_rows_are_computed_and_a_nan_is_reported():
    a = _arrays(np.random.default_rng(3))
    kernels = PandaRowKernels(a, K)
    kernels.servo(2, _rows(1, 3).ctypes.data)
    assert np.all(a["force"][[0, 2]] == 0.0) and np.all(a["force"][[1, 3]] != 0.0)
    a["q"][0, 2] = np.nan
    assert kernels.outputs(2, _rows(1, 3).ctypes.data) == 0  # the NaN is in a row not listed
    assert np.all(a["tau"][[0, 2]] == 0.0) and np.all(a["ee_pos"][[0, 2]] == 0.0)
    assert kernels.outputs(3, _rows(0, 1, 3).ctypes.data) == 1
    assert np.isnan(a["tracking_error"][0])  # NaN wins, as numpy's max


def test_arrays_of_the_wrong_layout_are_refused():
    a = _arrays(np.random.default_rng(1))
    a["q"] = np.zeros((7, K)).T  # K x 7 but not C-ordered
    with pytest.raises(ValueError, match=r"q: expected a C-contiguous float64 array of shape \(4, 7\), got .* not C-ordered"):
        PandaRowKernels(a, K)
    a["q"] = np.zeros((K, 7))
    a["ee_pos"] = np.zeros((K, 7))  # the C would write 3 per row
    with pytest.raises(ValueError, match=r"ee_pos: expected .* shape \(4, 3\), got float64 \(4, 7\)"):
        PandaRowKernels(a, K)


def test_the_checked_in_generated_c_is_up_to_date():
    """The text exactly, every numeric literal to 4 ulp (a constant's last bit follows the CPU's BLAS kernel)."""
    assert panda_rows.stale_files() == [], "run python -m cosim.models.panda_rows"


def _regeneration_with(change):
    """A ``generate`` giving the checked-in row-kernel C with ``change(text)`` applied: a stand-in for a
    regeneration on another machine, to see what the up-to-date check lets through."""
    def generate(out_dir):
        paths = []
        for name in ("panda_rows_casadi.c", "panda_rows_casadi.h"):
            path = out_dir / name
            text = (panda_rows.SOURCE_DIR / name).read_text()
            path.write_text(change(text) if name.endswith(".c") else text)
            paths.append(path)
        return paths
    return generate


def test_the_up_to_date_check_allows_a_constants_last_bits_and_nothing_else():
    """Issue 28: an AVX-512 OpenBLAS kernel printed ``a050=5.2878381999606115e-02`` where the checked-in C has
    ...108e-02 (one ulp): the same code. A constant moved by 1e-13 relative, or any other text, is other code."""
    import math
    import re

    from cosim.models.panda_symbolic import stale_generated_files

    original = (panda_rows.SOURCE_DIR / "panda_rows_casadi.c").read_text()
    literal = re.search(r"=(-?\d\.\d{16}e[-+]\d\d);", original).group(1)
    value = float(literal)

    def moved(by):
        return lambda text: text.replace(literal, f"{by(value):.16e}", 1)
    folder = panda_rows.SOURCE_DIR
    assert stale_generated_files(_regeneration_with(lambda t: t), folder) == []
    assert stale_generated_files(_regeneration_with(moved(lambda v: math.nextafter(v, math.inf))), folder) == []
    assert stale_generated_files(_regeneration_with(moved(lambda v: v + 3 * math.ulp(v))), folder) == []
    assert stale_generated_files(_regeneration_with(moved(lambda v: v * (1 + 1e-13))), folder) == ["panda_rows_casadi.c"]
    assert stale_generated_files(_regeneration_with(lambda t: t.replace("+", "-", 1)), folder) == ["panda_rows_casadi.c"]
    assert stale_generated_files(_regeneration_with(lambda t: t.replace("[1]", "[2]", 1)), folder) == ["panda_rows_casadi.c"]


def test_the_library_is_built_once_per_source_digest(tmp_path, monkeypatch):
    monkeypatch.setenv("COSIM_FMU_CACHE", str(tmp_path))
    path = panda_rows.library_path()
    assert path.is_file() and path.parent.parent == tmp_path and panda_rows.source_digest()[:20] in path.parent.name
    mtime = path.stat().st_mtime_ns
    assert panda_rows.library_path() == path and path.stat().st_mtime_ns == mtime  # cached, not rebuilt


# the inverse-dynamics twins' kernels (id_rows.c) against the numpy code they replace, bit for bit ----------------

def _bits(x: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=np.float64).view(np.int64)


def _trajectory_twin(rows: int, kernel: bool):
    from cosim.models.trajectory import TrajectoryGenerator

    twin = TrajectoryGenerator.batch_class(TrajectoryGenerator, "traj", rows)
    rng = np.random.default_rng(rows)
    for k in range(rows):  # three waypoints per row, random middle poses (thesis degrees)
        twin.waypoints[k, 7:14] = [-90.0, *rng.uniform(-100, 20, 1), 0.0, *rng.uniform(0, 140, 1), 0.0, 0.0, 0.0]
        twin.waypoints[k, 14] = -180.0
    twin.n_waypoints[:] = 3
    twin.convention[:] = "thesis_deg"
    twin.sampling[:] = "step_midpoint"
    if not kernel:
        twin._row_kernel = lambda: None
    twin.setup(0.0, 10.0)
    twin.exit_initialization()
    assert (twin._kernel is not None) == kernel
    return twin


def test_the_compiled_trajectory_sampling_is_the_numpy_twins_bit_for_bit():
    twin = _trajectory_twin(6, kernel=True)
    numpy_twin = _trajectory_twin(6, kernel=False)
    # inside phases, before the start, after the end, and exactly at phase starts and durations
    times = [-0.5, 0.0, 1e-9, 0.37, 1.0, 2.5, 4.0, *twin._starts[2, :4], *twin.duration, twin.duration[0] - 1e-12]
    q, v, a = (np.zeros((6, 7)) for _ in range(3))
    for t in times:
        twin._kernel.sample(float(t), q.ctypes.data, v.ctypes.data, a.ctypes.data)
        expected = numpy_twin._sample(float(t))
        for got, want in zip((q, v, a), expected):
            np.testing.assert_array_equal(_bits(got), _bits(want), err_msg=f"t={t}")
    for t in np.arange(0.01, 4.0, 0.01):  # the twins' outputs step by step, midpoint sampling
        twin.do_step(float(t) - 0.01, 0.01)
        numpy_twin.do_step(float(t) - 0.01, 0.01)
        for name in ("q_ref", "qd_ref", "qdd_ref", "finished"):
            np.testing.assert_array_equal(getattr(twin, name), getattr(numpy_twin, name), err_msg=name)
        assert np.array_equal(_bits(twin.qdd_ref), _bits(numpy_twin.qdd_ref))


def _arm_twin(kernel: bool, rows: int = 5):
    from cosim.models.panda_inverse_dynamics import PandaInverseDynamics

    twin = PandaInverseDynamics.batch_class(PandaInverseDynamics, "robot", rows)
    if not kernel:
        twin._row_kernel = lambda: None
    return twin


def test_the_compiled_arm_outputs_are_the_numpy_twins_bit_for_bit():
    rng = np.random.default_rng(35)
    lim = FRANKA_DOC_LIMITS
    twins = [_arm_twin(True), _arm_twin(False)]
    references = [(rng.uniform(lim.q_min * 1.1, lim.q_max * 1.1, (5, 7)), rng.uniform(-3, 3, (5, 7)),
                   rng.uniform(-20, 20, (5, 7))) for _ in range(30)]
    references[7][0][2, 3] = np.nan  # a NaN angle: numpy's max and min propagate it
    references[9][1][4] = -0.0
    last_q, last_qd, last_qdd = references[-1]
    last_q[0], last_qd[0], last_qdd[0] = (lim.q_min + lim.q_max) / 2, 0.0, 0.0  # at rest inside its limits
    for twin in twins:
        twin.q_ref[:], twin.qd_ref[:], twin.qdd_ref[:] = references[0]
        twin.setup(0.0, 1.0)
        twin.exit_initialization()
    assert twins[0]._kernel is not None and twins[1]._kernel is None
    for step, (q, qd, qdd) in enumerate(references[1:]):
        for twin in twins:
            if step == 12:
                twin.active = np.array([0, 2, 3])  # rows end: only the active ones are computed
            twin.q_ref[:], twin.qd_ref[:], twin.qdd_ref[:] = q, qd, qdd
            twin._outputs_stale = True
            twin.do_step(0.01 * step, 0.01)
        for name in ("tau", "ee_pos", "ee_path_length", "tracking_error", "tau_ratio"):
            np.testing.assert_array_equal(_bits(getattr(twins[0], name)), _bits(getattr(twins[1], name)),
                                          err_msg=f"{name} at step {step}")
        np.testing.assert_array_equal(twins[0].limit_violated, twins[1].limit_violated)
    assert twins[0].limit_violated.any() and not twins[0].limit_violated.all()
