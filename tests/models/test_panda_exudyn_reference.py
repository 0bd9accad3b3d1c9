"""PandaExudyn gives today's results: the speed work of issue 16 kept the model's outputs.

``tests/data/panda_exudyn_reference.json`` holds the unit's outputs computed *before*
the speed work (commit 0ca756b, see ``tests/data/make_panda_exudyn_reference.py``):
the pick-and-place study's objectives at five design points, a recorded trace, and
the unit driven directly with its defaults (two solver steps per communication
step, reference at mid-step) and with the bin-picking pendulum.  The same cases
are run again with the current unit and compared.

Stated tolerances
    objectives and recorded signals: relative 1e-6 plus absolute 1e-8 (SI units: rad,
    rad/s, N.m, m, J); outputs of the unit driven directly: within 1e-7 of the largest
    magnitude that output reaches in the run.  Booleans match exactly.

Why these bounds: the solver is the same generalized-alpha method with the same
step, tolerances and Newton settings; the work moved around it (reference update,
feed-forward, outputs) changes the arithmetic at the level of round-off, which the
Newton iteration passes on only up to its own tolerance (relative 1e-10 of the
residual).  Measured against the reference: objectives within 1e-9 relative;
positions, velocities, torques within 1e-11 of their range; accelerations (the
Newton unknowns) within 2e-8 of their range with the pendulum's constraints.
"""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest

from tests.helpers.paths import DATA

RTOL, ATOL = 1e-6, 1e-8
RANGE_TOL = 1e-7  # unit-level outputs: fraction of the largest magnitude in the run


def _maker():
    spec = importlib.util.spec_from_file_location("make_panda_exudyn_reference", DATA / "make_panda_exudyn_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


MAKER = _maker()
REFERENCE = json.loads((DATA / "panda_exudyn_reference.json").read_text())


@pytest.fixture(scope="module")
def study_now():
    return MAKER.study_cases()


def test_study_objectives_match_the_reference(study_now):
    rows, _ = study_now
    assert [r["point"] for r in rows] == [r["point"] for r in REFERENCE["study"]]
    for now, ref in zip(rows, REFERENCE["study"]):
        assert now["objectives"].keys() == ref["objectives"].keys()
        for name, expected in ref["objectives"].items():
            assert now["objectives"][name] == pytest.approx(expected, rel=RTOL, abs=ATOL), (ref["point"], name)
        assert now["objectives"]["limit_violated"] == ref["objectives"]["limit_violated"]


def test_recorded_trace_matches_the_reference(study_now):
    _, trace = study_now
    ref = REFERENCE["trace"]
    np.testing.assert_array_equal(trace["time"], ref["time"])  # the same communication points
    for signal in MAKER.TRACE_SIGNALS:
        np.testing.assert_allclose(trace[signal], ref[signal], rtol=RTOL, atol=ATOL, err_msg=signal)


@pytest.mark.parametrize("case, params", [("unit_defaults", {}), ("unit_pendulum", MAKER.PENDULUM)])
def test_unit_driven_directly_matches_the_reference(case, params):
    now, ref = MAKER.unit_case(params), REFERENCE[case]
    assert [a["t"] for a in now["samples"]] == [b["t"] for b in ref["samples"]]
    assert [a["limit_violated"] for a in now["samples"]] == [b["limit_violated"] for b in ref["samples"]]
    for name in MAKER.UNIT_OUTPUTS:
        got = np.array([a[name] for a in now["samples"]], dtype=float)
        expected = np.array([b[name] for b in ref["samples"]], dtype=float)
        scale = np.abs(expected).max()
        np.testing.assert_allclose(got, expected, rtol=0.0, atol=RANGE_TOL * scale, err_msg=f"{case} {name}")


def test_newton_jacobian_is_exudyns_own_when_fresh_and_serves_only_systems_without_constraints():
    """NewtonJacobian builds the Jacobian Exudyn builds itself (at a refresh), and the unit uses it without a pendulum."""
    import exudyn as exu

    from cosim.models.panda_exudyn import DEFAULT_KD, DEFAULT_KP, NewtonJacobian, PandaExudyn, build_kinematic_tree
    from cosim.models.panda_model import cached_model

    model = cached_model()
    q0, qd0 = np.array([0.3, -0.5, 0.2, -1.8, 0.1, 1.4, 0.6]), np.array([0.4, -0.2, 0.3, 0.5, -0.6, 0.2, 0.9])
    _, mbs, _, tree = build_kinematic_tree(model, q0, qd0)
    mbs.SetObjectParameter(tree, "jointPControlVector", list(DEFAULT_KP))
    mbs.SetObjectParameter(tree, "jointDControlVector", list(DEFAULT_KD))
    settings = exu.SimulationSettings()
    settings.solution.file.write = False
    settings.timeIntegration.numberOfSteps = 1
    settings.timeIntegration.endTime = 0.002
    solver = exu.MainSolverImplicitSecondOrder()
    solver.InitializeSolver(mbs, settings)
    assert solver.SolveSteps(mbs, settings)  # a step: mass matrix and step size as in a run
    solver.ComputeNewtonJacobian(mbs, settings)  # Exudyn's own (no user function registered)
    exudyns = solver.GetSystemJacobian()
    solver.SetSystemJacobian(np.zeros_like(exudyns))  # so that only NewtonJacobian can put it back
    ours = NewtonJacobian()
    assert ours(solver, mbs, settings)
    np.testing.assert_allclose(solver.GetSystemJacobian(), exudyns, rtol=1e-12, atol=1e-12 * np.abs(exudyns).max())
    assert np.abs(exudyns - exudyns.T).max() > 1e-6  # not a trivially symmetric matrix (damping, Coriolis)

    unit = PandaExudyn("robot")
    unit.setup(0.0, None)
    unit.exit_initialization()
    assert isinstance(unit._jacobian, NewtonJacobian)
    unit.reset()
    unit.set_values(MAKER.PENDULUM)
    unit.setup(0.0, None)
    unit.exit_initialization()
    assert unit._jacobian is None  # constraints: Exudyn's own Jacobian
