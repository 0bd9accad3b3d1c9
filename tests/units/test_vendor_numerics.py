"""Numerics that must agree with what OpenModelica / OMSimulator give on vendor systems (issue 33, items 5 and 7).

Every system is rebuilt from our own C FMUs (src/cosim/fmus) in the shape of the vendor's, and every expected value
is computed here from the equations (closed forms, the matrix exponential, free fall between bounces):

- OMSimulator's testsuite pair of equation FMUs (testsuite/simulation/equationPair.py: ``2 x1^2 + 5 x2 = 42`` in
  one FMU, ``x1 - 6 x2 = 4`` in the other, connected both ways) has two solutions; KINSOL, started from the start
  values, prints ``x1: 4.5572`` and ``x2: 0.0928``.  Two `algebraic` FMUs (``y = c0 + c1 u + c2 u^2``) are that pair.
- A nonlinear loop through one FMU (its output connected to its own input), in an SSP as OMSimulator writes one.
- OMSimulator's DualMassOscillator (testsuite/resources/DualMassOscillator.mo: m1 = m2 = 1, k1 = 10, k2 = 10,
  k3 = 20, c1 = 0.2, c2 = 0.5, c3 = 0.3, x2(0) = 0.5) as two `mass_spring` model-exchange FMUs.
- The Modelica Reference FMUs BouncingBall (h0 = 1, g = 9.81, e = 0.7, v_min = 0.1) and Dahlquist (x' = -k x,
  k = 1, x(0) = 1) as model exchange: our `bouncing_ball` and `linear_ode` (a = -1, x0 = 1) are the same models.

The bar for model exchange is the tolerance OMSimulator's testsuite compares these FMUs' results with
(``compareSimulationResults(..., relTol=1e-4, absTol=1e-4)`` in testsuite/tests/reference-fmus): every sample
within ``1e-4 + 1e-4 |reference|`` of the exact solution, run with cosim's defaults (no tolerance, no max step).
"""

from __future__ import annotations

import math
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.linalg import expm

from cosim import Execution, build_system, load_spec
from cosim.cli.main import main
from cosim.fmus.build import ensure_built
from tests.fmus.test_fmu_model_exchange import bounce_times

REL, ABS = 1e-4, 1e-4  # OMSimulator's compareSimulationResults on the Reference FMUs
# what equationPair.py prints (f"{x:.4f}"): x1 of equation2's output; x2 of equation1's, whose residual KINSOL left
# at -4.45e-5 (it solves "to within tolerance 0.0001", its log says), so x2 is the exact root to 1e-4
X1_OMS, X2_OMS, KINSOL_TOLERANCE = "4.5572", 0.0928, 1e-4


def _run(write_spec, spec: dict, name: str = "spec.json"):
    system = build_system(load_spec(write_spec(spec, name)))
    result = Execution(system, record=True).run()
    assert result.ok, result.message
    return system, result.traces


def _over_tolerance(got: np.ndarray, exact: np.ndarray) -> float:
    """The largest |got - exact| in units of OMSimulator's band 1e-4 + 1e-4 |exact| (<= 1: within it)."""
    return float(np.max(np.abs(got - exact) / (ABS + REL * np.abs(exact))))


# -- item 5: the root a loop with two solutions reaches -----------------------------------------------------------

def equation_pair(version: int, algorithm: str = "gauss-seidel", x1_start: float | None = None) -> dict:
    """equation1: x2 = (42 - 2 x1^2) / 5 (input x1); equation2: x1 = 4 + 6 x2 (input x2); connected both ways."""
    fmu = f"builtin:algebraic_fmi{version}"
    equation1 = {"fmu": fmu, "parameters": {"c0": 8.4, "c1": 0.0, "c2": -0.4}}
    if x1_start is not None:
        equation1["start"] = {"u": x1_start}
    return {"units": {"equation1": equation1,
                      "equation2": {"fmu": fmu, "parameters": {"c0": 4.0, "c1": 6.0}}},
            "connections": [{"from": "equation2.y", "to": "equation1.u"}, {"from": "equation1.y", "to": "equation2.u"}],
            "experiment": {"stop": 0.2, "step": 0.1, "algorithm": algorithm},
            "record": ["equation1.u", "equation1.y", "equation2.u", "equation2.y"]}


