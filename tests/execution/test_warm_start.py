"""Warm start (issue 26 item 5): ``"experiment": {"warm_start": T}`` runs once to T, saves every unit's state
(serialized: FMI serializeFMUstate, a Python unit's pickled get_state) and starts each point there.

The unit is a first-order lag ``x' = a x + b u`` (``linear_ode`` built from our C sources as FMI 2.0 and 3.0, and
its Python twin) with ``a`` and ``b`` tunable and u = 1 held: every step is exact, so a point that changes a and b
at T follows the closed form ``x(t) = x_T e^{a(t-T)} + (b/a)(e^{a(t-T)} - 1)`` to rounding; a point with the spec's
own values gives a run from the start time bit for bit, with half the steps.
"""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

import cosim
from cosim.errors import SpecError, UserError
from cosim.execution.point import run_point
from cosim.execution.warm_up import warm_up, warmed
from cosim.fmus.build import ensure_built
from cosim.spec.loader import spec_from_dict
from cosim.system.builder import build_system
from tests.helpers.tools import python_unit

A0, B0, T_WARM, STOP, STEP = -1.0, 1.0, 1.0, 2.0, 0.01


def lag_spec(source: dict, warm: float | None = T_WARM, **experiment) -> dict:
    return {"units": {"lag": {**source, "parameters": {"a": A0, "b": B0, "x0": 0.0}, "start": {"u": 1.0}}},
            "experiment": {"stop": STOP, "step": STEP, **({"warm_start": warm} if warm is not None else {}),
                           **experiment},
            "record": ["lag.y"],
            "objectives": {"y_end": {"signal": "lag.y", "reduce": "final"},
                           "y_integral": {"signal": "lag.y", "reduce": "integral"}}}


def system_of(spec: dict, tmp_path):
    return build_system(spec_from_dict(spec, tmp_path / "spec.json"))


def exact(t: np.ndarray, a: float, b: float) -> np.ndarray:
    """x(0) = 0 with (A0, B0) to T_WARM, then (a, b) from x(T_WARM); u = 1."""
    x_t = (B0 / A0) * math.expm1(A0 * T_WARM)
    before = (B0 / A0) * np.expm1(A0 * t)
    after = x_t * np.exp(a * (t - T_WARM)) + (b / a) * np.expm1(a * (t - T_WARM))
    return np.where(t <= T_WARM + 1e-12, before, after)


SOURCES = {"fmi2": lambda: {"fmu": str(ensure_built("linear_ode", 2))},
           "fmi3": lambda: {"fmu": str(ensure_built("linear_ode", 3))},
           "python": lambda: {"python": python_unit("TunableLinearOde")}}


@pytest.mark.parametrize("kind", SOURCES)
@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_spec_values_give_the_cold_run_bit_for_bit_in_half_the_steps(kind, algorithm, tmp_path):
    cold = run_point(system_of(lag_spec(SOURCES[kind](), None, algorithm=algorithm), tmp_path), record=True)
    warm = run_point(system_of(lag_spec(SOURCES[kind](), algorithm=algorithm), tmp_path), record=True)
    assert cold.ok and warm.ok, (cold.message, warm.message)
    assert warm.objectives == cold.objectives  # integral over the whole span: the warm-up's samples count
    assert warm.traces.equals(cold.traces)
    assert (cold.steps, warm.steps) == (200, 100)
    assert warm.objectives["y_end"] == pytest.approx(exact(np.array([STOP]), A0, B0)[0], abs=1e-13)


@pytest.mark.parametrize("kind", SOURCES)
def test_a_point_changes_tunable_parameters_at_the_warm_start(kind, tmp_path):
    system = warmed(system_of(lag_spec(SOURCES[kind]()), tmp_path))
    for a, b in [(-2.0, 3.0), (-0.5, -1.0)]:
        result = run_point(system, {"lag.a": a, "lag.b": b}, record=True)
        assert result.ok, result.message
        t, y = result.traces["time"].to_numpy(), result.traces["lag.y"].to_numpy()
        assert len(t) == 201 and t[100] == T_WARM
        assert np.max(np.abs(y - exact(t, a, b))) < 1e-13
        assert result.objectives["y_end"] == pytest.approx(exact(np.array([STOP]), a, b)[0], abs=1e-13)


