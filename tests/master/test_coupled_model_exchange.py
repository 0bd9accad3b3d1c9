"""Connected Model Exchange FMUs integrated together by one solver (issue 26, item 2).

A two-mass oscillator split into two Model Exchange FMUs (fmus/mass_spring, built
from our C sources): the left mass on its wall spring, driven by the coupling
force the right FMU computes from the left mass's position and velocity.  As one
system, its exact solution is the matrix exponential of the 4x4 system matrix.
Integrated together (the default), cosim matches it to the solver's tolerance
at any communication step; integrated one by one (the old behaviour, now an
opt-out), the values exchanged at communication points make it percents off.

Events of members: a stop that reflects the right mass (a state event in one
member; the exact solution is the matrix exponential between contacts, located
here by root finding on it), and a square wave's switches (time events) and a
trip (a step event) in a member feeding another.

Tolerance: CVode keeps each step's local error below rtol * |x| + atol (atol =
rtol: nominals are 1); over the oscillations of a run these add up, so bounds are
a stated multiple of rtol times the amplitude, with the measured error beside it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm
from scipy.optimize import brentq

from cosim import Execution, build_system, load_spec
from cosim.errors import SpecError
from cosim.units.fmu.coupled_me import CoupledModelExchange

RTOL = 1e-8
M1, M2, K1, K2, KC, DC = 1.0, 2.0, 10.0, 20.0, 1000.0, 0.5
X0 = np.array([1.0, 0.0, 0.0, 0.0])  # x1, v1, x2, v2: the left mass displaced, all at rest
A = np.array([[0.0, 1.0, 0.0, 0.0],
              [-(K1 + KC) / M1, -DC / M1, KC / M1, DC / M1],
              [0.0, 0.0, 0.0, 1.0],
              [KC / M2, DC / M2, -(K2 + KC) / M2, -DC / M2]])
COLUMNS = ["left.x", "left.v", "right.x", "right.v"]


def oscillator(left: int = 2, right: int = 2, step: float = 1e-3, stop: float = 1.0, **right_parameters) -> dict:
    """The two-mass oscillator as a spec: FMI versions of the two halves, communication step, stop time."""
    return {
        "units": {
            "left": {"fmu": f"builtin:mass_spring_fmi{left}", "tolerance": RTOL,
                     "parameters": {"m": M1, "k": K1, "x0": X0[0]}},
            "right": {"fmu": f"builtin:mass_spring_fmi{right}", "tolerance": RTOL,
                      "parameters": {"m": M2, "k": K2, "kc": KC, "dc": DC, **right_parameters}},
        },
        "connections": [{"from": "left.x", "to": "right.x_in"}, {"from": "left.v", "to": "right.v_in"},
                        {"from": "right.F_c", "to": "left.F"}],
        "experiment": {"stop": stop, "step": step},
        "record": COLUMNS + ["right.hits", "right.t_hit"],
    }


def run(write_spec, spec: dict, name: str = "spec.json"):
    system = build_system(load_spec(write_spec(spec, name)))
    result = Execution(system, record=True).run()
    assert result.ok, result.message
    return system, result.traces


EIGENVALUES, EIGENVECTORS = np.linalg.eig(A)


def flow(times: np.ndarray, state: np.ndarray) -> np.ndarray:
    """expm(A t) @ state for every t (rows), through A's eigen-decomposition (checked against expm below)."""
    weights = np.linalg.solve(EIGENVECTORS, state)
    return np.real((np.exp(np.outer(times, EIGENVALUES)) * weights) @ EIGENVECTORS.T)


def exact(times: np.ndarray) -> np.ndarray:
    return flow(np.asarray(times, dtype=float), X0)


def test_the_reference_is_the_matrix_exponential():
    times = np.array([0.0, 0.013, 0.5, 2.0])
    assert np.max(np.abs(exact(times) - np.array([expm(A * t) @ X0 for t in times]))) < 1e-12


