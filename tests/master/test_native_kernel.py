"""The native stepping kernel (cosim.master.native) against the Python master, bit for bit.

Every system here runs twice, ``experiment.kernel`` "native" and "python", on our own C FMUs built in the test
(FMI 2.0 and 3.0): traces, objectives, steps, end time, status and message must be equal exactly (DataFrame
``equals``: same values, same dtypes, NaN where NaN).  Also: which systems qualify, ``native`` refused with the
reason (exit 2), and ``cosim inspect`` naming the kernel.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from cosim import Execution, build_system, load_spec
from cosim.errors import SpecError
from cosim.fmus.build import ensure_built
from cosim.master.native.algorithm import NativeFixedStep
from tests.helpers.kernel_twins import assert_identical
from tests.helpers.tools import python_unit

ALGORITHMS = ("gauss-seidel", "jacobi", "jacobi-delayed")
REDUCTIONS = ("final", "initial", "min", "max", "mean", "integral", "integral_abs", "rms", "time_of_max", "time_of_min")


def fmu(name: str, version: int) -> str:
    return str(ensure_built(name, version))


def transfer_spec(kind: str, version: int, algorithm: str) -> dict:
    """Two linear ODEs in a feedback ring (plain copies, or a factor and offset), or a counter feeding another
    through Integer and Boolean ports, with the ODE's Real output weighting both."""
    ode = fmu("linear_ode", version)
    units = {"a": {"fmu": ode, "parameters": {"a": -1.0, "x0": 1.0}},
             "b": {"fmu": ode, "parameters": {"a": -2.5, "x0": 0.5}}}
    factor = {"factor": 1.7, "offset": 0.1} if kind == "factor" else {}
    connections = [{"from": "a.y", "to": "b.u", **factor}, {"from": "b.y", "to": "a.u", **factor}]
    record = ["a.y", "b.y", "a.u", "b.u"]
    signal = "b.y"
    if kind in ("integer", "boolean"):
        counter = fmu("counter", version)
        units["c1"] = {"fmu": counter, "parameters": {"count0": 1}, "start": {"increment": 3}}
        units["c2"] = {"fmu": counter}
        if kind == "integer":
            connections += [{"from": "c1.count", "to": "c2.increment"}, {"from": "a.y", "to": "c2.u"}]
        else:
            connections += [{"from": "c1.odd", "to": "c2.enable"}, {"from": "b.y", "to": "c1.u"}]
        record += ["c1.count", "c1.odd", "c2.count", "c2.odd", "c2.y", "c1.y", "c2.done"]
        signal = "c2.y"
    objectives = {f"{r}": {"signal": signal, "reduce": r} for r in REDUCTIONS}
    objectives["ay"] = {"signal": "a.y", "reduce": "integral"}
    return {"units": units, "connections": connections, "record": record, "objectives": objectives,
            "experiment": {"stop": 1.0, "step": 0.03, "algorithm": algorithm}}


