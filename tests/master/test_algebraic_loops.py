"""Algebraic loops solved at every communication point, and zero-delay feed-through under Jacobi (issue 26).

Every expected value is computed here from the units' equations (closed forms, or a bisection written here),
never by cosim.  The FMU cases use the `algebraic` and `linear_ode` FMUs built from src/cosim/fmus/.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import cosim
from cosim import Execution, build_system, load_spec
from cosim.master.contract import SystemView
from cosim.master.registry import make_algorithm
from tests.fmus.test_fmi_conformance import cli
from tests.helpers.tools import python_unit

DOTTIE = 0.7390851332151607  # the fixed point of cos: u = cos(u)


def _bisect(f, lo: float, hi: float) -> float:
    """A root of f in [lo, hi] (f changes sign there), to the last bit."""
    flo = f(lo)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        if (f(mid) > 0) == (flo > 0):
            lo, flo = mid, f(mid)
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _run(write_spec, spec: dict, name: str = "spec.json"):
    system = build_system(load_spec(write_spec(spec, name)))
    return system, Execution(system, record=True).run()


def linear_loop(algorithm: str, units: str = "python") -> dict:
    """x = 2 + y/2 and y = -1 + 3x + t: x = -3 - t, y = -10 - 2t (fixed-point iteration diverges: gain 3/2).

    A clock drives t; a gain downstream reads x (z = 2x = -6 - 2t).
    """
    algebraic = {"python": python_unit("Algebraic")} if units == "python" else {"fmu": "builtin:algebraic_fmi2"}
    spec = {
        "units": {
            "clock": {"python": python_unit("Clock"), "parameters": {"t_end": 10.0}},
            "ux": {**algebraic, "parameters": {"c0": 2.0, "c1": 0.5}},
            "uy": {**algebraic, "parameters": {"c0": -1.0, "c1": 3.0}},
            "gain": {"python": python_unit("Gain"), "parameters": {"k": 2.0}},
        },
        "connections": [
            {"from": "uy.y", "to": "ux.u"},
            {"from": "ux.y", "to": "uy.u"},
            {"from": "clock.time", "to": "uy.w"},
            {"from": "ux.y", "to": "gain.u"},
        ],
        "experiment": {"stop": 1.0, "step": 0.1, "algorithm": algorithm},
        "record": ["ux.y", "uy.y", "gain.y"],
    }
    return spec


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
@pytest.mark.parametrize("units", ["python", "fmu"])
def test_a_linear_loop_of_two_units_meets_its_closed_form_at_every_communication_point(write_spec, algorithm, units):
    system, result = _run(write_spec, linear_loop(algorithm, units))
    assert result.ok, result.message
    (loop,) = system.coupling.loops
    assert loop.units == ("ux", "uy") and len(loop.tearing) == 1  # one cut closes the loop
    t = result.traces["time"].to_numpy()
    assert len(t) == 11 and t[0] == 0.0  # the start time too: the loop is solved at initialization
    np.testing.assert_allclose(result.traces["ux.y"], -3.0 - t, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(result.traces["uy.y"], -10.0 - 2.0 * t, rtol=1e-12, atol=1e-12)
    # the unit downstream of the loop sees the solution, at the same communication point
    np.testing.assert_allclose(result.traces["gain.y"], -6.0 - 2.0 * t, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("version", [2, 3])
def test_a_nonlinear_loop_through_fmus_is_solved_to_1e_10(write_spec, version):
    """x = cos(y), y = x^3 through two `algebraic` FMUs: x = cos(x^3) (one root in [0, 1])."""
    fmu = f"builtin:algebraic_fmi{version}"
    spec = {
        "units": {"ux": {"fmu": fmu, "parameters": {"c1": 0.0, "a": 1.0}},
                  "uy": {"fmu": fmu, "parameters": {"c1": 0.0, "c3": 1.0}}},
        "connections": [{"from": "uy.y", "to": "ux.u"}, {"from": "ux.y", "to": "uy.u"}],
        "experiment": {"stop": 0.3, "step": 0.1},
        "record": ["ux.y", "uy.y", "ux.u", "uy.u"],
    }
    _, result = _run(write_spec, spec)
    assert result.ok, result.message
    x_exact = _bisect(lambda x: x - math.cos(x ** 3), 0.0, 1.0)
    traces = result.traces
    x, y = traces["ux.y"].to_numpy(), traces["uy.y"].to_numpy()
    assert np.all(np.abs(x - x_exact) < 1e-10) and np.all(np.abs(y - x_exact ** 3) < 1e-10)
    # the equations themselves hold at every communication point, on what the units output
    assert np.all(np.abs(x - np.cos(y)) < 1e-10) and np.all(np.abs(y - x ** 3) < 1e-10)


@pytest.mark.parametrize("unit", [{"fmu": "builtin:algebraic_fmi3"}, {"python": python_unit("Algebraic")}],
                         ids=["fmu", "python"])
def test_a_unit_feeding_its_own_input_is_solved(write_spec, unit):
    """y = cos(u) with y -> u: u = cos(u), the Dottie number."""
    spec = {"units": {"c": {**unit, "parameters": {"c1": 0.0, "a": 1.0}}},
            "connections": [{"from": "c.y", "to": "c.u"}],
            "experiment": {"stop": 0.2, "step": 0.1}, "record": ["c.y"]}
    system, result = _run(write_spec, spec)
    assert result.ok, result.message
    assert [loop.tearing for loop in system.coupling.loops] == [("c.u",)]
    np.testing.assert_allclose(result.traces["c.y"], DOTTIE, rtol=0, atol=1e-10)


def test_fixed_point_alone_fails_a_loop_it_cannot_contract_naming_the_loop_and_residual(write_spec):
    spec = linear_loop("gauss-seidel")
    spec["experiment"]["loop_solver"] = {"method": "fixed-point", "max_iterations": 30}
    _, result = _run(write_spec, spec)
    assert result.status == "failed" and result.failure == "unit"
    assert result.steps == 0  # at initialization already, and no hang
    message = result.message
    assert "algebraic loop through units ux, uy (tearing " in message
    assert "at t=0" in message and "did not converge: largest residual" in message
    assert "after 30 fixed-point iteration(s)" in message
    # the same loop with Newton (the default) converges
    spec["experiment"].pop("loop_solver")
    _, result = _run(write_spec, spec, "newton.json")
    assert result.ok, result.message


def test_a_loop_without_solution_is_a_failed_row_not_a_hang(write_spec):
    """x = y + 1 and y = x have no solution: the residual stays 1 whatever Newton or fixed-point try."""
    spec = {"units": {"ux": {"python": python_unit("Algebraic"), "parameters": {"c0": 1.0}},
                      "uy": {"python": python_unit("Algebraic")}},
            "connections": [{"from": "uy.y", "to": "ux.u"}, {"from": "ux.y", "to": "uy.u"}],
            "experiment": {"stop": 1.0, "step": 0.1, "loop_solver": {"max_iterations": 20}}}
    _, result = _run(write_spec, spec)
    assert result.status == "failed"
    assert "algebraic loop through units ux, uy (tearing ux.u)" in result.message
    assert "largest residual 1 (tolerance 1e-10)" in result.message
    assert "0 Newton iteration(s) (singular Jacobian), then 20 fixed-point iteration(s)" in result.message


def test_the_run_command_reports_the_failed_loop(capsys, write_spec):
    spec = linear_loop("jacobi")
    spec["experiment"]["loop_solver"] = {"method": "fixed-point"}
    code, text = cli(capsys, "run", str(write_spec(spec)))
    assert code == 1 and "algebraic loop through units ux, uy" in text and "Traceback" not in text


def chain_spec(algorithm: str) -> dict:
    """A plant (linear_ode FMU, state) fed back through sensor -> controller -> limiter, all direct feed-through:
    sensor = 2 x + 0.1 and controller = 1 - 3 sensor (`algebraic` FMUs), limiter = clip(controller, -1, 1)."""
    return {
        "units": {
            "plant": {"fmu": "builtin:linear_ode_fmi2", "parameters": {"a": -0.5, "b": 2.0, "x0": 1.0}},
            "sensor": {"fmu": "builtin:algebraic_fmi2", "parameters": {"c0": 0.1, "c1": 2.0}},
            "controller": {"fmu": "builtin:algebraic_fmi3", "parameters": {"c0": 1.0, "c1": -3.0}},
            "limiter": {"python": python_unit("Saturation"), "parameters": {"lo": -1.0, "hi": 1.0}},
        },
        "connections": [
            {"from": "plant.y", "to": "sensor.u"},
            {"from": "sensor.y", "to": "controller.u"},
            {"from": "controller.y", "to": "limiter.u"},
            {"from": "limiter.y", "to": "plant.u"},
        ],
        "experiment": {"stop": 2.0, "step": 0.05, "algorithm": algorithm},
        "record": ["plant.y", "sensor.y", "controller.y", "limiter.y"],
    }


def test_a_feedthrough_chain_under_jacobi_equals_gauss_seidel_at_every_communication_point(write_spec):
    _, gauss_seidel = _run(write_spec, chain_spec("gauss-seidel"), "gs.json")
    _, jacobi = _run(write_spec, chain_spec("jacobi"), "jacobi.json")
    _, delayed = _run(write_spec, chain_spec("jacobi-delayed"), "delayed.json")
    assert gauss_seidel.ok and jacobi.ok and delayed.ok
    columns = ["plant.y", "sensor.y", "controller.y", "limiter.y"]
    np.testing.assert_allclose(jacobi.traces[columns], gauss_seidel.traces[columns], rtol=1e-14, atol=1e-14)
    # independently: the plant integrates exactly over each step with the limited control held
    h, x = 0.05, 1.0
    for k, row in gauss_seidel.traces.iterrows():
        u = min(max(1.0 - 3.0 * (2.0 * x + 0.1), -1.0), 1.0)
        assert row["plant.y"] == pytest.approx(x, rel=1e-12) and row["limiter.y"] == pytest.approx(u, rel=1e-12)
        e = math.exp(-0.5 * h)
        x = e * x + (e - 1.0) / -0.5 * 2.0 * u
    # the old behaviour, by name: each of the three links adds one step of delay, and the result differs
    assert not np.allclose(delayed.traces["plant.y"], gauss_seidel.traces["plant.y"], rtol=1e-6)


def test_systems_without_loops_step_as_before(write_spec):
    """No loop: Gauss-Seidel keeps its plain step (no loop solver, nothing solved after a unit's step); Jacobi
    without direct feed-through sets every input before stepping and propagates nothing (the loop machinery is
    not in the stepping loop at all)."""
    spec = {"units": {"one": {"fmu": "builtin:linear_ode_fmi2"}, "two": {"fmu": "builtin:linear_ode_fmi2"}},
            "connections": [{"from": "one.y", "to": "two.u"}, {"from": "two.y", "to": "one.u"}],
            "experiment": {"stop": 0.1, "step": 0.1}}
    system = build_system(load_spec(write_spec(spec)))
    assert system.coupling.blocks == ()
    units = {name: u.unit_type.instantiate(name) for name, u in system.units.items()}
    try:
        view = SystemView(units, system.order, system.connections, system.coupling)
        gauss_seidel = make_algorithm("gauss-seidel", system.spec.experiment)
        gauss_seidel.bind(view)
        assert gauss_seidel._loops is None and gauss_seidel._solve_after is None
        jacobi = make_algorithm("jacobi", system.spec.experiment)
        jacobi.bind(view)
        assert jacobi._coupling is None and len(jacobi._transfers) == 2
    finally:
        for unit in units.values():
            unit.terminate()


def test_inspect_shows_the_loops_and_their_tearing_variables(capsys, write_spec):
    code, text = cli(capsys, "inspect", str(write_spec(linear_loop("gauss-seidel"))))
    assert code == 0, text
    assert "algebraic loops: 1 (solved by newton, tolerance 1e-10, at most 50 iterations)" in text
    assert "  loop through units ux, uy: tearing ux.u (1 value); ports ux.u, ux.y, uy.u, uy.y" in text
    no_loop = chain_spec("jacobi")
    code, text = cli(capsys, "inspect", str(write_spec(no_loop, "chain.json")))
    assert code == 0 and "algebraic loops: none" in text


def test_loops_that_cannot_be_solved_are_refused_by_validate(capsys, write_spec):
    integer = {"units": {"n": {"python": python_unit("Counter")}},
               "connections": [{"from": "n.n", "to": "n.n_in"}],
               "experiment": {"stop": 1.0, "step": 0.1}}
    code, text = cli(capsys, "validate", str(write_spec(integer)))
    assert code == 2
    assert ("$.connections: algebraic loop through units n (ports n.n, n.n_in) carries values that are not Real: "
            "n.n -> n.n_in (Integer); only loops of Real signals are solved") in text
    delayed = linear_loop("jacobi-delayed")
    code, text = cli(capsys, "validate", str(write_spec(delayed, "delayed.json")))
    assert code == 2
    assert ("$.experiment.algorithm: algebraic loop through units ux, uy (ports ux.u, ux.y, uy.u, uy.y): the master "
            "algorithm 'jacobi-delayed' does not solve algebraic loops") in text
    wrong = linear_loop("gauss-seidel")
    wrong["experiment"]["loop_solver"] = {"method": "broyden", "tolerance": 0}
    code, text = cli(capsys, "validate", str(write_spec(wrong, "wrong.json")))
    assert code == 2 and "$.experiment.loop_solver.method" in text and "$.experiment.loop_solver.tolerance" in text


def test_loop_settings_reach_the_solver(write_spec):
    spec = linear_loop("gauss-seidel")
    spec["experiment"]["loop_solver"] = {"tolerance": 1e-6, "max_iterations": 7}
    system = build_system(load_spec(write_spec(spec)))
    settings = system.coupling.settings
    assert (settings.method, settings.tolerance, settings.max_iterations) == ("newton", 1e-6, 7)
    assert cosim.run(str(write_spec(spec, "again.json"))).ok


def test_a_sweep_point_whose_loop_has_no_solution_is_a_failed_row(write_spec):
    """x = 2 + c y, y = x: x = 2/(1 - c); at c = 1 there is none (the residual stays 2). Real Dask, child process."""
    spec = {"units": {"ux": {"python": python_unit("Algebraic"), "parameters": {"c0": 2.0}},
                      "uy": {"python": python_unit("Algebraic")}},
            "connections": [{"from": "uy.y", "to": "ux.u"}, {"from": "ux.y", "to": "uy.u"}],
            "experiment": {"stop": 0.2, "step": 0.1},
            "objectives": {"x": {"signal": "ux.y", "reduce": "final"}},
            "design": {"parameters": {"ux.c1": {"values": [0.5, 1.0, -1.0]}}}}
    table = cosim.sweep(str(write_spec(spec)), workers=1, quiet=True)
    rows = {row["ux.c1"]: row for _, row in table.iterrows()}
    assert rows[0.5]["status"] == "ok" and rows[0.5]["x"] == pytest.approx(4.0, rel=1e-12)
    assert rows[-1.0]["status"] == "ok" and rows[-1.0]["x"] == pytest.approx(1.0, rel=1e-12)
    failed = rows[1.0]
    assert failed["status"] == "failed" and math.isnan(failed["x"])
    assert ("algebraic loop through units ux, uy (tearing ux.u) at t=0: did not converge: largest residual 2 "
            "(tolerance 1e-10)") in failed["message"]


def test_one_tearing_variable_where_one_input_lies_on_every_cycle(write_spec):
    """Two cycles b -> a -> b and b -> a -> c -> b share the input a.u: cutting the link into it alone breaks
    both (b, listed first, has two inputs on them, each on one cycle only).  a = b/2 + 1, c = a/2, b = a/4 + c:
    a = 1.6, b = 1.2, c = 0.8."""
    algebraic = python_unit("Algebraic")
    spec = {"units": {"b": {"python": algebraic, "parameters": {"c1": 0.25}},
                      "a": {"python": algebraic, "parameters": {"c0": 1.0, "c1": 0.5}},
                      "c": {"python": algebraic, "parameters": {"c1": 0.5}}},
            "connections": [{"from": "b.y", "to": "a.u"}, {"from": "a.y", "to": "b.u"},
                            {"from": "a.y", "to": "c.u"}, {"from": "c.y", "to": "b.w"}],
            "experiment": {"stop": 0.1, "step": 0.1}, "record": ["a.y", "b.y", "c.y"]}
    system, result = _run(write_spec, spec)
    (loop,) = system.coupling.loops
    assert loop.tearing == ("a.u",) and loop.units == ("b", "a", "c")
    assert result.ok, result.message
    final = result.traces.iloc[-1]
    assert (final["a.y"], final["b.y"], final["c.y"]) == pytest.approx((1.6, 1.2, 0.8), rel=1e-12)


@pytest.mark.parametrize("version", [2, 3])
def test_an_array_loop_with_an_offset_on_a_connection(write_spec, version):
    """gain_array FMUs (y = k u, 3 elements) in a loop whose connection adds 1: y1 = 2 y2, y2 = 3 (y1 + 1), so
    y1 = 6/(1 - 6) = -1.2 and y2 = -0.6 in every element; three tearing values, one Newton system."""
    fmu = f"builtin:gain_array_fmi{version}"
    spec = {"units": {"g1": {"fmu": fmu, "parameters": {"k": 2.0}}, "g2": {"fmu": fmu, "parameters": {"k": 3.0}}},
            "connections": [{"from": "g1.y", "to": "g2.u", "offset": 1.0}, {"from": "g2.y", "to": "g1.u"}],
            "experiment": {"stop": 0.2, "step": 0.1}, "record": ["g1.y", "g2.y"]}
    system, result = _run(write_spec, spec)
    assert result.ok, result.message
    (loop,) = system.coupling.loops
    assert sum(len(system.connections[i].target.refs) for i in loop.torn) == 3
    traces = result.traces
    for i in (1, 2, 3):
        np.testing.assert_allclose(traces[f"g1.y[{i}]"], -1.2, rtol=1e-12)
        np.testing.assert_allclose(traces[f"g2.y[{i}]"], -0.6, rtol=1e-12)


def test_an_algorithm_of_ones_own_runs_through_the_one_contract_and_is_refused_loops(write_spec, monkeypatch):
    """A master algorithm of one's own implements the contract (bind a view, advance from t and say where it
    got to) and is handed to Execution; it runs systems without loops, and the system check refuses a loop for
    an algorithm that does not say ``solves_loops``, naming it."""
    from cosim.master.algorithms import FixedStep
    from cosim.master.contract import step_unit
    from cosim.master.registry import ALGORITHMS
    from cosim.system.stepping import check_algebraic_loops

    class InOrder(FixedStep):
        name = "in-order"

        def bind(self, view):
            self.view = view
            self._units = [view.units[n] for n in view.order]

        def step(self, t, h):
            for unit in self._units:
                step_unit(unit, t, h)

    spec = {"units": {"clock": {"python": python_unit("Clock")}}, "experiment": {"stop": 0.3, "step": 0.1},
            "record": ["clock.time"]}
    system = build_system(load_spec(write_spec(spec)))
    result = Execution(system, record=True, algorithm=InOrder(system.spec.experiment)).run()
    assert result.ok, result.message
    np.testing.assert_allclose(result.traces["clock.time"], [0.0, 0.1, 0.2, 0.3], atol=1e-15)
    monkeypatch.setitem(ALGORITHMS, "in-order", InOrder)
    system = build_system(load_spec(write_spec(linear_loop("gauss-seidel"), "loop.json")))
    problems: list = []
    check_algebraic_loops(system.units, list(system.connections), problems, "spec.json", system.coupling, "in-order")
    assert [p.path for p in problems] == ["$.experiment.algorithm"]
    assert "the master algorithm 'in-order' does not solve algebraic loops" in problems[0].message


# -- Newton's Jacobian from the FMUs' directional derivatives (issue 26 item 1) --------------------------------------


def _bound_solver(write_spec, spec: dict, jacobian: str):
    """The loop solver of ``spec``'s one loop, bound to its initialized units (FMUs built from our C sources)."""
    from cosim.master.loops import LoopSettings, LoopSolver

    system = build_system(load_spec(write_spec(spec, f"{jacobian}.json")))
    units = {name: su.unit_type.instantiate(name) for name, su in system.units.items()}
    for unit in units.values():
        unit.setup(0.0, 1.0)
    for a in system.assignments:
        units[a.unit].set(units[a.unit].select(a.refs), list(a.values))
    for unit in units.values():
        unit.enter_initialization()
        unit.exit_initialization()
    (loop,) = system.coupling.loops
    return loop, units, LoopSolver(loop, units, system.connections, LoopSettings(jacobian=jacobian))


