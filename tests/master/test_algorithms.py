"""Master algorithm semantics and the execution loop, with small in-memory units."""

from __future__ import annotations

import numpy as np
import pytest

from cosim import Execution, build_system, load_spec
from cosim.master.contract import step_count
from tests.helpers.tools import python_unit


def chain_spec(algorithm: str, step: float = 0.1, stop: float = 1.0) -> dict:
    return {
        "units": {"gain": {"python": python_unit("Gain"), "parameters": {"k": 3.0}},
                  "clock": {"python": python_unit("Clock"), "parameters": {"t_end": 10.0}}},
        "connections": [{"from": "clock.time", "to": "gain.u"}],
        "experiment": {"stop": stop, "step": step, "algorithm": algorithm},
        "record": ["gain.y", "clock.time"],
        "objectives": {"y": {"signal": "gain.y", "reduce": "final"}},
    }


def run(write_spec, spec: dict, **kwargs):
    system = build_system(load_spec(write_spec(spec)))
    return system, Execution(system, record=True, **kwargs).run()


def test_gauss_seidel_steps_sources_first_and_passes_new_values(write_spec):
    system, result = run(write_spec, chain_spec("gauss-seidel"))
    assert system.order == ("clock", "gain")  # the source goes first although listed second
    traces = result.traces
    # the gain sees the clock's value at the end of the same step: y(t) = 3 t
    np.testing.assert_allclose(traces["gain.y"], 3.0 * traces["time"], atol=1e-12)


def test_jacobi_uses_values_from_the_start_of_the_step(write_spec):
    # an integrator (dx/dt = u, exact for u held over the step) fed by the clock: under Jacobi it steps from the
    # clock's value at the start of each step, y(k h) = h * sum_{j<k} j h; Gauss-Seidel gives it the value at the end
    spec = chain_spec("jacobi")
    spec["units"]["integ"] = {"python": python_unit("LinearOde"), "parameters": {"a": 0.0, "b": 1.0, "x0": 0.0}}
    spec["connections"].append({"from": "clock.time", "to": "integ.u"})
    spec["record"].append("integ.y")
    _, result = run(write_spec, spec)
    h, k = 0.1, np.arange(11)
    np.testing.assert_allclose(result.traces["integ.y"], h * h * k * (k - 1) / 2, atol=1e-12)
    # the feed-through gain's output is read after its input was set: y(t) = 3 u(t) = 3 t in every row
    np.testing.assert_allclose(result.traces["gain.y"], 3.0 * result.traces["time"], atol=1e-12)
    spec["experiment"]["algorithm"] = "gauss-seidel"
    _, result = run(write_spec, spec)
    np.testing.assert_allclose(result.traces["integ.y"], h * h * k * (k + 1) / 2, atol=1e-12)


def test_jacobi_traces_show_inputs_consistent_with_the_outputs_at_each_time(write_spec):
    # issue 25 item 8: the row at t shows gain.u = clock.time at t (not at t - h), the stop time included;
    spec = chain_spec("jacobi", step=0.3, stop=1.0)
    spec["record"].append("gain.u")
    _, result = run(write_spec, spec)
    traces = result.traces
    np.testing.assert_allclose(traces["time"], [0, 0.3, 0.6, 0.9, 1.0], atol=1e-15)
    np.testing.assert_allclose(traces["gain.u"], traces["time"], atol=1e-15)
    np.testing.assert_allclose(traces["gain.y"], 3.0 * traces["time"], atol=1e-12)  # y = k u, read after u was set


def test_jacobi_delayed_adds_a_step_of_delay_at_each_link_between_feedthrough_units(write_spec):
    # clock -> gain (k = 3) -> gain2 (k = 2): every output is read before any input is set, so gain2 sees
    # gain's output from before gain's input was set: gain2.y(t) = 6 (t - h) after the first step
    spec = chain_spec("jacobi-delayed")
    spec["units"]["gain2"] = {"python": python_unit("Gain"), "parameters": {"k": 2.0}}
    spec["connections"].append({"from": "gain.y", "to": "gain2.u"})
    spec["record"].append("gain2.y")
    _, result = run(write_spec, spec)
    t = result.traces["time"]
    np.testing.assert_allclose(result.traces["gain2.y"].iloc[1:], 6.0 * (t.iloc[1:] - 0.1), atol=1e-12)
    assert result.traces["gain2.y"].iloc[0] == 0.0  # initialization sets every input in dependency order


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_jacobi_sets_direct_feedthrough_inputs_in_dependency_order(write_spec, algorithm):
    # the same chain under Jacobi: gain2's input is set after gain's, at every communication point: 6 t, as GS
    spec = chain_spec(algorithm)
    spec["units"]["gain2"] = {"python": python_unit("Gain"), "parameters": {"k": 2.0}}
    spec["connections"].append({"from": "gain.y", "to": "gain2.u"})
    spec["record"].append("gain2.y")
    _, result = run(write_spec, spec)
    np.testing.assert_allclose(result.traces["gain2.y"], 6.0 * result.traces["time"], atol=1e-12)