def position_error(traces) -> float:
    """Largest error of the two positions against the exact solution, relative to the largest displacement."""
    times = traces["time"].to_numpy()
    reference = exact(times)
    got = traces[COLUMNS].to_numpy()
    return float(np.max(np.abs(got[:, [0, 2]] - reference[:, [0, 2]])) / np.max(np.abs(reference[:, [0, 2]])))


@pytest.mark.parametrize("left,right", [(2, 2), (3, 3), (2, 3)], ids=["fmi2", "fmi3", "fmi2+fmi3"])
def test_two_mass_oscillator_in_two_fmus_matches_the_matrix_exponential(write_spec, left, right):
    system, traces = run(write_spec, oscillator(left, right))
    assert [g.members for g in system.model_exchange.groups] == [("left", "right")]
    assert system.model_exchange.order == ("left+right",)
    error = position_error(traces)
    # Measured 6.4e-7 at rtol 1e-8 (a stiff coupling spring: ~6 periods of the fast mode in 1 s): the bound is
    # 1000 * rtol of the amplitude; one by one, the old way, it is 0.13 off after 0.5 s (below).
    assert error < 1000 * RTOL
    full = np.max(np.abs(traces[COLUMNS].to_numpy() - exact(traces["time"].to_numpy())))
    assert full < 1000 * RTOL * np.max(np.abs(traces[COLUMNS].to_numpy()))  # velocities too


def test_together_the_communication_step_does_not_matter(write_spec):
    """The coupling is inside the solver: with 10 ms steps the error stays at the solver's size (measured 2.2e-6;
    1 ms: 6.4e-7), where one by one it grows with the communication step."""
    _, coarse = run(write_spec, oscillator(step=1e-2), "coarse.json")
    assert position_error(coarse) < 1000 * RTOL


def test_opting_out_integrates_each_alone_as_before(write_spec):
    spec = oscillator(stop=0.5)
    _, together = run(write_spec, spec, "together.json")
    spec["experiment"]["coupled_model_exchange"] = False
    system, alone = run(write_spec, spec, "alone.json")
    assert system.model_exchange.groups == () and system.model_exchange.order == system.order
    error_alone, error_together = position_error(alone), position_error(together)
    # values exchanged at 1 ms communication points only, held in between: measured 0.13 of the amplitude
    # after 0.5 s (together: 6e-7)
    assert error_alone > 1e-2 > 1e4 * error_together
    per_unit = oscillator(stop=0.5)
    per_unit["units"]["right"]["coupled_model_exchange"] = False  # one unit opting out leaves no group
    system, one_out = run(write_spec, per_unit, "one_out.json")
    assert system.model_exchange.groups == ()
    assert np.array_equal(one_out[COLUMNS].to_numpy(), alone[COLUMNS].to_numpy())


def contacts(x_stop: float, e_stop: float, stop: float) -> tuple[list[float], np.ndarray]:
    """The exact contact times of the right mass with its stop, and the state at ``stop``.

    Between contacts the state is expm(A (t - t_k)) X_k; a contact is the first root of x2(t) = x_stop
    (found on a 0.1 ms grid, then by Brent's method), where v2 := -e v2 and x2 := x_stop.
    """
    t_k, state, times = 0.0, X0.copy(), []
    while True:
        grid = np.arange(t_k + 1e-4, stop + 1e-4, 1e-4)
        below = np.nonzero(flow(grid - t_k, state)[:, 2] > x_stop)[0]
        if not len(below) or grid[below[0]] > stop:
            return times, flow(np.array([stop - t_k]), state)[0]
        start = state
        found = brentq(lambda t: flow(np.array([t - t_k]), start)[0, 2] - x_stop, grid[below[0]] - 1e-4,
                       grid[below[0]], xtol=1e-14)
        state = flow(np.array([found - t_k]), state)[0]
        state[2], state[3] = x_stop, -e_stop * state[3]
        t_k = found
        times.append(found)