def both(write_spec, spec: dict, record: bool = True):
    """(native result, python result, native system) of ``spec``, each kernel asked for explicitly."""
    results, systems = [], []
    for kernel in ("native", "python"):
        spec["experiment"]["kernel"] = kernel
        system = build_system(load_spec(write_spec(spec, f"{kernel}.json")))
        assert system.kernel.kernel == kernel
        systems.append(system)
        results.append(Execution(system, record=record).run())
    return results[0], results[1], systems[0]


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("algorithm", ALGORITHMS)
@pytest.mark.parametrize("kind", ["plain", "factor", "integer", "boolean"])
def test_every_algorithm_and_transfer_kind_gives_the_python_masters_bits(write_spec, version, algorithm, kind):
    native, python, _ = both(write_spec, transfer_spec(kind, version, algorithm))
    assert native.status == "ok", native.message
    assert native.steps == 34 and native.end_time == 1.0
    assert_identical(native, python)
    traces = native.traces
    assert traces["b.y"].nunique() > 30  # the run moved: a test of equal constants could not fail
    if kind == "factor":  # the conversion was applied: b.u = 1.7 a.y + 0.1 at every row
        np.testing.assert_allclose(traces["b.u"], 1.7 * traces["a.y"] + 0.1, rtol=1e-15)
    if kind == "integer":
        assert traces["c2.count"].dtype == np.int64 and traces["c2.count"].iloc[-1] > 34
    if kind == "boolean":
        assert traces["c1.odd"].dtype == bool and traces["c2.count"].iloc[-1] > 0


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_stop_when_ends_both_at_the_same_step(write_spec, version, algorithm):
    spec = transfer_spec("integer", version, algorithm)
    spec["units"]["c2"]["parameters"] = {"limit": 40}
    spec["experiment"]["stop_when"] = "c2.done"
    native, python, _ = both(write_spec, spec)
    assert native.status == "ok"  # stop_when is the run's own end: no message
    assert 1 < native.steps < 34 and native.traces["c2.done"].iloc[-1] and not native.traces["c2.done"].iloc[-2]
    assert_identical(native, python)


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("mode, status", [(3, "failed"), (4, "failed")])
def test_a_failing_fmu_is_the_same_failed_row(write_spec, version, mode, status):
    # mode 3: doStep returns Error at t >= 0.5 (the row names the unit, the call, the time and the FMU's log);
    # mode 4: the output turns NaN: the objective is not finite
    spec = transfer_spec("plain", version, "gauss-seidel")
    spec["units"]["f"] = {"fmu": fmu("fault", version), "parameters": {"mode": mode, "trigger_time": 0.5}}
    spec["connections"].append({"from": "a.y", "to": "f.u"})
    spec["objectives"]["fy"] = {"signal": "f.y", "reduce": "max"}
    native, python, _ = both(write_spec, spec)
    assert native.status == status
    if mode == 3:
        assert "unit 'f' at t=0.51" in native.message and f"fmi{version}DoStep returned Error" in native.message
        assert "fault mode 3" in native.message  # the FMU's own log line
        assert native.steps == 17
    else:
        assert "not finite: fy" in native.message
    assert_identical(native, python)


def test_objectives_alone_run_without_recording(write_spec):
    native, python, _ = both(write_spec, transfer_spec("factor", 2, "jacobi"), record=False)
    assert native.traces is None
    assert_identical(native, python)


def test_auto_takes_the_kernel_for_fmus_and_python_for_python_units(write_spec):
    spec = transfer_spec("plain", 2, "gauss-seidel")
    system = build_system(load_spec(write_spec(spec)))
    assert system.kernel.kernel == "native"  # auto is the default
    assert isinstance(Execution(system)._default_algorithm(), NativeFixedStep)
    spec["units"]["g"] = {"python": python_unit("Gain")}
    spec["connections"].append({"from": "a.y", "to": "g.u"})
    system = build_system(load_spec(write_spec(spec)))
    assert system.kernel.kernel == "python" and "unit 'g' is not an FMI 2.0/3.0 FMU" in system.kernel.reason
    spec["experiment"]["algorithm"] = "adaptive"
    spec["units"].pop("g")
    spec["connections"].pop()
    system = build_system(load_spec(write_spec(spec)))
    assert system.kernel.reason == "the 'adaptive' algorithm runs in Python only"


def test_native_refuses_a_system_it_cannot_step_with_the_reason(write_spec, tmp_path):
    spec = transfer_spec("plain", 2, "gauss-seidel")
    spec["units"]["g"] = {"python": python_unit("Gain")}
    spec["connections"].append({"from": "a.y", "to": "g.u"})
    spec["experiment"]["kernel"] = "native"
    path = write_spec(spec)
    with pytest.raises(SpecError) as caught:
        build_system(load_spec(path))
    (problem,) = caught.value.problems
    assert problem.path == "$.experiment.kernel" and "unit 'g' is not an FMI 2.0/3.0 FMU" in problem.message
    done = subprocess.run([sys.executable, "-m", "cosim", "run", str(path)], capture_output=True, text=True,
                          cwd=tmp_path)
    assert done.returncode == 2 and "experiment.kernel" in done.stderr and "Traceback" not in done.stderr