def test_warm_started_points_do_half_the_work_measured_in_unit_steps(tmp_path):
    cold_system = system_of(lag_spec(SOURCES["python"](), None), tmp_path)
    unit_class = cold_system.units["lag"].unit_type.load_class()  # the class as cosim loaded it from its file
    unit_class.calls = 0
    cold = [run_point(cold_system, {"lag.b": b}) for b in (1.0, 2.0, 3.0, 4.0)]
    cold_calls, unit_class.calls = unit_class.calls, 0
    system = warmed(system_of(lag_spec(SOURCES["python"]()), tmp_path))  # the warm-up: 100 steps, once
    assert system.units["lag"].unit_type.load_class() is unit_class
    warm = [run_point(system, {"lag.b": b}) for b in (1.0, 2.0, 3.0, 4.0)]
    warm_calls = unit_class.calls
    assert (cold_calls, warm_calls) == (4 * 200, 100 + 4 * 100)
    assert all(r.ok for r in cold + warm)
    assert warm[0].objectives == cold[0].objectives  # b = 1: the spec's own value
    for b, result in zip((1.0, 2.0, 3.0, 4.0), warm):
        assert result.objectives["y_end"] == pytest.approx(exact(np.array([STOP]), A0, b)[0], abs=1e-13)


def test_two_coupled_fmus_warm_started_equal_the_cold_run(tmp_path):
    """An oscillator split into two linear_ode FMUs (FMI 2 and 3 mixed) exchanging position and velocity."""
    k, c = 4 * math.pi ** 2, 0.5
    spec = {"units": {"pos": {"fmu": str(ensure_built("linear_ode", 2)), "parameters": {"a": 0.0, "b": 1.0, "x0": 1.0}},
                      "vel": {"fmu": str(ensure_built("linear_ode", 3)), "parameters": {"a": -c, "b": -k, "x0": 0.0}}},
            "connections": [{"from": "vel.y", "to": "pos.u"}, {"from": "pos.y", "to": "vel.u"}],
            "experiment": {"stop": 2.0, "step": 1e-3}, "record": ["pos.y", "vel.y"],
            "objectives": {"x_max": {"signal": "pos.y", "reduce": "max"}}}
    cold = run_point(system_of(spec, tmp_path), record=True)
    spec["experiment"]["warm_start"] = 1.5
    warm = run_point(system_of(spec, tmp_path), record=True)
    assert cold.ok and warm.ok and (cold.steps, warm.steps) == (2000, 500)
    assert warm.traces.equals(cold.traces) and warm.objectives == cold.objectives


def test_the_warm_state_is_bytes_that_travel_to_another_process(tmp_path):
    system = system_of(lag_spec(SOURCES["fmi2"]()), tmp_path)
    state, result = warm_up(system)
    assert result.ok and state.time == T_WARM and state.steps == 100
    assert dict(state.states)["lag"][:1] and isinstance(dict(state.states)["lag"], bytes)
    assert pickle.loads(pickle.dumps(state)).states == state.states
    assert state.samples.shape == (101, 1) and state.samples[-1, 0] == pytest.approx(exact(np.array([T_WARM]), A0, B0)[0])


def test_a_sweep_ships_the_warm_state_to_its_workers(write_spec, local_cluster):  # noqa: F811
    spec = lag_spec(SOURCES["fmi3"]())
    spec["design"] = {"parameters": {"lag.b": {"values": [0.5, 1.0, 2.0]}, "lag.a": {"values": [-2.0, -1.0]}}}
    df = cosim.sweep(str(write_spec(spec)), scheduler=local_cluster, batch_size=2)
    assert list(df["status"]) == ["ok"] * 6
    for _, row in df.iterrows():
        assert row["y_end"] == pytest.approx(exact(np.array([STOP]), row["lag.a"], row["lag.b"])[0], abs=1e-13)


# -- what a warm start refuses, with the field and the fix ----------------------------------------------------------


