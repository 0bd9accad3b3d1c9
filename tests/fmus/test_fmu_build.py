"""cosim.fmus.build and the test FMUs: real gcc builds, checked and run with real FMPy."""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
import zipfile

import fmpy
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu

import cosim.fmus.build as build
from cosim.fmus.build import FmuBuildError, build_fmu, ensure_built
from cosim.fmus.testing import FmuInstance
from tests.helpers.paths import REPO

MODELS = ["algebraic", "bouncing_ball", "counter", "decay", "fault", "gain_array", "linear_ode", "mass_spring", "motor_gear_energy",
          "panda_inverse_dynamics", "square_lag"]
# tests/fmus/test_fmu_model_exchange.py runs them (mass_spring: tests/master/test_coupled_model_exchange.py)
MODEL_EXCHANGE_ONLY = {"bouncing_ball", "mass_spring", "square_lag"}


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch):
    cache = tmp_path / "cache"
    monkeypatch.setenv("COSIM_FMU_CACHE", str(cache))
    return cache


@pytest.fixture
def fmus_copy(tmp_path, monkeypatch):
    """A copy of the fmus/ sources the builder is pointed at, free to edit."""
    copy = tmp_path / "fmus"
    shutil.copytree(REPO / "src" / "cosim" / "fmus", copy, ignore=shutil.ignore_patterns("__pycache__", "*.fmu"))
    monkeypatch.setattr(build, "FMUS_DIR", copy)
    monkeypatch.setattr(build, "COMMON_DIR", copy / "common")
    return copy


def test_available_models():
    assert build.available_models() == MODELS


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("name", MODELS)
def test_fmu_validates_and_simulates(name, version):
    path = ensure_built(name, version)
    assert path.name == f"{name}_fmi{version}.fmu"
    assert validate_fmu(str(path)) == []
    platform = fmpy.platform if version == 2 else fmpy.platform_tuple
    with zipfile.ZipFile(path) as zf:
        assert sorted(zf.namelist()) == sorted(["modelDescription.xml", f"binaries/{platform}/{name}.so"])
    md = read_model_description(str(path))
    assert md.fmiVersion == f"{version}.0"
    if name in MODEL_EXCHANGE_ONLY:
        assert md.coSimulation is None and md.modelExchange is not None
        return
    cs = md.coSimulation
    assert cs.canHandleVariableCommunicationStepSize and not cs.canBeInstantiatedOnlyOncePerProcess
    assert not cs.needsExecutionTool
    result = simulate_fmu(str(path), stop_time=1.0, output_interval=0.01)
    assert result["time"][-1] == pytest.approx(1.0)
    final = result[-1]
    if name == "linear_ode":
        assert final["y"] == pytest.approx(math.exp(-1.0), rel=1e-12)
    elif name == "decay":  # x starts at its declared start 1: x = e^{-t}
        assert final["x"] == pytest.approx(math.exp(-1.0), rel=1e-12)
    elif name == "fault":
        assert final["y"] == pytest.approx(1.0)
    elif name == "motor_gear_energy":
        assert final["e_total"] == 0.0  # no torque, no speed


def test_value_reference_conventions():
    """FMI 3: VR k = k-th variable of model.json (time 0); FMI 2: one VR per element, in order."""
    md3 = read_model_description(str(ensure_built("motor_gear_energy", 3)))
    md2 = read_model_description(str(ensure_built("motor_gear_energy", 2)))
    vars3 = [(v.name, v.valueReference, int(v.dimensions[0].start) if v.dimensions else 1) for v in md3.modelVariables]
    assert vars3[:4] == [("time", 0, 1), ("tau", 1, 7), ("omega", 2, 7), ("gear_ratio", 3, 7)]
    expected2 = [(name if size == 1 and name in ("time", "recuperation", "p_total", "e_total", "e_total_no_recuperation")
                  else f"{name}[{i}]") for name, _, size in vars3 for i in range(1, size + 1)]
    assert [v.name for v in md2.modelVariables] == expected2
    assert [v.valueReference for v in md2.modelVariables] == list(range(len(expected2)))
    units = {v.name: v.unit for v in md3.modelVariables}
    assert units["tau"] == "N.m" and units["omega"] == "rad/s" and units["n_motor"] == "rpm" and units["e_total"] == "J"
    assert {u.name for u in md3.unitDefinitions} >= {"N.m", "rad/s", "rpm", "A", "W", "J", "Ohm", "N.m/A"}
    assert md3.defaultExperiment.stepSize == "0.001"
    deps2 = {o.variable.name: [d.name for d in o.dependencies] for o in md2.outputs}
    assert deps2["tau_motor[3]"] == ["tau[3]", "omega[3]"] and deps2["e_el[1]"] == []
    assert sorted(d.name for d in md3.outputs[-1].dependencies) == []  # e_total_no_recuperation