def test_inspect_names_the_kernel(write_spec, tmp_path):
    spec = transfer_spec("plain", 3, "jacobi")
    native = write_spec(spec)
    out = subprocess.run([sys.executable, "-m", "cosim", "inspect", str(native)], capture_output=True, text=True,
                         cwd=tmp_path)
    assert out.returncode == 0 and "kernel: native\n" in out.stdout
    spec["experiment"]["kernel"] = "python"
    out = subprocess.run([sys.executable, "-m", "cosim", "inspect", str(write_spec(spec, "p.json"))],
                         capture_output=True, text=True, cwd=tmp_path)
    assert "kernel: python (experiment.kernel is 'python')" in out.stdout


class _Watcher:
    """An observer of the plain kind (not a trace recorder): the run steps one kernel step per advance."""

    def __init__(self):
        self.rows = []

    def attached(self, context):
        pass

    def initialized(self, t, values):
        self.rows.append((t, values.copy()))

    def step(self, t, values):
        self.rows.append((t, values.copy()))

    def load(self, times, values):
        return False

    def finished(self, t):
        pass

    def detached(self):
        pass


@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_an_observer_watching_step_by_step_sees_the_same_rows(write_spec, algorithm):
    from cosim.master.observers import Observer

    spec = transfer_spec("boolean", 2, algorithm)
    seen = []
    for kernel in ("native", "python"):
        spec["experiment"]["kernel"] = kernel
        system = build_system(load_spec(write_spec(spec, f"{kernel}.json")))
        watcher = type("W", (_Watcher, Observer), {})()
        result = Execution(system, record=True, observers=[watcher]).run()
        assert result.status == "ok" and len(watcher.rows) == 35
        seen.append((result, watcher.rows))
    (native, rows_native), (python, rows_python) = seen
    assert_identical(native, python)
    for (t1, v1), (t2, v2) in zip(rows_native, rows_python):
        assert t1 == t2 and v1.tobytes() == v2.tobytes()


# players, system connectors and FMI 3.0 arrays: run as data inside the kernel ----------------------------------

def _table(tmp_path, fmt: str):
    """A recorded table: irregular times, a repeated time (an event), Real, Integer and Boolean columns, ending
    before the run does (the end values are held)."""
    import pandas as pd

    t = [0.0, 0.05, 0.13, 0.13, 0.3, 0.41, 0.5, 0.77]
    frame = pd.DataFrame({"time": t, "u": [0.5, -1.0, 2.0, 0.25, 3.5, -0.75, 1.0, 0.0],
                          "n": [1, 2, 2, 5, -3, 4, 4, 7],
                          "flag": [True, False, True, True, False, True, False, True]})
    path = tmp_path / f"rec.{fmt}"
    frame.to_parquet(path) if fmt == "parquet" else frame.to_csv(path, index=False)
    return path


def player_spec(table, version: int, algorithm: str, interpolation: str) -> dict:
    ode, counter = fmu("linear_ode", version), fmu("counter", version)
    return {"units": {"p": {"player": str(table), "interpolation": interpolation},
                      "a": {"fmu": ode, "parameters": {"a": -1.5, "x0": 0.2}},
                      "c": {"fmu": counter}},
            "connections": [{"from": "p.u", "to": "a.u", "factor": 0.5, "offset": 1.0},
                            {"from": "p.n", "to": "c.increment"}, {"from": "p.flag", "to": "c.enable"},
                            {"from": "a.y", "to": "c.u"}],
            "record": ["p.u", "p.n", "p.flag", "a.y", "a.u", "c.count", "c.y", "c.enable", "c.increment"],
            "objectives": {r: {"signal": "c.y", "reduce": r} for r in REDUCTIONS}
            | {"pu": {"signal": "p.u", "reduce": "integral"}, "pn": {"signal": "p.n", "reduce": "max"}},
            "experiment": {"stop": 1.0, "step": 0.03, "algorithm": algorithm}}