def _nonlinear(version: int) -> dict:
    fmu = f"builtin:algebraic_fmi{version}"
    return {"units": {"ux": {"fmu": fmu, "parameters": {"c1": 0.0, "a": 1.0}},
                      "uy": {"fmu": fmu, "parameters": {"c1": 0.0, "c3": 1.0}}},
            "connections": [{"from": "uy.y", "to": "ux.u"}, {"from": "ux.y", "to": "uy.u", "factor": 0.5}],
            "experiment": {"stop": 0.3, "step": 0.1}, "record": ["ux.y", "uy.y"]}


@pytest.mark.parametrize("version", [2, 3])
def test_the_jacobian_from_directional_derivatives_is_the_exact_one(write_spec, version):
    """x = cos(y), y = (x/2)^3 (the link halves x): the residual's derivative at the tearing value, computed here by
    hand, against the one the FMUs' derivatives give (exact) and finite differences give (to about 1e-7)."""
    loop, units, exact_solver = _bound_solver(write_spec, _nonlinear(version), "auto")
    _, fd_units, fd_solver = _bound_solver(write_spec, _nonlinear(version), "finite-differences")
    assert exact_solver.derivatives is not None and fd_solver.derivatives is None
    x = np.array([0.6])
    g, g_fd = exact_solver._evaluate(x), fd_solver._evaluate(x)
    assert g == pytest.approx(g_fd, abs=0)
    if loop.tearing == ("ux.u",):  # G(u) = (cos(u) / 2)^3
        expected = 3 * (math.cos(0.6) / 2) ** 2 * (-math.sin(0.6) / 2) - 1
        assert g[0] == pytest.approx((math.cos(0.6) / 2) ** 3, abs=1e-15)
    else:  # tearing uy.u: G(u) = cos(u^3) / 2
        expected = -math.sin(0.6 ** 3) * 3 * 0.6 ** 2 / 2 - 1
    evaluations = fd_solver.evaluations
    jac, jac_fd = exact_solver.jacobian_at(x, g), fd_solver.jacobian_at(x, g_fd)
    assert jac.shape == (1, 1) and jac[0, 0] == pytest.approx(expected, abs=1e-15)
    assert jac_fd[0, 0] == pytest.approx(expected, abs=1e-7) and jac_fd[0, 0] != jac[0, 0]
    # the cost: one derivative call per unit and loop input (2 FMU calls) against one evaluation of G per tearing
    # value (4 FMU calls: set the tearing input, get ux.y, set uy.u, get uy.y)
    assert exact_solver.derivatives.calls == 2 and fd_solver.evaluations - evaluations == 1
    for unit in (*units.values(), *fd_units.values()):
        unit.terminate()