# 12 x1^2 + 5 x1 - 272 = 0 (x2 eliminated): the two solutions
X1_ROOTS = ((-5 + math.sqrt(25 + 48 * 272)) / 24, (-5 - math.sqrt(25 + 48 * 272)) / 24)


def test_the_closed_form_roots_are_the_ones_the_tool_and_the_issue_name():
    assert f"{X1_ROOTS[0]:.4f}" == X1_OMS and abs((X1_ROOTS[0] - 4) / 6 - X2_OMS) < KINSOL_TOLERANCE
    assert f"{X1_ROOTS[1]:.2f}" == "-4.97" and f"{(X1_ROOTS[1] - 4) / 6:.4f}" == "-1.4956"  # cosim's, before


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
@pytest.mark.parametrize("version", [2, 3])
def test_the_equation_pair_reaches_the_root_omsimulator_prints(write_spec, version, algorithm):
    """Newton starts at the tearing variable's start value (x1 = 0, the FMU's), as KINSOL starts from the start
    values: the root 4.5572.  Before, the cut link was carried at initialization too, twice round the loop
    (x1 = 4, 16, then -560), and Newton from -560 went down the other branch to -4.97."""
    system, traces = _run(write_spec, equation_pair(version, algorithm))
    (loop,) = system.coupling.loops
    assert loop.tearing == ("equation1.u",)
    x1, x2 = traces["equation2.y"].to_numpy(), traces["equation1.y"].to_numpy()
    assert [f"{v:.4f}" for v in x1] == [X1_OMS] * 3 and np.max(np.abs(x2 - X2_OMS)) < KINSOL_TOLERANCE
    assert np.max(np.abs(x1 - X1_ROOTS[0])) < 1e-9 and np.max(np.abs(x2 - (X1_ROOTS[0] - 4) / 6)) < 1e-9
    # both equations hold on what the units output and read
    assert np.max(np.abs(2 * traces["equation1.u"] ** 2 + 5 * x2 - 42)) < 1e-9
    assert np.max(np.abs(x1 - 6 * traces["equation2.u"] - 4)) < 1e-9


@pytest.mark.parametrize("version", [2, 3])
def test_a_start_value_on_the_tearing_variable_chooses_the_root(write_spec, version):
    """The documented way to the other solution: the tearing variable's start value in the spec."""
    _, traces = _run(write_spec, equation_pair(version, x1_start=-10.0))
    assert np.max(np.abs(traces["equation2.y"].to_numpy() - X1_ROOTS[1])) < 1e-9
    _, traces = _run(write_spec, equation_pair(version, x1_start=3.0), "near.json")
    assert np.max(np.abs(traces["equation2.y"].to_numpy() - X1_ROOTS[0])) < 1e-9


def test_the_cut_link_is_not_carried_at_initialization(write_spec):
    """The tearing variable keeps its start value until the loop is solved (the other links are carried)."""
    system = build_system(load_spec(write_spec(equation_pair(2, x1_start=1.5))))
    (loop,) = system.coupling.loops
    cut = system.connections[loop.torn[0]]
    assert cut not in system.init_order and len(system.init_order) == len(system.connections) - 1


SELF_LOOP_SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" name="selfLoop" version="1.0">
  <ssd:System name="root">
    <ssd:Elements>
      <ssd:Component name="equation" type="application/x-fmu-sharedlibrary" source="resources/equation.fmu">
        <ssd:Connectors>
          <ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
          <ssv:ParameterSet version="1.0" name="equation"><ssv:Parameters>
            <ssv:Parameter name="c0"><ssv:Real value="2"/></ssv:Parameter>
            <ssv:Parameter name="c1"><ssv:Real value="0"/></ssv:Parameter>
            <ssv:Parameter name="c2"><ssv:Real value="-1"/></ssv:Parameter>
          </ssv:Parameters></ssv:ParameterSet>
        </ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="equation" startConnector="y" endElement="equation" endConnector="u"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="0.3"/>