@pytest.mark.parametrize("experiment, message", [
    ({"warm_start": 1.005}, "not a communication point"),
    ({"warm_start": 2.0}, "not between start"),
    ({"warm_start": -1.0}, "not between start"),
    ({"warm_start": 1.0, "algorithm": "adaptive"}, "fixed communication step"),
])
def test_a_warm_start_off_the_grid_or_span_or_with_adaptive_steps_is_refused(experiment, message, tmp_path):
    spec = lag_spec(SOURCES["fmi2"](), None, **experiment)
    with pytest.raises(SpecError) as info:
        spec_from_dict(spec, tmp_path / "spec.json")
    problem = info.value.problems[0]
    assert problem.path == "$.experiment.warm_start" and message in problem.message and problem.fix


def test_a_fixed_parameter_cannot_be_a_design_parameter_or_a_value(tmp_path):
    spec = lag_spec(SOURCES["fmi2"]())
    spec["design"] = {"parameters": {"lag.x0": {"values": [0.0, 1.0]}, "lag.b": {"values": [1.0, 2.0]}}}
    with pytest.raises(SpecError) as info:
        system_of(spec, tmp_path)
    [problem] = info.value.problems
    assert problem.path == "$.design.parameters['lag.x0']" or problem.path.endswith("lag.x0")
    assert "fixed parameter" in problem.message and "tunable" in problem.fix
    system = system_of(lag_spec(SOURCES["python"]()), tmp_path)
    with pytest.raises(SpecError, match="'lag.x0' is a .*parameter"):
        run_point(system, {"lag.x0": 2.0})
    assert run_point(system, {"lag.u": 2.0}).ok  # an input may change


@pytest.mark.parametrize("source, why", [
    ({"python": python_unit("LinearOde")}, "without get_state and set_state"),
    ({"fmu": str(ensure_built("linear_ode", 2, interfaces=("ModelExchange",)))}, "Model Exchange"),
])
def test_a_unit_that_cannot_save_its_state_is_named(source, why, tmp_path):
    spec = lag_spec(source)
    spec["units"]["lag"]["parameters"] = {"x0": 0.0}  # no tunable a and b here: nothing varied
    with pytest.raises(UserError) as info:
        warmed(system_of(spec, tmp_path))
    [problem] = info.value.problems
    assert problem.path == "$.experiment.warm_start" and "unit 'lag' cannot save" in problem.message
    assert why in problem.message and problem.fix


def test_a_state_that_does_not_pickle_fails_the_run_naming_the_unit(tmp_path):
    spec = lag_spec({"python": python_unit("UnpicklableState")})
    spec["units"]["lag"]["parameters"] = {"x0": 0.0}
    result = run_point(system_of(spec, tmp_path))
    assert not result.ok and "warm-up to t=1 failed" in result.message and "cannot be pickled" in result.message


def test_a_run_ending_before_the_warm_start_is_refused(tmp_path):
    spec = lag_spec(SOURCES["python"]())
    spec["units"]["clock"] = {"python": python_unit("RestorableEndsAtHalf")}
    with pytest.raises(UserError, match=r"ended at t=0\.5, before warm_start 1"):
        warmed(system_of(spec, tmp_path))


def test_cosim_run_says_where_the_run_started_and_refuses_a_fixed_parameter(write_spec, capsys):
    from cosim.cli.main import main

    path = str(write_spec(lag_spec(SOURCES["fmi2"]())))
    assert main(["run", path, "--set", "lag.b=3"]) == 0
    out = capsys.readouterr().out
    assert "100 steps from the warm start at t=1 s" in out and "to t=2 s" in out
    y_end = float(next(line.split()[1] for line in out.splitlines() if line.startswith("y_end")))
    assert y_end == pytest.approx(exact(np.array([STOP]), A0, 3.0)[0], rel=1e-5)  # printed to 6 digits
    assert main(["run", path, "--set", "lag.x0=3"]) == 2
    err = capsys.readouterr()
    assert "'lag.x0' is a fixed parameter" in err.err + err.out and "remove experiment.warm_start" in err.err + err.out


@pytest.mark.parametrize("mode, why", [(1, "died (killed by signal SIGSEGV)"), (3, "fmi2DoStep returned Error")])
def test_a_study_warm_up_that_crashes_or_fails_is_a_clear_error_not_a_dead_client(tmp_path, mode, why):
    """The `fault` FMU (our C sources) segfaults or fails at t >= 0.5, inside the warm-up to t = 1: the study's
    payload is made in this process, the warm-up in a child process, so this process lives and says why."""
    from cosim.parallel.isolation.payload import make_payload

    spec = lag_spec(SOURCES["fmi2"]())
    spec["units"]["fault"] = {"fmu": str(ensure_built("fault", 2)), "parameters": {"mode": mode, "trigger_time": 0.5}}
    system = system_of(spec, tmp_path)
    with pytest.raises(UserError) as info:
        make_payload(system)
    [problem] = info.value.problems
    assert problem.path == "$.experiment.warm_start" and "the warm-up run to t=1 failed" in problem.message
    assert why in problem.message and problem.fix