@pytest.mark.parametrize("version", [2, 3])
def test_a_state_event_in_one_member_is_located_and_handled(write_spec, version):
    x_stop, e_stop, stop = 0.1, 0.8, 2.5
    times, final = contacts(x_stop, e_stop, stop)
    assert len(times) == 4  # at 0.021, 1.042, 2.059, 2.097 s
    _, traces = run(write_spec, oscillator(version, version, step=0.01, stop=stop, x_stop=x_stop, e_stop=e_stop))
    assert traces["right.hits"].iloc[-1] == len(times)
    assert traces["right.t_hit"].iloc[-1] == pytest.approx(times[-1], abs=1e-5)  # measured 4e-7
    assert np.max(traces["right.x"].to_numpy()) <= x_stop + 1e-6
    got = traces[COLUMNS].iloc[-1].to_numpy()
    # after four contacts, each located as accurately as the solution allows: measured 3.2e-5 of the amplitude
    assert np.max(np.abs(got - final)) < 1e4 * RTOL * np.max(np.abs(final))


def square_lag_reference(times: np.ndarray, tau: float, period: float, a: float) -> np.ndarray:
    """y at ``times`` for y' = a y + x, x' = (s - x)/tau, s the square wave (1 in the first half of each period,
    0 in the second): solve_ivp at rtol 1e-12, half period by half period (the switches are breakpoints)."""
    edges = np.arange(0.0, times[-1] + period / 2, period / 2)
    y, state = np.empty(len(times)), np.zeros(2)
    for k, (start, end) in enumerate(zip(edges[:-1], edges[1:])):
        s = 1.0 if k % 2 == 0 else 0.0
        solution = solve_ivp(lambda _t, z, s=s: [(s - z[0]) / tau, a * z[1] + z[0]], (start, end), state,
                             rtol=1e-12, atol=1e-14, dense_output=True)
        inside = (times >= start) & (times <= end)
        y[inside] = solution.sol(times[inside])[1]
        state = solution.y[:, -1]
    return y


@pytest.mark.parametrize("version", [2, 3])
def test_time_events_of_a_member_reach_the_member_it_feeds(write_spec, version):
    tau, period, a = 0.1, 0.2, -2.0
    spec = {
        "units": {
            "lag": {"fmu": f"builtin:square_lag_fmi{version}", "tolerance": RTOL,
                    "parameters": {"tau": tau, "period": period}},
            "ode": {"fmu": f"builtin:linear_ode_fmi{version}", "interface": "model-exchange", "tolerance": RTOL,
                    "parameters": {"a": a, "b": 1.0, "x0": 0.0}},
        },
        "connections": [{"from": "lag.x", "to": "ode.u"}],
        "experiment": {"stop": 0.75, "step": 0.03},  # switches every 0.1 s fall inside communication steps
        "record": ["lag.x", "lag.switches", "ode.y"],
    }
    system, traces = run(write_spec, spec)
    assert [g.members for g in system.model_exchange.groups] == [("lag", "ode")]
    times = traces["time"].to_numpy()
    assert traces["lag.switches"].iloc[-1] == 7  # at 0.1, 0.2, ..., 0.7
    error = np.max(np.abs(traces["ode.y"].to_numpy() - square_lag_reference(times, tau, period, a)))
    assert error < 1000 * RTOL  # measured 1.6e-8: u follows the lag between communication points, not held
    spec["experiment"]["coupled_model_exchange"] = False
    _, alone = run(write_spec, spec, "alone.json")
    # one by one, u is held over each step: measured 7.6e-3
    assert np.max(np.abs(alone["ode.y"].to_numpy() - square_lag_reference(times, tau, period, a))) > 1e-3