</ssd:SystemStructureDescription>
"""


@pytest.mark.parametrize("version", [2, 3])
def test_a_nonlinear_loop_through_one_fmu_in_an_ssp_is_solved(tmp_path, capsys, version):
    """u = y = 2 - u^2 through one FMU's own connection: roots 1 and -2; from the start value u = 0, Newton
    reaches 1 at every communication point."""
    ssp = tmp_path / "selfLoop.ssp"
    with zipfile.ZipFile(ssp, "w") as archive:
        archive.writestr("SystemStructure.ssd", SELF_LOOP_SSD)
        archive.write(ensure_built("algebraic", version), "resources/equation.fmu")
    out = tmp_path / "out.csv"
    assert main(["run", str(ssp), "--step", "0.1", "--out", str(out)]) == 0, capsys.readouterr()
    capsys.readouterr()
    assert main(["inspect", str(ssp)]) == 0
    assert "loop through units equation: tearing equation.u (1 value)" in capsys.readouterr().out
    traces = pd.read_csv(out)
    assert len(traces) == 4
    np.testing.assert_allclose(traces["equation.y"], 1.0, rtol=0, atol=1e-10)


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_units_after_a_loop_start_from_its_solution(write_spec, algorithm):
    """The loop is solved at the start time after initialization has carried the values from before the solve:
    every other input then gets the solution too, so a unit downstream steps from it from the first step (under
    Jacobi it stepped from the value before the solve, 54.4) and the first row shows it."""
    spec = equation_pair(2, algorithm)
    spec["units"]["ode"] = {"fmu": "builtin:linear_ode_fmi2", "parameters": {"a": -1.0, "b": 1.0, "x0": 0.0}}
    spec["connections"].append({"from": "equation2.y", "to": "ode.u"})
    spec["record"] += ["ode.u", "ode.y"]
    _, traces = _run(write_spec, spec)
    t = traces["time"].to_numpy()
    np.testing.assert_allclose(traces["ode.u"], X1_ROOTS[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(traces["ode.y"], (1 - np.exp(-t)) * X1_ROOTS[0], rtol=0, atol=1e-9)


def test_a_system_connector_after_a_loop_shows_the_solution_from_the_first_row(tmp_path):
    """The SSP's root output connector fed by the looped FMU's output: the same value as that output in every
    row (it showed the value before the solve, 2, at t = 0)."""
    ssd = SELF_LOOP_SSD.replace(
        '<ssd:System name="root">',
        '<ssd:System name="root">\n    <ssd:Connectors><ssd:Connector name="out" kind="output"><ssc:Real/>'
        '</ssd:Connector></ssd:Connectors>').replace(
        '<ssd:Connection startElement="equation" startConnector="y" endElement="equation" endConnector="u"/>',
        '<ssd:Connection startElement="equation" startConnector="y" endConnector="out"/>\n'
        '      <ssd:Connection startConnector="out" endElement="equation" endConnector="u"/>')
    ssp = tmp_path / "selfLoopThroughTheSystem.ssp"
    with zipfile.ZipFile(ssp, "w") as archive:
        archive.writestr("SystemStructure.ssd", ssd)
        archive.write(ensure_built("algebraic", 3), "resources/equation.fmu")
    out = tmp_path / "out.csv"
    assert main(["run", str(ssp), "--step", "0.1", "--out", str(out)]) == 0
    traces = pd.read_csv(out)
    assert list(traces.columns) == ["time", "equation.y", "root.out"]
    np.testing.assert_allclose(traces["equation.y"], 1.0, rtol=0, atol=1e-10)
    np.testing.assert_allclose(traces["root.out"], 1.0, rtol=0, atol=1e-10)


# -- item 5: connected model-exchange FMUs of a two-mass oscillator ----------------------------------------------

C1, C2, C3, K1, K2, K3, M1, M2 = 0.2, 0.5, 0.3, 10.0, 10.0, 20.0, 1.0, 1.0
DMO = np.array([[0.0, 1.0, 0.0, 0.0],
                [-(K1 + K2) / M1, -(C1 + C2) / M1, K2 / M1, C2 / M1],
                [0.0, 0.0, 0.0, 1.0],
                [K2 / M2, C2 / M2, -(K2 + K3) / M2, -(C2 + C3) / M2]])
DMO_X0 = np.array([0.0, 0.0, 0.5, 0.0])  # x1, v1, x2, v2
DMO_COLUMNS = ["system1.x", "system1.v", "system2.x", "system2.v"]


def dual_mass_oscillator(version: int, step: float, stop: float) -> dict:
    """System1 (mass 1 on k1, c1, driven by F) and System2 (mass 2 on k3, c3, coupled to mass 1 by k2, c2; its
    output F_c = k2 (x2 - x1) + c2 (v2 - v1) is System1's F), with cosim's model-exchange defaults."""
    fmu = f"builtin:mass_spring_fmi{version}"
    return {"units": {"system1": {"fmu": fmu, "parameters": {"m": M1, "k": K1, "d": C1}},
                      "system2": {"fmu": fmu, "parameters": {"m": M2, "k": K3, "d": C3, "kc": K2, "dc": C2,
                                                             "x0": DMO_X0[2]}}},
            "connections": [{"from": "system1.x", "to": "system2.x_in"}, {"from": "system1.v", "to": "system2.v_in"},
                            {"from": "system2.F_c", "to": "system1.F"}],
            "experiment": {"stop": stop, "step": step}, "record": DMO_COLUMNS}


@pytest.mark.parametrize("version", [2, 3])
def test_the_dual_mass_oscillator_agrees_to_the_tools_tolerance_on_all_four_signals(write_spec, version):
    """OMSimulator integrates it with relativeTolerance 1e-6 (testsuite DualMassOscillator2); each of cosim's four
    signals must be within 10 x 1e-6 of its amplitude of the exact solution, run with the defaults at a 1 ms
    communication step.  Before (default tolerance 1e-6), CVode, its step capped at 1 ms, stayed at BDF order 2
    and the four signals drifted to 3.6e-5 .. 5.7e-5 of their amplitudes (v2 9.9e-5 off after 2.6 s, at the edge
    of OMSimulator's comparison band); now (1e-8) every signal is within 2.3e-7 of its amplitude."""
    _, traces = _run(write_spec, dual_mass_oscillator(version, 1e-3, 4.0))
    t = traces["time"].to_numpy()[::10]
    exact = np.array([expm(DMO * ti) @ DMO_X0 for ti in t])
    got = traces[DMO_COLUMNS].to_numpy()[::10]
    amplitude = np.max(np.abs(exact), axis=0)
    relative = np.max(np.abs(got - exact), axis=0) / amplitude
    assert np.all(relative < 10 * 1e-6), dict(zip(DMO_COLUMNS, relative))
    assert _over_tolerance(got, exact) < 0.1  # and 10x inside OMSimulator's comparison band


# -- item 7: the Reference FMUs BouncingBall and Dahlquist as model exchange, with cosim's defaults ----------------

def _alone(tmp_path: Path, fmu: Path, *args: str) -> pd.DataFrame:
    """``cosim run model.fmu`` (the FMU alone: its default experiment, every output recorded) with ``args``."""
    out = tmp_path / f"{fmu.stem}.csv"
    assert main(["run", str(fmu), "--out", str(out), *args]) == 0
    return pd.read_csv(out)


def free_fall(times: np.ndarray, h0: float = 1.0, g: float = 9.81, e: float = 0.7, v_min: float = 0.1
              ) -> tuple[np.ndarray, np.ndarray]:
    """h and v of the bouncing ball at ``times``: a parabola between the analytic bounces, at rest after them."""
    bounces = bounce_times(h0, g, e, v_min)
    h, v = np.zeros(len(times)), np.zeros(len(times))
    for i, t in enumerate(times):
        k = int(np.searchsorted(bounces, t, side="right"))
        if k == 0:
            h[i], v[i] = h0 - 0.5 * g * t ** 2, -g * t
        elif k < len(bounces):
            up, dt = g * bounces[0] * e ** k, t - bounces[k - 1]
            h[i], v[i] = up * dt - 0.5 * g * dt ** 2, up - g * dt
    return h, v


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("step", [0.01, 0.05], ids=["default-experiment", "ref-csv-interval"])
def test_bouncing_ball_with_the_defaults_is_within_the_tools_tolerance(tmp_path, version, step):
    """BouncingBall's default experiment (3 s, step 0.01) and its *_ref.csv output interval (0.05 s).  Before
    (tolerance 1e-6) the bounce times drifted by 1e-4 over the eleven bounces and v was up to 7.6 bands off after
    the late ones (8e-4 at t = 2.49); now the worst sample is below 0.1 of the band."""
    fmu = ensure_built("bouncing_ball", version)
    traces = _alone(tmp_path, fmu, "--step", str(step))
    t = traces["time"].to_numpy()
    assert t[-1] == pytest.approx(3.0)
    h, v = free_fall(t)
    assert _over_tolerance(traces["bouncing_ball.h"].to_numpy(), h) < 0.1
    assert _over_tolerance(traces["bouncing_ball.v"].to_numpy(), v) < 0.1
    assert traces["bouncing_ball.bounces"].iloc[-1] == len(bounce_times(1.0, 9.81, 0.7, 0.1)) == 11


@pytest.mark.parametrize("version", [2, 3])
def test_bouncing_ball_bounce_times_are_located_to_well_within_the_tolerance(write_spec, version):
    """Event location: with the defaults each bounce is found within 1e-5 s of the analytic time (1e-4 s before),
    and the event rows (``record_events``) hold the impact and rebound speeds within the band."""
    spec = {"units": {"ball": {"fmu": f"builtin:bouncing_ball_fmi{version}", "record_events": True}},
            "experiment": {"stop": 3.0, "step": 0.01}, "record": ["ball.h", "ball.v", "ball.bounces"]}
    _, traces = _run(write_spec, spec)
    t, v, bounces = (traces[c].to_numpy() for c in ("time", "ball.v", "ball.bounces"))
    at_event = np.flatnonzero(np.diff(t) == 0)  # (before, after) row pairs at equal times
    expected = bounce_times(1.0, 9.81, 0.7, 0.1)
    events = [i for i in at_event if bounces[i + 1] == bounces[i] + 1]
    assert len(events) == len(expected)
    assert np.max(np.abs(t[events] - expected)) < 1e-5
    impact = 9.81 * expected[0] * 0.7 ** np.arange(len(expected))  # speed before bounce k
    assert _over_tolerance(v[events], -impact) < 0.1
    rebound = np.where(0.7 * impact >= 0.1, 0.7 * impact, 0.0)  # the last one rests
    assert _over_tolerance(v[np.array(events) + 1], rebound) < 0.1


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("step", ["0.1", "0.2", "0.01"], ids=["default-experiment", "ref-csv-interval", "fine"])
def test_dahlquist_with_the_defaults_is_within_the_tools_tolerance(tmp_path, version, step):
    """Dahlquist (x' = -x, x(0) = 1) over its default experiment (10 s), at its step 0.1, its *_ref.csv interval 0.2
    and 0.01: x = exp(-t) to well inside the band (the worst before: 0.09 of it, at step 0.01; now 0.001)."""
    fmu = ensure_built("linear_ode", version, interfaces=("ModelExchange",))
    traces = _alone(tmp_path, fmu, "--stop", "10", "--step", step)
    t = traces["time"].to_numpy()
    assert t[-1] == pytest.approx(10.0)
    assert _over_tolerance(traces["linear_ode.y"].to_numpy(), np.exp(-t)) < 0.01