def test_ensure_built_caches_by_source_digest(fresh_cache, fmus_copy):
    first = ensure_built("gain_array", 3)
    assert first.is_file() and fresh_cache in first.parents
    mtime = first.stat().st_mtime_ns
    assert ensure_built("gain_array", 3) == first and first.stat().st_mtime_ns == mtime  # not rebuilt
    with open(fmus_copy / "gain_array" / "model.c", "a") as f:
        f.write("\n/* an edit */\n")
    second = ensure_built("gain_array", 3)
    assert second != first and second.name == first.name and second.is_file()
    assert not list(fresh_cache.glob("*/build-*"))  # no temporary build folders left


def test_concurrent_builds_do_not_collide(fresh_cache):
    code = "from cosim.fmus.build import ensure_built; print(ensure_built('linear_ode', 2))"
    env = {**os.environ, "COSIM_FMU_CACHE": str(fresh_cache)}
    procs = [subprocess.Popen([sys.executable, "-c", code], cwd=REPO, env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(3)]
    outs = [p.communicate(timeout=120) for p in procs]
    assert all(p.returncode == 0 for p in procs), outs
    paths = {out.strip() for out, _ in outs}
    assert len(paths) == 1
    assert validate_fmu(paths.pop()) == []
    assert [p.name for p in fresh_cache.glob("*/*")] == ["linear_ode_fmi2.fmu"]


def test_missing_compiler_is_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.setenv("CC", "no-such-compiler-cosim")
    with pytest.raises(FmuBuildError, match=r"apt-get install gcc"):
        build_fmu("gain_array", 2, tmp_path)
    result = subprocess.run([sys.executable, "-m", "cosim.fmus.build", "--out", str(tmp_path), "gain_array"], cwd=REPO,
                            env={**os.environ, "CC": "no-such-compiler-cosim"}, capture_output=True, text=True)
    assert result.returncode == 1
    assert "apt-get install gcc" in result.stderr and "Traceback" not in result.stderr
    assert list(tmp_path.glob("*.fmu")) == []


def test_cli_builds_into_a_folder(tmp_path):
    result = subprocess.run([sys.executable, "-m", "cosim.fmus.build", "--out", str(tmp_path), "--fmi", "3", "gain_array"],
                            cwd=REPO, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert [p.name for p in tmp_path.iterdir()] == ["gain_array_fmi3.fmu"]
    assert result.stdout.strip() == str(tmp_path / "gain_array_fmi3.fmu")


def test_unknown_model_and_compile_errors(tmp_path, fmus_copy):
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(FmuBuildError, match="no FMU model 'nope'"):
        build_fmu("nope", 3, out)
    with pytest.raises(FmuBuildError, match="FMI version"):
        build_fmu("gain_array", 1, out)
    (fmus_copy / "gain_array" / "model.c").write_text("this is not C;\n")
    with pytest.raises(FmuBuildError, match=r"compiling gain_array \(FMI 2\) failed(.|\n)*error"):
        build_fmu("gain_array", 2, out)
    assert list(out.iterdir()) == []  # no FMU, no temporary folder


# -- the test FMUs ------------------------------------------------------------

@pytest.fixture(params=[2, 3], ids=["fmi2", "fmi3"])
def version(request):
    return request.param


def exact_ode(x, a, b, u, h):
    if a == 0:
        return x + h * b * u
    return math.exp(a * h) * x + (math.exp(a * h) - 1) / a * b * u


@pytest.mark.parametrize("a", [-0.7, 0.0, 0.3])
def test_linear_ode_steps_exactly_and_resets(version, a, tmp_path):
    with FmuInstance(ensure_built("linear_ode", version), unzip_parent=tmp_path) as ode:
        ode.instantiate()
        ode.initialize(a=a, b=2.0, x0=1.5)
        assert ode.get("y") == 1.5
        x, t = 1.5, 0.0
        for k, h in enumerate([0.1, 0.25, 0.05, 1.0, 0.5]):
            u = math.sin(k) + 0.5
            before = ode.get("y")
            ode.set("u", u)
            assert ode.get("y") == before  # no direct feed-through
            ode.step(t, h)
            x = exact_ode(x, a, 2.0, u, h)
            t += h
            assert ode.get("y") == pytest.approx(x, rel=1e-14, abs=1e-15)
        ode.reset()
        ode.initialize()
        assert ode.get("y") == 1.0 and ode.get("a") == -1.0  # start values are back


@pytest.mark.parametrize("version_", [2, 3])
def test_linear_ode_declares_no_feedthrough(version_):
    md = read_model_description(str(ensure_built("linear_ode", version_)))
    assert [(o.variable.name, o.dependencies) for o in md.outputs] == [("y", [])]


def test_fault_mode_3_returns_an_error_at_the_trigger(version, tmp_path):
    with FmuInstance(ensure_built("fault", version), unzip_parent=tmp_path) as fault:
        fault.instantiate()
        fault.initialize(mode=3, trigger_time=0.25)
        for k in range(3):  # t = 0, 0.1, 0.2 < trigger_time
            fault.step(k * 0.1, 0.1)
        assert fault.get("y") == pytest.approx(0.3)
        with pytest.raises(FMICallException):
            fault.step(0.3, 0.1)
        assert any(status == 3 and "fault mode 3" in text for status, text in fault.messages)


def test_fault_mode_4_outputs_nan_from_the_trigger(version, tmp_path):
    with FmuInstance(ensure_built("fault", version), unzip_parent=tmp_path) as fault:
        fault.instantiate()
        fault.initialize(mode=4, trigger_time=0.15)
        fault.step(0.0, 0.1)
        assert fault.get("y") == pytest.approx(0.1)
        fault.step(0.1, 0.1)
        assert fault.get("y") == pytest.approx(0.2)
        fault.step(0.2, 0.1)
        assert math.isnan(fault.get("y"))
        fault.step(0.3, 0.1)
        assert math.isnan(fault.get("y"))


def test_fault_refuses_unknown_mode(version, tmp_path):
    with FmuInstance(ensure_built("fault", version), unzip_parent=tmp_path) as fault:
        fault.instantiate()
        with pytest.raises(FMICallException):
            fault.initialize(mode=7)
        assert any("mode = 7" in text for _, text in fault.messages)


def test_gain_array_feeds_through(version, tmp_path):
    with FmuInstance(ensure_built("gain_array", version), unzip_parent=tmp_path) as gain:
        assert gain.variables["u"][2] and len(gain.variables["u"][1]) == 3
        gain.instantiate()
        gain.initialize(k=3.0)
        gain.set("u", [1.0, -2.0, 0.5])
        assert gain.get("y").tolist() == [3.0, -6.0, 1.5]  # before any step
        gain.step(0.0, 0.1)
        gain.set("u", [0.0, 1.0, 2.0])
        assert gain.get("y").tolist() == [0.0, 3.0, 6.0]


def test_framework_refuses_misuse(version, tmp_path):
    with FmuInstance(ensure_built("gain_array", version), unzip_parent=tmp_path) as gain:
        gain.instantiate(logging_on=True)
        assert any("instantiated gain_array" in text for _, text in gain.messages)  # info when logging is on
        gain.initialize()
        with pytest.raises(FMICallException):
            gain.set("y", [1.0, 2.0, 3.0])  # an output
        with pytest.raises(FMICallException):
            gain.set("k", 5.0)  # a fixed parameter after initialization
        assert any("'y' is not a parameter or input" in text for _, text in gain.messages)
        assert any("parameter 'k'" in text for _, text in gain.messages)
        with pytest.raises(FMICallException):
            gain.slave.getFloat64([99]) if version == 3 else gain.slave.getReal([99])


def test_wrong_instantiation_token_is_refused(tmp_path):
    with FmuInstance(ensure_built("gain_array", 3), unzip_parent=tmp_path) as gain:
        other = FMU3Slave(guid="{00000000-0000-0000-0000-000000000000}", unzipDirectory=gain.unzipdir,
                          modelIdentifier="gain_array", instanceName="x")
        messages = []
        with pytest.raises(Exception, match="Failed to instantiate"):
            other.instantiate(logMessage=lambda env, status, cat, msg: messages.append(msg.decode()))
        assert any("does not match" in m for m in messages)


@pytest.mark.parametrize("mode", [1, 2])
def test_fault_modes_1_and_2_crash_or_hang_a_separate_process(mode, tmp_path):
    """Run in a child process: mode 1 dies of SIGSEGV, mode 2 never returns from doStep."""
    code = (f"from cosim.fmus.testing import FmuInstance\n"
            f"f = FmuInstance({str(ensure_built('fault', 3))!r}, unzip_parent={str(tmp_path)!r})\n"
            f"f.instantiate(); f.initialize(mode={mode}, trigger_time=0.1)\n"
            f"f.step(0.0, 0.1); print('stepped', flush=True); f.step(0.1, 0.1); print('survived', flush=True)\n")
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    # No deadline on the child's start (a loaded machine may take seconds to import): wait for its first step.
    first = proc.stdout.readline()
    try:
        # the hang is checked by waiting 3 s past the first step: a working doStep of 0.1 s takes microseconds
        out, _ = proc.communicate(timeout=3 if mode == 2 else 60)
        hung = False
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
        hung = True
    assert first == "stepped\n" and "survived" not in out
    if mode == 1:
        assert proc.returncode == -11  # SIGSEGV
    else:
        assert hung


@pytest.mark.parametrize("version", [2, 3])
def test_a_state_declared_exact_takes_its_start_value_before_initialization_only(version, tmp_path):
    # decay's x: initial="exact", start 1, not an initial unknown; set before initialization the model starts there
    path = str(ensure_built("decay", version))
    md = read_model_description(path)
    x = next(v for v in md.modelVariables if v.name == "x")
    assert (x.causality, x.initial, x.start) == ("output", "exact", "1.0")
    assert "x" not in [u.variable.name for u in md.initialUnknowns]
    for interface in ("CoSimulation", "ModelExchange"):
        result = simulate_fmu(path, fmi_type=interface, start_values={"x": 3.0, "k": 0.5}, stop_time=2.0,
                              output_interval=0.1)
        assert result["x"][0] == 3.0
        # co-simulation exact; model exchange by fmpy's CVode at its default tolerance
        assert result["x"][-1] == pytest.approx(3.0 * math.exp(-1.0), rel=1e-12 if interface == "CoSimulation"
                                                else 1e-3)
    with FmuInstance(path, unzip_parent=tmp_path) as fmu:
        fmu.instantiate()
        fmu.set("x", 2.0)  # before initialization: the start value
        fmu.initialize(k=0.5)
        assert fmu.get("x") == 2.0
        fmu.step(0.0, 1.0)
        assert fmu.get("x") == pytest.approx(2.0 * math.exp(-0.5), rel=1e-15)
        with pytest.raises(FMICallException):  # after initialization a set of x is refused, as FMI says
            fmu.set("x", 2.0)
