"""Two coupled FMUs (one FMI 2.0, one FMI 3.0) against the exact solution.

x1' = a1 x1 + b1 x2 and x2' = a2 x2 + b2 x1, each half a real FMU
(fmus/linear_ode) that integrates exactly for its input held over a step, so
the only error left is the coupling error of the master algorithm, which must
fall at first order as the communication step halves.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm

import cosim
from cosim import Execution, build_system, load_spec

A1, B1, A2, B2 = -1.0, 0.5, -2.0, 1.5
X0 = np.array([1.0, -0.5])
STOP = 2.0


def exact(t: float) -> np.ndarray:
    return expm(np.array([[A1, B1], [B2, A2]]) * t) @ X0


def coupled_spec(step: float, algorithm: str) -> dict:
    return {
        "units": {
            "one": {"fmu": "builtin:linear_ode_fmi2", "parameters": {"a": A1, "b": B1, "x0": X0[0]}},
            "two": {"fmu": "builtin:linear_ode_fmi3", "parameters": {"a": A2, "b": B2, "x0": X0[1]}},
        },
        "connections": [{"from": "one.y", "to": "two.u"}, {"from": "two.y", "to": "one.u"}],
        "experiment": {"start": 0.0, "stop": STOP, "step": step, "algorithm": algorithm},
        "record": ["one.y", "two.y"],
        "objectives": {"x1": {"signal": "one.y", "reduce": "final"}, "x2": {"signal": "two.y", "reduce": "final"}},
    }


def final_error(write_spec, step: float, algorithm: str) -> float:
    result = cosim.run(str(write_spec(coupled_spec(step, algorithm), f"s_{algorithm}_{step}.json")))
    assert result.ok, result.message
    return float(np.max(np.abs(np.array([result.objectives["x1"], result.objectives["x2"]]) - exact(STOP))))


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_coupling_error_falls_at_first_order(write_spec, algorithm):
    steps = [0.04, 0.02, 0.01, 0.005]
    errors = [final_error(write_spec, h, algorithm) for h in steps]
    orders = [math.log2(errors[i] / errors[i + 1]) for i in range(len(errors) - 1)]
    assert errors[-1] < 5e-3
    assert all(0.9 < p < 1.1 for p in orders), (errors, orders)


def test_traces_follow_the_exact_solution(write_spec):
    system = build_system(load_spec(write_spec(coupled_spec(0.001, "gauss-seidel"))))
    result = Execution(system, record=True).run()
    assert result.ok, result.message
    traces = result.traces
    assert len(traces) == 2001 and traces["time"].iloc[-1] == pytest.approx(STOP, abs=1e-12)
    expected = np.array([exact(t) for t in traces["time"]])
    assert np.max(np.abs(traces[["one.y", "two.y"]].to_numpy() - expected)) < 1e-3
    assert traces["one.y"].iloc[0] == X0[0] and traces["two.y"].iloc[0] == X0[1]