def test_a_study_names_the_unit_that_cannot_save_its_state_from_the_warm_up_child(tmp_path):
    from cosim.parallel.isolation.payload import make_payload

    spec = lag_spec({"python": python_unit("LinearOde")})
    spec["units"]["lag"]["parameters"] = {"x0": 0.0}
    with pytest.raises(UserError) as info:
        make_payload(system_of(spec, tmp_path))
    [problem] = info.value.problems
    assert problem.path == "$.experiment.warm_start" and "unit 'lag' cannot save and serialize" in problem.message


def test_a_hanging_warm_up_obeys_the_study_timeout(tmp_path):
    """The `fault` FMU hangs at t >= 0.5 inside the warm-up to t = 1: the study's timeout (--timeout; here 3 s)
    stops it; before, only COSIM_TIMEOUT_FIRST (600 s) did. The library names no command-line option."""
    import time

    from cosim.parallel.isolation.payload import make_payload

    spec = lag_spec(SOURCES["fmi2"]())
    spec["units"]["fault"] = {"fmu": str(ensure_built("fault", 2)), "parameters": {"mode": 2, "trigger_time": 0.5}}
    system = system_of(spec, tmp_path)
    began = time.monotonic()
    with pytest.raises(UserError) as info:
        make_payload(system, timeout=3.0)
    [problem] = info.value.problems
    assert problem.path == "$.experiment.warm_start", problem
    assert "the warm-up run to t=1 failed: it did not finish within 3 s (the study's timeout); it was stopped" in problem.message
    assert time.monotonic() - began < 120  # the child load and the 3 s, not 600 s


BIG_STATE = """
from cosim import PythonUnit, Variable

class BigState(PythonUnit):
    # a unit whose saved state is size_mb megabytes
    variables = (Variable("size_mb", "parameter", start=2.0), Variable("y", "output", start=0.0))

    def do_step(self, t, h):
        self.y = t + h

    def get_state(self):
        return b"x" * int(self.size_mb * (1 << 20))

    def set_state(self, state):
        pass
"""


def test_a_warm_state_over_the_channel_limit_names_the_limit_its_unit_and_the_fix(tmp_path, monkeypatch):
    """A 2 MB warm state under COSIM_CHILD_MESSAGE_MB=1 (the limit is 64 MB by default): a study's warm-up
    child could not send it and the study said "wrote something other than a result on its channel (bad message
    length)", while `cosim run` went on; both refuse it now with one message naming the limit, its unit (MB),
    the unit whose state it is and the fix."""
    from cosim.parallel.isolation.payload import make_payload

    (tmp_path / "big.py").write_text(BIG_STATE)
    spec = {"units": {"big": {"python": "big.py:BigState"}}, "experiment": {"stop": 1.0, "step": 0.1, "warm_start": 0.5},
            "objectives": {"y_end": {"signal": "big.y", "reduce": "final"}}}
    monkeypatch.setenv("COSIM_CHILD_MESSAGE_MB", "1")
    messages = []
    for how in (lambda system: warmed(system), lambda system: make_payload(system)):  # cosim run, a study
        with pytest.raises(UserError) as info:
            how(system_of(spec, tmp_path))
        [problem] = info.value.problems
        assert problem.path == "$.experiment.warm_start", problem
        messages.append((problem.message, problem.fix))
    assert messages[0] == messages[1], messages
    message, fix = messages[0]
    assert "the warm state at t=0.5 is 2.0 MB (unit 'big' saved 2.0 MB of it), more than the limit of 1 MB" in message
    assert "COSIM_CHILD_MESSAGE_MB=3 (megabytes)" in fix
    monkeypatch.setenv("COSIM_CHILD_MESSAGE_MB", "3")  # the fix works
    assert make_payload(system_of(spec, tmp_path))["system"]
