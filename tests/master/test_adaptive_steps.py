"""The adaptive master algorithm (cosim.master.adaptive): steps chosen by an estimate of the coupling error.

A damped oscillator ``x' = v, v' = -k x - c v`` split into two units that exchange position and velocity
(``linear_ode`` FMUs built from our C sources, or Python units): every unit integrates exactly for its held
input, so whatever differs from the matrix exponential is the coupling's error, which the algorithm controls.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from cosim.errors import SpecError
from cosim.execution.point import run_point
from cosim.spec.loader import load_spec, spec_from_dict
from cosim.system.builder import build_system
from tests.helpers.tools import python_unit

K, C = 4 * math.pi ** 2, 0.5  # 1 Hz, lightly damped
A = np.array([[0.0, 1.0], [-K, -C]])
X0 = np.array([1.0, 0.0])


def oscillator(position: dict, velocity: dict, experiment: dict) -> dict:
    """The spec: 'pos' integrates v (a=0, b=1), 'vel' integrates -k x - c v (a=-c, b=-k)."""
    return {"units": {"pos": {**position, "parameters": {"a": 0.0, "b": 1.0, "x0": X0[0]}},
                      "vel": {**velocity, "parameters": {"a": -C, "b": -K, "x0": X0[1]}}},
            "connections": [{"from": "vel.y", "to": "pos.u"}, {"from": "pos.y", "to": "vel.u"}],
            "experiment": {"stop": 2.0, **experiment}, "record": ["pos.y", "vel.y"]}


def run(spec: dict, tmp_path, units=None):
    system = build_system(spec_from_dict(spec, tmp_path / "spec.json"))
    return run_point(system, record=True, units=units), system


def states(result) -> tuple[np.ndarray, np.ndarray]:
    return result.traces["time"].to_numpy(), result.traces[["pos.y", "vel.y"]].to_numpy()


def flow(h: np.ndarray, x: np.ndarray) -> np.ndarray:
    """expm(A h_i) @ x_i for every row (A's eigenvectors: one vectorised product instead of an expm per step)."""
    values, vectors = np.linalg.eig(A)
    inverse = np.linalg.inv(vectors)
    return np.real(np.einsum("ij,nj,jk,nk->ni", vectors, np.exp(np.outer(h, values)), inverse, x))


def exact(t: np.ndarray) -> np.ndarray:
    """The oscillator's states at the times ``t`` from X0."""
    return flow(np.asarray(t), np.tile(X0, (len(t), 1)))


def local_errors(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Per accepted step, |computed - exact flow from the computed start| for each state (the error the step added)."""
    return np.abs(x[1:] - flow(np.diff(t), x[:-1]))


@pytest.fixture(params=[2, 3], ids=["fmi2", "fmi3"])
def fmu(request, built_fmu):
    return {"fmu": str(built_fmu("linear_ode", request.param))}


def test_fmu_steps_stay_within_the_tolerance_of_the_exact_solution(fmu, tmp_path):
    rtol, atol = 1e-4, 1e-8
    result, _ = run(oscillator(fmu, fmu, {"step": 0.01, "algorithm": "adaptive",
                                          "adaptive": {"rtol": rtol, "atol": atol}}), tmp_path)
    assert result.ok, result.message
    t, x = states(result)
    solution = exact(t)
    size = np.abs(solution).max(axis=0)  # rtol is relative to each signal's largest magnitude
    # what the controller promises: the error each accepted step adds is within atol + rtol * |signal|
    added = local_errors(t, x)
    assert np.all(added <= 1.2 * (atol + rtol * size)), added.max(axis=0) / (atol + rtol * size)
    # and most of the allowance is used: the steps are not needlessly small
    assert np.max(added / (atol + rtol * size)) > 0.3
    stats = result.step_stats
    assert stats["estimate"] == "step doubling" and stats["accepted"] == result.steps == len(t) - 1
    assert t[-1] == 2.0 and np.all(np.diff(t) > 0)
    assert stats["smallest"] == pytest.approx(np.diff(t).min()) and stats["largest"] == pytest.approx(np.diff(t).max())
    # the run's error: the sum of what the steps added, carried by a stable system (no more than their sum)
    assert np.abs(x - solution).max() <= np.linalg.norm(added, axis=1).sum()
    assert np.abs(x - solution).max() < 0.01 * size.max()
    # a tighter tolerance takes more, smaller steps and ends closer to the exact solution
    finer, _ = run(oscillator(fmu, fmu, {"step": 0.01, "algorithm": "adaptive",
                                         "adaptive": {"rtol": rtol / 10, "atol": atol}}), tmp_path)
    tf, xf = states(finer)
    assert finer.steps > 2 * result.steps
    assert np.abs(xf - exact(tf)).max() < 0.5 * np.abs(x - solution).max()


def test_a_step_too_long_is_rejected_restored_and_repeated(fmu, tmp_path):
    """The first step (0.5 s, half a period) is far too long: it is taken, rejected, the units' saved
    FMU states restored, and repeated shorter; only accepted steps are recorded."""
    rtol, atol = 1e-3, 1e-8
    result, _ = run(oscillator(fmu, fmu, {"step": 0.5, "algorithm": "adaptive",
                                          "adaptive": {"rtol": rtol, "atol": atol}}), tmp_path)
    assert result.ok, result.message
    stats = result.step_stats
    assert stats["rejected"] >= 1 and stats["exceeded"] == 0
    t, x = states(result)
    assert t[1] < 0.5 / 4  # the recorded first step is the repeated, shorter one
    assert stats["base_steps"] == 3 * (stats["accepted"] + stats["rejected"])  # a try: one step and two halves
    size = np.abs(exact(t)).max(axis=0)
    assert np.all(local_errors(t, x) <= 1.2 * (atol + rtol * size))


def test_python_units_restore_their_own_state_through_get_state(tmp_path):
    """A Python unit with get_state/set_state is restored, the state it keeps outside its variables too."""
    unit = {"python": python_unit("RestorableLinearOde")}
    spec = oscillator(unit, unit, {"step": 0.5, "algorithm": "adaptive", "adaptive": {"rtol": 1e-3, "atol": 1e-8}})
    system = build_system(spec_from_dict(spec, tmp_path / "spec.json"))
    units = {name: su.unit_type.instantiate(name) for name, su in system.units.items()}
    try:
        result = run_point(system, record=True, units=units)
    finally:
        for u in units.values():
            u.terminate()
    assert result.ok, result.message
    stats = result.step_stats
    assert stats["estimate"] == "step doubling" and stats["rejected"] >= 1
    # every accepted step kept its two half steps; the full-length tries and the rejected ones were undone
    assert units["pos"].steps_kept == units["vel"].steps_kept == 2 * stats["accepted"]
    # the same numbers as the FMUs' (the same exact integration, the same controller)
    t, x = states(result)
    assert np.abs(x - exact(t)).max() < 0.05


def test_without_restore_the_controller_only_adapts_the_next_step(fmu, tmp_path):
    """A unit that cannot restore its state (a Python unit without get_state) or restore 'never': no step is
    repeated; a step over the tolerance is kept and counted, and the next one is shorter."""
    plain = {"python": python_unit("LinearOde")}
    rtol, atol = 1e-2, 1e-8
    for position, options in ((plain, {}), (fmu, {"restore": "never"})):
        result, _ = run(oscillator(position, fmu, {"step": 0.2, "algorithm": "adaptive",
                                                   "adaptive": {"rtol": rtol, "atol": atol, **options}}), tmp_path)
        assert result.ok, result.message
        stats = result.step_stats
        assert stats["estimate"] == "signal change" and stats["rejected"] == 0
        assert stats["exceeded"] >= 1
        t, x = states(result)
        assert t[1] == pytest.approx(0.2)  # the first step could not be repeated: it is kept
        assert t[2] - t[1] < 0.2 / 2  # and the next is shorter
        assert stats["base_steps"] == stats["accepted"]
        # the estimate: how far each exchanged signal moves within one step stays near rtol of its size
        size = np.abs(exact(t)).max(axis=0)
        change = np.abs(np.diff(x, axis=0))[5:] / (atol + rtol * size)  # once the controller caught up
        assert change.max() < 2 and np.median(change.max(axis=1)) > 0.3


def test_fixed_step_runs_are_unchanged_and_carry_no_statistics(fmu, tmp_path):
    spec = oscillator(fmu, fmu, {"step": 0.01})
    result, _ = run(spec, tmp_path)
    assert result.step_stats is None and result.steps == 200
    t, _ = states(result)
    assert np.array_equal(t, [k * 0.01 for k in range(200)] + [2.0])  # whole steps counted: t_k = start + k h


def test_fmu_states_save_and_restore_directly(fmu, built_fmu, tmp_path):
    """The C framework's get/set FMU state: a restored FMU repeats a step bit for bit."""
    system = build_system(spec_from_dict(oscillator(fmu, fmu, {"step": 0.1}), tmp_path / "spec.json"))
    unit = system.units["vel"].unit_type.instantiate("vel")
    try:
        assert unit.can_save_state
        unit.setup(0.0, 2.0)
        unit.enter_initialization()
        unit.exit_initialization()
        u = unit.select(list(system.connections[1].target.refs))  # vel.u
        y = unit.select(list(system.connections[0].source.refs))  # vel.y
        unit.set(u, [1.0])
        unit.do_step(0.0, 0.1)
        state = unit.save_state()
        unit.do_step(0.1, 0.1)
        after = unit.get(y)
        unit.set(u, [5.0])
        unit.do_step(0.2, 0.3)
        assert unit.get(y) != after
        unit.restore_state(state)
        unit.set(u, [1.0])
        unit.do_step(0.1, 0.1)
        assert unit.get(y) == after
        assert unit.save_state(state) is state  # a saved state's storage is reused
        unit.free_state(state)
    finally:
        unit.terminate()


def test_model_exchange_units_do_not_claim_to_restore(built_fmu, tmp_path):
    """A Model Exchange unit's CVode state is not in the FMU state: the adaptive algorithm only adapts."""
    from cosim.fmus.build import ensure_built

    me = {"fmu": str(ensure_built("linear_ode", 2, interfaces=("ModelExchange",)))}
    cs = {"fmu": str(built_fmu("linear_ode", 2))}
    result, system = run(oscillator(cs, me, {"step": 0.05, "stop": 0.5, "algorithm": "adaptive",
                                             "adaptive": {"rtol": 1e-2}}), tmp_path)
    assert result.ok, result.message
    assert result.step_stats["estimate"] == "signal change"


@pytest.mark.parametrize("adaptive, path, words", [
    ({"rtol": 0, "atol": 0}, "$.experiment.adaptive", "both 0"),
    ({"min_step": 0.1, "max_step": 0.01}, "$.experiment.adaptive.min_step", "larger than max_step"),
    ({"rtol": -1}, "$.experiment.adaptive.rtol", "out of range"),
    ({"tolerance": 1e-3}, "$.experiment.adaptive.tolerance", "unknown field"),
    ({"restore": "sometimes"}, "$.experiment.adaptive.restore", "not allowed"),
])
def test_bad_options_are_reported_at_their_path(adaptive, path, words, tmp_path):
    unit = {"python": python_unit("LinearOde")}
    with pytest.raises(SpecError) as caught:
        spec_from_dict(oscillator(unit, unit, {"step": 0.1, "algorithm": "adaptive", "adaptive": adaptive}),
                       tmp_path / "spec.json")
    assert any(p.path == path and words in p.message for p in caught.value.problems), caught.value.problems


def test_options_without_the_adaptive_algorithm_are_refused(tmp_path):
    unit = {"python": python_unit("LinearOde")}
    with pytest.raises(SpecError) as caught:
        spec_from_dict(oscillator(unit, unit, {"step": 0.1, "adaptive": {"rtol": 1e-3}}), tmp_path / "spec.json")
    (problem,) = caught.value.problems
    assert problem.path == "$.experiment.adaptive" and "algorithm" in problem.fix


def test_cosim_run_prints_the_step_statistics(fmu, tmp_path):
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(oscillator(fmu, fmu, {"step": 0.5, "algorithm": "adaptive",
                                                     "adaptive": {"rtol": 1e-3, "max_step": 0.05}})))
    assert load_spec(path).experiment.adaptive == (("max_step", 0.05), ("rtol", 1e-3))
    out = subprocess.run([sys.executable, "-m", "cosim", "run", str(path)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    line = next(line for line in out.stdout.splitlines() if line.startswith("adaptive steps"))
    assert "step doubling" in line and "rejected and repeated" in line
    accepted = int(line.split(": ", 1)[1].split(" accepted")[0])
    assert f"status: ok; {accepted} steps to t=2 s" in out.stdout
    largest = float(line.split(" .. ")[1].split(" s")[0])
    assert largest <= 0.05


def test_jacobi_as_the_base_algorithm_and_stop_when(fmu, tmp_path):
    """Each step taken by Jacobi (also first-order: the same estimate holds), and stop_when ends the run at the
    first accepted step where the signal says so."""
    rtol, atol = 1e-4, 1e-8
    result, _ = run(oscillator(fmu, fmu, {"step": 0.01, "algorithm": "adaptive",
                                          "adaptive": {"rtol": rtol, "atol": atol, "base": "jacobi"}}), tmp_path)
    assert result.ok and result.step_stats["base"] == "jacobi"
    t, x = states(result)
    size = np.abs(exact(t)).max(axis=0)
    assert np.all(local_errors(t, x) <= 1.2 * (atol + rtol * size))

    clock = {"python": python_unit("Clock"), "parameters": {"t_end": 0.5}}
    spec = oscillator(fmu, fmu, {"step": 0.01, "algorithm": "adaptive", "adaptive": {"rtol": 1e-3},
                                 "stop_when": "clock.done"})
    spec["units"]["clock"] = clock
    stopped, _ = run(spec, tmp_path)
    assert stopped.ok, stopped.message
    assert 0.5 <= stopped.end_time < 0.6 and stopped.step_stats["accepted"] == stopped.steps


def never_accepted(fault_fmu: str, adaptive: dict | None = None, restore: str = "auto") -> dict:
    """A fault FMU whose output turns NaN at t = 0.3 (mode 4), fed into a second one: no step after it can meet
    any tolerance.  Before the bound, steps shrank to 1e-9 of the span and the run took ~10^9 of them."""
    return {"units": {"bad": {"fmu": fault_fmu, "parameters": {"mode": 4, "trigger_time": 0.3}},
                      "sink": {"fmu": fault_fmu}},
            "connections": [{"from": "bad.y", "to": "sink.u"}],
            "experiment": {"stop": 1.0, "step": 0.01, "algorithm": "adaptive",
                           "adaptive": {"restore": restore, **(adaptive or {})}}}


@pytest.mark.parametrize("restore", ["auto", "never"])
def test_steps_never_accepted_end_the_run_as_failed_naming_them(built_fmu, tmp_path, restore):
    fault = str(built_fmu("fault", 2))
    result, _ = run(never_accepted(fault, restore=restore), tmp_path)
    assert not result.ok and result.failure == "unit", result.message
    # the default min_step: 1e-3 * rtol (1e-4) * step (0.01 s): 1e-9 s; the run ends after 101 tries in a row that missed
    assert "adaptive steps at t=0.3" in result.message, result.message
    assert "101 tries in a row missed the tolerance (rtol 0.0001, atol 1e-06; max_rejected 100)" in result.message
    assert "(min_step 1e-09 s)" in result.message and "the exchanged signal bad.y is nan" in result.message
    assert "raise max_rejected in experiment.adaptive" in result.message
    assert result.end_time == pytest.approx(0.3, abs=0.2)  # where the NaN came, not 10^9 steps later
    # a bound of one's own: max_rejected 5 ends it after 6
    result, _ = run(never_accepted(fault, {"max_rejected": 5, "min_step": 1e-4}, restore), tmp_path)
    assert "6 tries in a row missed the tolerance" in result.message and "(min_step 0.0001 s)" in result.message


def test_cosim_run_of_steps_never_accepted_ends_with_exit_1(built_fmu, tmp_path):
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(never_accepted(str(built_fmu("fault", 3)))))
    out = subprocess.run([sys.executable, "-m", "cosim", "run", str(path)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 1, (out.returncode, out.stdout, out.stderr)
    assert "101 tries in a row missed the tolerance" in out.stdout + out.stderr
    assert "Traceback" not in out.stderr


@pytest.mark.parametrize("adaptive, path, words", [
    ({"max_rejected": 0}, "$.experiment.adaptive.max_rejected", "out of range"),
    ({"max_rejected": 10 ** 9}, "$.experiment.adaptive.max_rejected", "out of range"),
])
def test_a_bad_max_rejected_is_reported_at_its_path(adaptive, path, words, tmp_path):
    unit = {"python": python_unit("LinearOde")}
    with pytest.raises(SpecError) as caught:
        spec_from_dict(oscillator(unit, unit, {"step": 0.1, "algorithm": "adaptive", "adaptive": adaptive}),
                       tmp_path / "spec.json")
    assert any(p.path == path and words in p.message for p in caught.value.problems), caught.value.problems


FLIP = """
from cosim import PythonUnit, Variable

class Flip(PythonUnit):
    # its output changes sign at every step, however short: no step meets a tolerance
    variables = (Variable("y", "output", start=1.0),)

    def do_step(self, t, h):
        self.y = -self.y

    def get_state(self):  # restorable: the output is a variable, restored with the others
        return None

    def set_state(self, state):
        pass
"""


@pytest.mark.parametrize("restore", ["auto", "never"])
def test_a_discontinuous_unit_ends_its_run_instead_of_taking_a_billion_steps(built_fmu, tmp_path, restore):
    """Before the bound: step doubling rejected every step down to min_step (1e-9 of the span), kept each one
    there over the tolerance, and `cosim run` went on for ~10^9 steps, silent (killed here after 120 s)."""
    (tmp_path / "flip.py").write_text(FLIP)
    spec = {"units": {"flip": {"python": "flip.py:Flip"}, "sink": {"fmu": str(built_fmu("fault", 2))}},
            "connections": [{"from": "flip.y", "to": "sink.u"}],
            "experiment": {"stop": 10.0, "step": 0.1, "algorithm": "adaptive", "adaptive": {"restore": restore}}}
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(spec))
    out = subprocess.run([sys.executable, "-m", "cosim", "run", str(path)], capture_output=True, text=True,
                         timeout=120)
    said = out.stdout + out.stderr
    assert out.returncode == 1, (out.returncode, said)
    assert "adaptive steps at t=" in said, said
    assert float(said.split("adaptive steps at t=")[1].split(":")[0]) < 1.0  # soon, not at the stop time (10 s)
    assert "101 tries in a row missed the tolerance" in said and "the exchanged signal farthest off is flip.y" in said
    assert "(min_step 1e-08 s)" in said  # 1e-3 * rtol (1e-4) * step (0.1 s)