@pytest.mark.parametrize("interpolation", ["linear", "hold", "nearest"])
@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_a_player_is_played_by_the_kernel_bit_for_bit(write_spec, tmp_path, interpolation, algorithm):
    spec = player_spec(_table(tmp_path, "parquet"), 3 if algorithm == "jacobi" else 2, algorithm, interpolation)
    native, python, system = both(write_spec, spec)
    assert system.kernel.kernel == "native" and native.status == "ok", native.message
    assert_identical(native, python)
    traces = native.traces
    assert traces["p.n"].dtype == np.int64 and set(traces["p.n"]) >= {1, 7}  # played, held at the end
    assert traces["p.u"].nunique() > 5 and traces["p.u"].iloc[-1] == 0.0
    if interpolation == "linear":  # between samples the player blends: a value no sample has
        assert not set(traces["p.u"]) <= {0.5, -1.0, 2.0, 0.25, 3.5, -0.75, 1.0, 0.0}


def test_a_csv_player_runs_natively_too(write_spec, tmp_path):
    native, python, system = both(write_spec, player_spec(_table(tmp_path, "csv"), 3, "gauss-seidel", "linear"))
    assert system.kernel.kernel == "native"
    assert_identical(native, python)


@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_system_connectors_hold_what_the_kernel_gives_them(write_spec, algorithm):
    spec = transfer_spec("plain", 2, algorithm)
    spec["units"]["Root.sub"] = {"connectors": "Root.sub", "inputs": {"speed": "", "other": ""},
                                 "parameters": {"k": -0.5, "n": 3, "on": True}}
    spec["connections"] += [{"from": "a.y", "to": "Root.sub.speed", "factor": 2.0, "offset": -0.25},
                            {"from": "b.y", "to": "Root.sub.other"}]
    spec["record"] += ["Root.sub.speed", "Root.sub.other", "Root.sub.k", "Root.sub.n", "Root.sub.on"]
    spec["objectives"]["speed"] = {"signal": "Root.sub.speed", "reduce": "rms"}
    native, python, system = both(write_spec, spec)
    assert system.kernel.kernel == "native" and native.status == "ok", native.message
    assert_identical(native, python)
    traces = native.traces
    np.testing.assert_allclose(traces["Root.sub.speed"], 2.0 * traces["a.y"] - 0.25, rtol=1e-15)
    assert (traces["Root.sub.k"] == -0.5).all() and (traces["Root.sub.n"] == 3).all() and traces["Root.sub.on"].all()


def array_spec(version: int, algorithm: str) -> dict:
    """An ODE into one element of an FMI 3.0 array (the others keep their values: the array is read before it
    is set), a whole array converted into another, an element of it back into the ODE."""
    ode, gain = fmu("linear_ode", version), fmu("gain_array", version)
    return {"units": {"a": {"fmu": ode, "parameters": {"a": -1.0, "x0": 1.0}},
                      "g1": {"fmu": gain, "parameters": {"k": 2.0}, "start": {"u": [0.5, 0.0, -0.5]}},
                      "g2": {"fmu": gain, "parameters": {"k": -0.7}}},
            "connections": [{"from": "a.y", "to": "g1.u[2]"},
                            {"from": "g1.y", "to": "g2.u", "factor": 1.5, "offset": 0.1},
                            {"from": "g2.y[3]", "to": "a.u"}],
            "record": ["a.y", "a.u", "g1.u", "g1.y", "g2.y"],
            "objectives": {"g2": {"signal": "g2.y", "reduce": "integral"}, "g1": {"signal": "g1.y", "reduce": "max"},
                           "last": {"signal": "g2.y[2]", "reduce": "final"}},
            "experiment": {"stop": 1.0, "step": 0.03, "algorithm": algorithm}}


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi-delayed"])
def test_arrays_are_carried_by_the_kernel_bit_for_bit(write_spec, version, algorithm):
    native, python, system = both(write_spec, array_spec(version, algorithm))
    assert system.kernel.kernel == "native" and native.status == "ok", native.message
    assert_identical(native, python)
    traces = native.traces
    assert (traces["g1.u[1]"] == 0.5).all() and (traces["g1.u[3]"] == -0.5).all()  # kept by the partial set
    assert traces["g1.u[2]"].nunique() > 20 and "g2[3]" in native.objectives


def test_arrays_under_jacobi_keep_the_python_master_for_their_feed_through(write_spec):
    spec = array_spec(3, "jacobi")
    system = build_system(load_spec(write_spec(spec)))
    assert system.kernel.kernel == "python" and "direct feed-through" in system.kernel.reason