@pytest.mark.parametrize("version", [2, 3])
def test_newton_with_directional_derivatives_solves_the_loop_with_fewer_fmu_calls(write_spec, version, monkeypatch):
    """The whole run, both ways: the same solution to the tolerance at every communication point, and fewer FMU
    calls with the derivatives (counted: 4 per evaluation of G, 1 per derivative call).  Newton keeps its Jacobian
    between communication points while it contracts, so few are made in a run (measured: 4570 against 4572 calls,
    FMI 2 and 3): the derivatives save their evaluations of G and make each Jacobian exact."""
    from cosim.master import loops

    made: list = []
    original = loops.LoopSolver.__init__

    def keep(self, *args, **kwargs):
        original(self, *args, **kwargs)
        made.append(self)

    monkeypatch.setattr(loops.LoopSolver, "__init__", keep)
    runs, calls = {}, {}
    for jacobian in ("auto", "finite-differences"):
        spec = _nonlinear(version)
        spec["experiment"].update(stop=2.0, step=0.01, loop_solver={"jacobian": jacobian})
        # a drive into ux.w moves the solution at every communication point, so Newton works at each
        spec["units"]["drive"] = {"fmu": "builtin:linear_ode_fmi2", "parameters": {"a": -2.0, "b": 0.0, "x0": 0.3}}
        spec["connections"].append({"from": "drive.y", "to": "ux.w"})
        _, runs[jacobian] = _run(write_spec, spec, f"{jacobian}.json")
        assert runs[jacobian].ok, runs[jacobian].message
        solver = made[-1]
        assert (solver.derivatives is not None) == (jacobian == "auto") and solver.jacobians > 0
        calls[jacobian] = 4 * solver.evaluations + (solver.derivatives.calls if solver.derivatives else 0)
    t = runs["auto"].traces["time"].to_numpy()
    w = 0.3 * np.exp(-2.0 * t)
    for run in runs.values():  # x = cos(y) + w, y = (x/2)^3 at every point, on what the FMUs output
        x, y = run.traces["ux.y"].to_numpy(), run.traces["uy.y"].to_numpy()
        assert np.max(np.abs(x - np.cos(y) - w)) < 1e-9 and np.max(np.abs(y - (x / 2) ** 3)) < 1e-9
    assert calls["auto"] < calls["finite-differences"]