def test_a_step_event_of_a_member_is_handled_in_the_group(write_spec):
    """square_lag trips (a step event, after a completed integrator step) once x exceeds x_trip; in the group
    the trip comes at most one communication step (the solver's largest step) after the exact crossing."""
    tau, x_trip, step = 0.1, 0.5, 0.01
    spec = {
        "units": {
            "lag": {"fmu": "builtin:square_lag_fmi3", "tolerance": RTOL,
                    "parameters": {"tau": tau, "period": 10.0, "x_trip": x_trip}},
            "ode": {"fmu": "builtin:linear_ode_fmi3", "interface": "model-exchange", "tolerance": RTOL,
                    "parameters": {"a": 0.0, "b": 1.0, "x0": 0.0}},
        },
        "connections": [{"from": "lag.s", "to": "ode.u"}],  # ode.y integrates the square wave: the trip time
        "experiment": {"stop": 0.3, "step": step},
        "record": ["lag.tripped", "lag.t_trip", "ode.y"],
    }
    _, traces = run(write_spec, spec)
    crossing = -tau * math.log(1 - x_trip)  # x = 1 - e^{-t/tau} reaches x_trip
    t_trip = traces["lag.t_trip"].iloc[-1]
    assert bool(traces["lag.tripped"].iloc[-1]) and crossing <= t_trip <= crossing + step
    assert traces["ode.y"].iloc[-1] == pytest.approx(t_trip, abs=1e-6)  # s = 1 exactly until the trip, then 0


def test_a_group_between_other_units_steps_as_one_unit(write_spec):
    """A co-simulation unit reads the group's output; the group's unit is made from the live members."""
    spec = oscillator()
    spec["units"]["probe"] = {"fmu": "builtin:linear_ode_fmi2", "parameters": {"a": 0.0, "b": 1.0, "x0": 0.0}}
    spec["connections"].append({"from": "right.x", "to": "probe.u"})
    spec["record"].append("probe.y")
    system, traces = run(write_spec, spec)
    assert system.model_exchange.order == ("left+right", "probe")
    # probe.y = h x the sum of right.x at the ends of the steps (Gauss-Seidel: the group steps first, and the
    # CS FMU integrates its input held over the step)
    h = spec["experiment"]["step"]
    right_x = traces["right.x"].to_numpy()
    assert traces["probe.y"].iloc[-1] == pytest.approx(h * np.sum(right_x[1:]), abs=1e-12)


def test_inspect_shows_the_group_in_the_stepping_order(write_spec, capsys):
    from cosim.cli.main import main

    assert main(["inspect", str(write_spec(oscillator()))]) == 0
    out = capsys.readouterr().out
    assert "stepping order: left+right\n" in out
    assert "integrated together (one solver): left+right = left, right" in out


def test_coupled_model_exchange_on_a_co_simulation_unit_is_refused(write_spec):
    spec = oscillator()
    spec["units"]["cs"] = {"fmu": "builtin:linear_ode_fmi2", "coupled_model_exchange": False}
    with pytest.raises(SpecError) as caught:
        build_system(load_spec(write_spec(spec)))
    problem, = [p for p in caught.value.problems if "coupled_model_exchange" in p.path]
    assert problem.path == "$.units.cs.coupled_model_exchange" and "model-exchange" in problem.fix


def test_a_member_refuses_to_step_alone(built_fmu):
    from cosim.units.fmu.description import FmuUnitType
    from cosim.units.protocol import UnitError

    member = FmuUnitType(built_fmu("mass_spring", 2)).instantiate("left")
    try:
        CoupledModelExchange("left+right", {"left": member}, [])
        with pytest.raises(UnitError, match="integrates together"):
            member.do_step(0.0, 0.1)
    finally:
        member.terminate()


def test_a_sweep_integrates_the_group_in_dask_workers(write_spec, tmp_path):
    """Two points of the oscillator with a stop, swept on a Dask worker (each point in a child process, the
    system pickled there, members re-used after reset): each point's contacts as the exact solution has them."""
    import cosim

    spec = oscillator(step=0.01, stop=1.2, e_stop=0.8)
    spec["objectives"] = {"hits": {"signal": "right.hits", "reduce": "final"},
                          "last_hit": {"signal": "right.t_hit", "reduce": "final"}}
    spec["design"] = {"parameters": {"right.x_stop": {"values": [0.05, 0.1]}}}
    df = cosim.sweep(str(write_spec(spec)), workers=1, out=tmp_path / "out")
    assert list(df["status"]) == ["ok", "ok"]
    for x_stop, hits, last_hit in zip(df["right.x_stop"], df["hits"], df["last_hit"]):
        times, _ = contacts(x_stop, 0.8, 1.2)
        assert hits == len(times) and last_hit == pytest.approx(times[-1], abs=1e-5)