def test_arrays_are_stepped_natively_one_step_at_a_time_too(write_spec):
    from cosim.master.observers import Observer

    spec = array_spec(3, "gauss-seidel")
    seen = []
    for kernel in ("native", "python"):
        spec["experiment"]["kernel"] = kernel
        system = build_system(load_spec(write_spec(spec, f"{kernel}.json")))
        watcher = type("W", (_Watcher, Observer), {})()
        result = Execution(system, record=True, observers=[watcher]).run()
        seen.append((result, watcher.rows))
    (native, rows_native), (python, rows_python) = seen
    assert_identical(native, python)
    assert [v.tobytes() for _, v in rows_native] == [v.tobytes() for _, v in rows_python]


@pytest.mark.parametrize("version", [2, 3])
def test_units_of_measure_are_converted_by_the_kernel_bit_for_bit(write_spec, tmp_path, version):
    """A player's rpm column into an FMU's rad/s array element, the FMU's rpm output into a rad/s system
    connector, a torque in N.m from another column: the unit conversions cosim derives, applied in C."""
    import pandas as pd

    table = tmp_path / "drive.csv"
    pd.DataFrame({"time": [0.0, 0.2, 0.5, 1.0], "n": [0.0, 3000.0, -1200.0, 450.0],
                  "torque": [0.0, 12.0, -3.0, 7.5]}).to_csv(table, index=False)
    spec = {"units": {"play": {"player": str(table), "units": {"n": "rpm", "torque": "N.m"}},
                      "energy": {"fmu": fmu("motor_gear_energy", version)},
                      "Root": {"connectors": "Root", "inputs": {"speed": "rad/s"}}},
            "connections": [{"from": "play.n", "to": "energy.omega[2]"}, {"from": "play.torque", "to": "energy.tau[2]"},
                            {"from": "energy.n_motor[2]", "to": "Root.speed"}],
            "record": ["play.n", "energy.omega", "energy.n_motor", "energy.e_el", "Root.speed"],
            "objectives": {"e": {"signal": "energy.e_total", "reduce": "final"},
                           "p": {"signal": "energy.p_el", "reduce": "max"},
                           "speed": {"signal": "Root.speed", "reduce": "integral_abs"}},
            "experiment": {"stop": 1.0, "step": 0.02}}
    native, python, system = both(write_spec, spec)
    assert system.kernel.kernel == "native" and native.status == "ok", native.message
    assert_identical(native, python)
    traces = native.traces
    rpm = np.pi / 30.0
    np.testing.assert_allclose(traces["energy.omega[2]"], traces["play.n"] * rpm, rtol=1e-15)
    assert traces["play.n"].abs().max() > 1000 and native.objectives["e"] != 0.0


def test_players_and_connectors_stepped_one_step_at_a_time_give_the_same_rows(write_spec, tmp_path):
    """An observer watching step by step: the kernel advances one step per call and the probe reads the player's
    values and the connectors' held values from the Python units, which the kernel keeps up to date."""
    from cosim.master.observers import Observer

    spec = player_spec(_table(tmp_path, "parquet"), 2, "gauss-seidel", "linear")
    spec["units"]["Root"] = {"connectors": "Root", "inputs": {"speed": ""}}
    spec["connections"].append({"from": "a.y", "to": "Root.speed", "factor": 3.0})
    spec["record"].append("Root.speed")
    seen = []
    for kernel in ("native", "python"):
        spec["experiment"]["kernel"] = kernel
        system = build_system(load_spec(write_spec(spec, f"{kernel}.json")))
        assert system.kernel.kernel == kernel
        watcher = type("W", (_Watcher, Observer), {})()
        result = Execution(system, record=True, observers=[watcher]).run()
        seen.append((result, watcher.rows))
    (native, rows_native), (python, rows_python) = seen
    assert_identical(native, python)
    assert len(rows_native) == 35 and native.traces["Root.speed"].nunique() > 20
    assert [v.tobytes() for _, v in rows_native] == [v.tobytes() for _, v in rows_python]
