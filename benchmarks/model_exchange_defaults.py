"""Model-exchange defaults against the tools' check: the figures of docs/fmi-support.md, "Model exchange defaults".

    python benchmarks/model_exchange_defaults.py [--tolerances 1e-6,1e-8] [--reference-fmus DIR]

Runs, as model exchange and with no ``max_step`` (the default: the communication step), at each tolerance:

- BouncingBall (our ``bouncing_ball``: h0 = 1, g = 9.81, e = 0.7, v_min = 0.1) to 3 s at 0.01 s and 0.05 s;
- Dahlquist (our ``linear_ode``, a = -1, x0 = 1: x' = -x) to 10 s at 0.1, 0.2 and 0.01 s;
- OMSimulator's DualMassOscillator (two ``mass_spring`` FMUs) to 10 s at 1 ms;

and prints, per case, the largest error against the exact solution in units of OMSimulator's comparison band
``1e-4 + 1e-4 |exact|`` (the worst signal), the bounce-time error, and CVode's right-hand-side evaluations (counted
in fmpy's solver callback; they do not depend on the machine's load).  ``--reference-fmus DIR`` (a folder with the
Modelica Reference FMUs' ``BouncingBall.fmu`` and ``Dahlquist.fmu`` built from their sources) runs those instead
of ours for the first two.  FMI 2.0; Markdown rows.
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
from pathlib import Path

import fmpy.sundials
import numpy as np
from scipy.linalg import expm

from cosim import Execution, build_system, load_spec

_RHS = {"calls": 0}
_ORIGINAL_F = fmpy.sundials.CVodeSolver.f


def _counting_f(self, *args):  # fmpy's right-hand-side callback, counted
    _RHS["calls"] += 1
    return _ORIGINAL_F(self, *args)


fmpy.sundials.CVodeSolver.f = _counting_f


def bounce_times(h0=1.0, g=9.81, e=0.7, v_min=0.1) -> list[float]:
    t = math.sqrt(2 * h0 / g)
    v, times = g * t, [t]
    while e * v >= v_min:
        v *= e
        t += 2 * v / g
        times.append(t)
    return times


def free_fall(times, h0=1.0, g=9.81, e=0.7):
    bounces = bounce_times()
    h, v = np.zeros(len(times)), np.zeros(len(times))
    for i, t in enumerate(times):
        k = int(np.searchsorted(bounces, t, side="right"))
        if k == 0:
            h[i], v[i] = h0 - 0.5 * g * t ** 2, -g * t
        elif k < len(bounces):
            up, dt = g * bounces[0] * e ** k, t - bounces[k - 1]
            h[i], v[i] = up * dt - 0.5 * g * dt ** 2, up - g * dt
    return h, v


def band(got, exact) -> float:
    return float(np.max(np.abs(np.asarray(got) - exact) / (1e-4 + 1e-4 * np.abs(exact))))


def run(spec: dict, folder: Path):
    path = folder / "spec.json"
    path.write_text(json.dumps(spec))
    _RHS["calls"] = 0
    result = Execution(build_system(load_spec(path)), record=True).run()
    assert result.ok, result.message
    return result.traces, _RHS["calls"]


def unit(fmu: str, tolerance: float, **fields) -> dict:
    return {"fmu": fmu, "interface": "model-exchange", "tolerance": tolerance, **fields}


def ball(tolerance: float, step: float, folder: Path, fmu: str) -> tuple[str, str]:
    spec = {"units": {"b": unit(fmu, tolerance, record_events=True)}, "experiment": {"stop": 3.0, "step": step},
            "record": ["b.h", "b.v"]}
    traces, calls = run(spec, folder)
    t = traces["time"].to_numpy()
    keep = np.flatnonzero(np.abs(t / step - np.round(t / step)) < 1e-9)  # the communication points (not events)
    h, v = free_fall(t[keep])
    events = np.flatnonzero(np.diff(t) == 0)
    located = t[events][np.abs(traces["b.v"].to_numpy()[events]) > 0.05]
    expected = bounce_times()
    drift = max(min(abs(x - e) for x in located) for e in expected) if len(located) else float("nan")
    worst = max(band(traces["b.h"].to_numpy()[keep], h), band(traces["b.v"].to_numpy()[keep], v))
    return f"{worst:.3g} (bounce times {drift:.2g} s off)", str(calls)


def dahlquist(tolerance: float, step: float, folder: Path, fmu: str, variable: str) -> tuple[str, str]:
    spec = {"units": {"d": unit(fmu, tolerance, **({"parameters": {"a": -1.0, "x0": 1.0}} if "builtin" in fmu else {}))},
            "experiment": {"stop": 10.0, "step": step}, "record": [f"d.{variable}"]}
    traces, calls = run(spec, folder)
    t = traces["time"].to_numpy()
    return f"{band(traces[f'd.{variable}'].to_numpy(), np.exp(-t)):.3g}", str(calls)


def oscillator(tolerance: float, folder: Path) -> tuple[str, str]:
    c1, c2, c3, k1, k2, k3 = 0.2, 0.5, 0.3, 10.0, 10.0, 20.0
    a = np.array([[0, 1, 0, 0], [-(k1 + k2), -(c1 + c2), k2, c2], [0, 0, 0, 1], [k2, c2, -(k2 + k3), -(c2 + c3)]])
    x0 = np.array([0.0, 0.0, 0.5, 0.0])
    fmu = "builtin:mass_spring_fmi2"
    spec = {"units": {"s1": unit(fmu, tolerance, parameters={"k": k1, "d": c1}),
                      "s2": unit(fmu, tolerance, parameters={"k": k3, "d": c3, "kc": k2, "dc": c2, "x0": 0.5})},
            "connections": [{"from": "s1.x", "to": "s2.x_in"}, {"from": "s1.v", "to": "s2.v_in"},
                            {"from": "s2.F_c", "to": "s1.F"}],
            "experiment": {"stop": 10.0, "step": 1e-3}, "record": ["s1.x", "s1.v", "s2.x", "s2.v"]}
    traces, calls = run(spec, folder)
    t = traces["time"].to_numpy()[::10]
    exact = np.array([expm(a * ti) @ x0 for ti in t])
    got = traces[["s1.x", "s1.v", "s2.x", "s2.v"]].to_numpy()[::10]
    amplitude = float(np.max(np.abs(got - exact) / np.max(np.abs(exact), axis=0)))
    return f"{band(got, exact):.3g} ({amplitude:.2g} of the amplitude)", str(calls)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tolerances", default="1e-6,1e-8")
    parser.add_argument("--reference-fmus", type=Path, help="a folder with the Reference FMUs' BouncingBall.fmu, "
                                                            "Dahlquist.fmu")
    args = parser.parse_args()
    tolerances = [float(x) for x in args.tolerances.split(",")]
    ref = args.reference_fmus
    ball_fmu = str(ref / "BouncingBall.fmu") if ref else "builtin:bouncing_ball_fmi2"
    dq_fmu, dq_var = (str(ref / "Dahlquist.fmu"), "x") if ref else ("builtin:linear_ode_fmi2", "y")
    cases = [(f"BouncingBall, {s} s", lambda tol, f, s=s: ball(tol, s, f, ball_fmu)) for s in (0.01, 0.05)]
    cases += [(f"Dahlquist, {s} s", lambda tol, f, s=s: dahlquist(tol, s, f, dq_fmu, dq_var)) for s in (0.1, 0.2, 0.01)]
    cases += [("DualMassOscillator, 1 ms", oscillator)]
    print("| case | " + " | ".join(f"band, tolerance {t:g} | rhs" for t in tolerances) + " |")
    print("|---|" + "---|---|" * len(tolerances))
    with tempfile.TemporaryDirectory() as folder:
        for name, case in cases:
            cells = [cell for tol in tolerances for cell in case(tol, Path(folder))]
            print(f"| {name} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