@pytest.mark.parametrize("version", [2, 3])
def test_a_member_ending_the_simulation_ends_the_run_at_its_event(write_spec, version):
    """A bouncing ball (state events; terminateSimulation once at rest) feeds its height to an integrator:
    the run ends at the resting bounce, and the integral of the height over the flights is the exact one."""
    g, e, h0, v_min = 9.81, 0.7, 1.0, 0.1
    spec = {
        "units": {
            "ball": {"fmu": f"builtin:bouncing_ball_fmi{version}", "tolerance": RTOL,
                     "parameters": {"g": g, "e": e, "h0": h0, "v_min": v_min, "stop_at_rest": True}},
            "area": {"fmu": f"builtin:linear_ode_fmi{version}", "interface": "model-exchange", "tolerance": RTOL,
                     "parameters": {"a": 0.0, "b": 1.0, "x0": 0.0}},
        },
        "connections": [{"from": "ball.h", "to": "area.u"}],
        "experiment": {"stop": 5.0, "step": 0.05},
        "objectives": {"area": {"signal": "area.y", "reduce": "final"},
                       "bounces": {"signal": "ball.bounces", "reduce": "final"}},
    }
    system = build_system(load_spec(write_spec(spec)))
    assert [g.members for g in system.model_exchange.groups] == [("ball", "area")]
    result = Execution(system).run()
    assert result.ok and "stopped early: unit 'ball' ended the simulation" in result.message, result.message
    t1 = math.sqrt(2 * h0 / g)  # the drop, then flights launched at e^k * g t1 until one is slower than v_min
    times, area, v = [t1], h0 * t1 - g * t1 ** 3 / 6, g * t1
    while e * v >= v_min:
        v *= e
        flight = 2 * v / g
        area += v * flight ** 2 / 2 - g * flight ** 3 / 6
        times.append(times[-1] + flight)
    assert result.end_time == pytest.approx(times[-1], abs=1e-6)
    assert result.objectives["bounces"] == len(times)
    assert result.objectives["area"] == pytest.approx(area, abs=1e-6)


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_an_input_from_outside_reaches_the_member_through_the_group(write_spec, algorithm):
    """A constant force on the right mass from a co-simulation unit (set through the group's port
    right.F): the exact solution is the matrix exponential of the system with the force as a fifth state."""
    force = 30.0
    spec = oscillator(step=0.01, stop=1.0)
    spec["units"]["push"] = {"fmu": "builtin:linear_ode_fmi3", "parameters": {"a": 0.0, "b": 0.0, "x0": force}}
    spec["connections"].append({"from": "push.y", "to": "right.F"})
    spec["experiment"]["algorithm"] = algorithm
    system, traces = run(write_spec, spec)
    assert [g.members for g in system.model_exchange.groups] == [("left", "right")]
    forced = np.zeros((5, 5))
    forced[:4, :4], forced[3, 4] = A, 1.0 / M2  # der(v2) gets F / m2; the fifth state is the force, constant
    times = traces["time"].to_numpy()
    expected = np.array([expm(forced * t) @ np.append(X0, force) for t in times[::10]])[:, :4]
    got = traces[COLUMNS].to_numpy()[::10]
    assert np.max(np.abs(got - expected)) < 1000 * RTOL * np.max(np.abs(expected))


# -- an algebraic loop among the members, solved inside the group (issue 26 item 4) ----------------------------------

LA, LB = 0.5, 0.8  # coupling stiffnesses: F_c of each mass is the other's x_in, so the two forces form a loop