def test_a_loop_whose_units_give_no_derivatives_keeps_finite_differences(write_spec):
    # gain_array: no directional derivatives declared (and arrays); the Python Algebraic unit: none at all
    loop, units, solver = _bound_solver(write_spec, linear_loop("gauss-seidel"), "auto")
    assert solver.derivatives is None
    for unit in units.values():
        unit.terminate()


@pytest.mark.parametrize("version", [2, 3])
def test_a_loop_through_a_model_exchange_unit_is_solved_at_every_communication_point(write_spec, version):
    """A mass on springs (`mass_spring`, Model Exchange, integrated by CVode inside each step) whose coupling
    force F_c = kc (x - x_in) feeds a gain (`algebraic`, y = u/2) back into x_in: a loop of direct feed-through
    through the ME unit.  At every communication point x_in = F_c / 2 = x - x_in, so x_in = x/2 (to the loop
    tolerance); between points x_in is held, so the mass follows x'' = -k x - kc (x - x_in) = -2x (x = cos(√2 t))
    with an error of first order in the step (it halves with the step)."""
    errors = []
    for step in (0.01, 0.005):
        spec = {"units": {"mass": {"fmu": f"builtin:mass_spring_fmi{version}",
                                   "parameters": {"m": 1.0, "k": 1.0, "kc": 2.0, "x0": 1.0}, "tolerance": 1e-10},
                          "gain": {"fmu": "builtin:algebraic_fmi2", "parameters": {"c1": 0.5}}},
                "connections": [{"from": "mass.F_c", "to": "gain.u"}, {"from": "gain.y", "to": "mass.x_in"}],
                "experiment": {"stop": 2.0, "step": step}, "record": ["mass.x", "mass.x_in", "mass.F_c"]}
        system, result = _run(write_spec, spec, f"me_{step}.json")
        assert result.ok, result.message
        (loop,) = system.coupling.loops
        assert loop.units == ("mass", "gain") and system.model_exchange.groups == ()
        t, x = result.traces["time"].to_numpy(), result.traces["mass.x"].to_numpy()
        x_in, force = result.traces["mass.x_in"].to_numpy(), result.traces["mass.F_c"].to_numpy()
        assert np.max(np.abs(x_in - x / 2)) < 1e-10 and np.max(np.abs(force - 2 * (x - x_in))) < 1e-10
        errors.append(np.max(np.abs(x - np.cos(math.sqrt(2) * t))))
    assert errors[0] < 1e-2 and 1.7 < errors[0] / errors[1] < 2.3