def test_time_does_not_drift_over_many_steps(write_spec):
    _, result = run(write_spec, chain_spec("gauss-seidel", step=1e-3, stop=100.0))
    assert result.steps == 100_000
    times = result.traces["time"].to_numpy()
    # t_k = k*h exactly as floating point allows; summing h 100 000 times would drift ~1e-10
    np.testing.assert_array_equal(times, np.arange(100_001) * 1e-3)
    assert result.end_time == 100.0


@pytest.mark.parametrize("start,stop,h,n", [(0, 1, 0.1, 10), (0, 1, 0.3, 4), (0.5, 2.0, 0.5, 3), (0, 1e-3, 1e-3, 1)])
def test_step_count_includes_a_shorter_last_step(start, stop, h, n):
    assert step_count(start, stop, h) == n


def test_last_step_is_shortened_to_hit_stop(write_spec):
    _, result = run(write_spec, chain_spec("gauss-seidel", step=0.3, stop=1.0))
    np.testing.assert_allclose(result.traces["time"], [0, 0.3, 0.6, 0.9, 1.0], atol=1e-15)


def test_stop_when_ends_the_run_early(write_spec):
    spec = chain_spec("gauss-seidel")
    spec["units"]["clock"]["parameters"]["t_end"] = 0.45
    spec["experiment"]["stop_when"] = "clock.done"
    _, result = run(write_spec, spec)
    assert result.ok and result.steps == 5 and result.end_time == pytest.approx(0.5)


def test_reductions_match_the_recorded_trace(write_spec):
    spec = chain_spec("gauss-seidel", step=0.01, stop=2.0)
    spec["record"].append("clock.vec")
    spec["objectives"] = {
        "final": {"signal": "clock.vec[3]", "reduce": "final"},
        "initial": {"signal": "clock.time", "reduce": "initial"},
        "min": {"signal": "clock.vec[3]", "reduce": "min"},
        "max": {"signal": "clock.vec", "reduce": "max"},
        "mean": {"signal": "clock.time", "reduce": "mean"},
        "integral": {"signal": "gain.y", "reduce": "integral"},
        "integral_abs": {"signal": "clock.vec[3]", "reduce": "integral_abs"},
        "rms": {"signal": "clock.time", "reduce": "rms"},
        "t_max": {"signal": "clock.time", "reduce": "time_of_max"},
        "t_min": {"signal": "clock.vec[3]", "reduce": "time_of_min"},
        "ratio": {"expr": "integral / max(max) + sqrt(abs(min)) * 0"},
    }
    _, result = run(write_spec, spec)
    o = result.objectives
    assert o["final"] == pytest.approx(-2.0)
    assert o["initial"] == 0.0
    assert o["min"] == pytest.approx(-2.0)
    assert [o["max[1]"], o["max[2]"], o["max[3]"]] == pytest.approx([2.0, 4.0, 0.0])
    assert o["mean"] == pytest.approx(1.0)           # mean of t over [0, 2]
    assert o["integral"] == pytest.approx(6.0)       # integral of 3t over [0, 2], exact for trapezoids
    assert o["integral_abs"] == pytest.approx(2.0)
    assert o["rms"] == pytest.approx(np.sqrt(4 / 3), rel=1e-4)
    assert o["t_max"] == pytest.approx(2.0) and o["t_min"] == pytest.approx(2.0)
    assert o["ratio"] == pytest.approx(6.0 / 4.0)


def test_a_failing_unit_gives_a_failed_result_naming_unit_and_time(write_spec):
    spec = {
        "units": {"bad": {"python": python_unit("Failing"), "parameters": {"fail_at": 0.25}}},
        "experiment": {"stop": 1.0, "step": 0.1},
        "objectives": {"y": {"signal": "bad.y", "reduce": "final"}},
    }
    _, result = run(write_spec, spec)
    assert result.status == "failed"
    assert "unit 'bad' at t=0.3" in result.message and "do_step raised RuntimeError: boom" in result.message
    assert result.steps == 3


def test_nan_objective_marks_the_run_failed(write_spec):
    spec = chain_spec("gauss-seidel")
    spec["objectives"]["bad"] = {"expr": "y * 0 / 0"}
    _, result = run(write_spec, spec)
    assert result.status == "failed" and "bad" in result.message