def looped(version: int, step: float = 1e-2) -> dict:
    """Two masses on wall springs; each one's coupling force F_c = kc (x - x_in) is the other's x_in (direct
    feed-through both ways: an algebraic loop among two Model Exchange units)."""
    return {"units": {"a": {"fmu": f"builtin:mass_spring_fmi{version}", "tolerance": RTOL,
                            "parameters": {"m": 1.0, "k": 4.0, "kc": LA, "x0": 1.0}},
                      "b": {"fmu": f"builtin:mass_spring_fmi{version}", "tolerance": RTOL,
                            "parameters": {"m": 2.0, "k": 9.0, "kc": LB, "v0": 0.5}}},
            # a force taken as a position (values passed as they are): no physics, but a loop with a closed form
            "connections": [{"from": "a.F_c", "to": "b.x_in", "convert": False},
                            {"from": "b.F_c", "to": "a.x_in", "convert": False}],
            "experiment": {"stop": 2.0, "step": step},
            "record": ["a.x", "a.v", "b.x", "b.v", "a.x_in", "b.x_in"]}


def looped_exact(times: np.ndarray) -> np.ndarray:
    """[xa, va, xb, vb] by the matrix exponential: the loop x_in_a = LB (xb - x_in_b), x_in_b = LA (xa - x_in_a)
    solved by hand, x_in_a = LB (xb - LA xa) / (1 - LA LB), then m v' = -k x - kc (x - x_in) for each mass."""
    in_a = np.array([-LA * LB, LB]) / (1 - LA * LB)  # x_in_a as a row over [xa, xb]
    in_b = LA * (np.array([1.0, 0.0]) - in_a)
    force_a = LA * (np.array([1.0, 0.0]) - in_a)
    force_b = LB * (np.array([0.0, 1.0]) - in_b)
    system = np.zeros((4, 4))
    system[0, 1] = system[2, 3] = 1.0
    system[1, [0, 2]] = (-4.0 * np.array([1.0, 0.0]) - force_a) / 1.0
    system[3, [0, 2]] = (-9.0 * np.array([0.0, 1.0]) - force_b) / 2.0
    return np.array([expm(system * t) @ np.array([1.0, 0.0, 0.0, 0.5]) for t in times])


@pytest.mark.parametrize("version", [2, 3])
def test_a_loop_among_the_members_is_solved_inside_the_group(write_spec, version):
    system, traces = run(write_spec, looped(version), f"looped{version}.json")
    assert [g.members for g in system.model_exchange.groups] == [("a", "b")]
    assert system.model_exchange.groups[0].coupling.loops  # solved by the group, at every right-hand side
    t = traces["time"].to_numpy()
    got = traces[["a.x", "a.v", "b.x", "b.v"]].to_numpy()
    reference = looped_exact(t)
    # integrated together: the solver's accuracy (rtol 1e-8), not a coupling error of the 10 ms step
    assert np.max(np.abs(got - reference)) < 1000 * RTOL * np.max(np.abs(reference))
    x_in_a, x_in_b = traces["a.x_in"].to_numpy(), traces["b.x_in"].to_numpy()
    xa, xb = got[:, 0], got[:, 2]
    # the loop holds at every recorded point, the start time included
    assert np.max(np.abs(x_in_a - LB * (xb - x_in_b))) < 1e-9 and np.max(np.abs(x_in_b - LA * (xa - x_in_a))) < 1e-9


def test_inspect_says_a_loop_is_solved_inside_its_group(write_spec, capsys):
    from cosim.cli.main import main

    assert main(["inspect", str(write_spec(looped(3), "inspect.json"))]) == 0
    out = capsys.readouterr().out
    assert "integrated together (one solver): a+b = a, b" in out and "loop through units a, b" in out
    assert "solved inside a+b at every evaluation of its equations" in out


def test_a_loop_inside_a_group_without_solution_fails_the_run_naming_the_loop(write_spec):
    # kc = 1 on both masses: x_in_a + x_in_b = x_b and = x_a, which no value meets while x_a != x_b
    spec = looped(2)
    spec["units"]["a"]["parameters"]["kc"] = spec["units"]["b"]["parameters"]["kc"] = 1.0
    system = build_system(load_spec(write_spec(spec, "singular.json")))
    assert system.model_exchange.groups[0].coupling.loops
    result = Execution(system).run()
    assert not result.ok and result.failure == "unit"
    assert "loop through units a, b" in result.message and "did not converge" in result.message
