"""The C framework's Model Exchange interface (FMI 2.0 and 3.0), checked with FMPy alone.

The FMUs are built from fmus/ with gcc; FMPy validates them and its own
simulate_fmu (CVode) runs them, so these tests check the C side independently
of cosim's model-exchange unit (tests/units/test_model_exchange_units.py).
"""

from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Model
from fmpy.fmi3 import FMU3Model
from fmpy.validation import validate_fmu

import cosim.fmus.build as build
from cosim.fmus.build import FmuBuildError, build_fmu, ensure_built

CHOICES = {"cs": ("CoSimulation",), "me": ("ModelExchange",), "cs,me": ("CoSimulation", "ModelExchange")}


def bounce_times(h0: float, g: float, e: float, v_min: float) -> list[float]:
    """Analytic bounce times of a ball dropped at rest from h0 (until it rests)."""
    t = math.sqrt(2 * h0 / g)
    v = g * t  # impact speed
    times = [t]
    while e * v >= v_min:
        v *= e
        t += 2 * v / g
        times.append(t)
    return times


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("choice", sorted(CHOICES))
def test_linear_ode_builds_with_each_interface_choice(choice, version, tmp_path):
    path = build_fmu("linear_ode", version, tmp_path, CHOICES[choice])
    assert validate_fmu(str(path)) == []
    md = read_model_description(str(path))
    assert (md.coSimulation is not None) == ("CoSimulation" in CHOICES[choice])
    assert (md.modelExchange is not None) == ("ModelExchange" in CHOICES[choice])
    if md.modelExchange is not None:
        assert md.numberOfContinuousStates == 1 and md.numberOfEventIndicators == 0
        assert [d.variable.name for d in md.derivatives] == ["der_y"]
        assert md.derivatives[0].variable.derivative.name == "y"


def test_default_builds_offer_what_model_json_declares():
    for name, cs, me in [("linear_ode", True, True), ("bouncing_ball", False, True), ("gain_array", True, False)]:
        md = read_model_description(str(ensure_built(name, 3)))
        assert (md.coSimulation is not None, md.modelExchange is not None) == (cs, me), name


def test_an_unsupported_interface_is_a_build_error(tmp_path):
    with pytest.raises(FmuBuildError, match="supports CoSimulation; cannot build ModelExchange"):
        build_fmu("gain_array", 3, tmp_path, ("ModelExchange",))
    with pytest.raises(FmuBuildError, match="supports ModelExchange; cannot build CoSimulation"):
        build_fmu("bouncing_ball", 2, tmp_path, ("CoSimulation",))


def test_model_json_states_are_checked(tmp_path, monkeypatch):
    copy = tmp_path / "fmus"
    shutil.copytree(build.FMUS_DIR, copy, ignore=shutil.ignore_patterns("__pycache__", "*.fmu"))
    monkeypatch.setattr(build, "FMUS_DIR", copy)
    monkeypatch.setattr(build, "COMMON_DIR", copy / "common")
    spec = json.loads((copy / "linear_ode" / "model.json").read_text())
    spec["variables"][-1]["derivative"] = "a"  # a parameter cannot be a state
    (copy / "linear_ode" / "model.json").write_text(json.dumps(spec))
    with pytest.raises(FmuBuildError, match="the state 'a' must be an output or local Real scalar"):
        build_fmu("linear_ode", 3, tmp_path / "out")


def _instantiate(path, version: int, interface: str, folder) -> list[str]:
    """Instantiate ``path`` for ``interface`` straight through the binary (FMPy would refuse
    from the modelDescription first); returns the logged messages, raises when refused."""
    from fmpy import extract
    from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
    from fmpy.fmi3 import FMU3Slave

    md = read_model_description(str(path))
    messages: list[str] = []
    unzipped = extract(str(path), unzipdir=str(folder))
    if version == 3:
        cls = FMU3Model if interface == "ModelExchange" else FMU3Slave
        fmu = cls(guid=md.guid, unzipDirectory=unzipped, modelIdentifier="linear_ode", instanceName="x")
        fmu.instantiate(logMessage=lambda env, status, cat, msg: messages.append(msg.decode()))
    else:
        cls = FMU2Model if interface == "ModelExchange" else FMU2Slave
        fmu = cls(guid=md.guid, unzipDirectory=unzipped, modelIdentifier="linear_ode", instanceName="x")
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(lambda env, name, status, cat, msg: messages.append(msg.decode()))
        try:
            fmu.instantiate(callbacks=callbacks)
        except Exception as exc:
            raise RuntimeError(messages) from exc
    fmu.freeInstance()
    return messages


@pytest.mark.parametrize("version", [2, 3])
def test_a_build_refuses_the_interface_it_does_not_offer(version, tmp_path):
    """An ME-only binary cannot be instantiated for co-simulation and vice versa; the FMU logs why."""
    me_only = build_fmu("linear_ode", version, tmp_path / "me", ("ModelExchange",))
    cs_only = build_fmu("linear_ode", version, tmp_path / "cs", ("CoSimulation",))
    _instantiate(me_only, version, "ModelExchange", tmp_path / "a")  # the offered interface works
    _instantiate(cs_only, version, "CoSimulation", tmp_path / "b")
    for path, wrong, message in [(me_only, "CoSimulation", "built without co-simulation"),
                                 (cs_only, "ModelExchange", "built without Model Exchange")]:
        with pytest.raises(Exception):
            _instantiate(path, version, wrong, tmp_path / wrong)


@pytest.mark.parametrize("version", [2, 3])
def test_linear_ode_model_exchange_with_fmpy_matches_the_exact_solution(version):
    rtol = 1e-9
    result = simulate_fmu(str(ensure_built("linear_ode", version)), fmi_type="ModelExchange", stop_time=2.0,
                          output_interval=0.05, relative_tolerance=rtol, start_values={"a": -1.5, "x0": 2.0})
    exact = 2.0 * np.exp(-1.5 * result["time"])
    # CVode's local error test keeps each step within rtol (absolute tolerance rtol * nominal 1);
    # 100 * rtol leaves room for the accumulation over the run.
    assert np.max(np.abs(result["y"] - exact)) < 100 * rtol


@pytest.mark.parametrize("version", [2, 3])
def test_bouncing_ball_with_fmpy_bounces_at_the_analytic_times(version):
    result = simulate_fmu(str(ensure_built("bouncing_ball", version)), stop_time=3.0, output_interval=0.01,
                          relative_tolerance=1e-8)
    expected = bounce_times(h0=1.0, g=9.81, e=0.7, v_min=0.1)
    located = np.unique(result["t_bounce"][result["bounces"] > 0])
    assert len(located) == len(expected) == result["bounces"][-1]
    # Local errors of ~rtol per step add up over a few hundred steps and carry from bounce to bounce
    # through the rebound speed (the 11th bounce is ~1e-6 off at rtol 1e-8): 1000 * rtol bounds them.
    assert np.max(np.abs(located - expected)) < 1000 * 1e-8
    assert result["resting"][-1] and result["h"][-1] == 0.0


@pytest.mark.parametrize("version", [2, 3])
def test_model_exchange_calls_check_mode_and_sizes(version, tmp_path):
    """The ME functions refuse wrong array sizes and calls in the wrong mode, with a logged message."""
    from fmpy import extract

    path = ensure_built("bouncing_ball", version)
    md = read_model_description(str(path))
    folder = extract(str(path), unzipdir=str(tmp_path / "x"))
    messages: list[str] = []
    cls = FMU3Model if version == 3 else FMU2Model
    fmu = cls(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.modelExchange.modelIdentifier, instanceName="b")
    if version == 3:
        fmu.instantiate(logMessage=lambda env, status, cat, msg: messages.append(msg.decode()))
        fmu.enterInitializationMode()
    else:
        from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(lambda env, name, status, cat, msg: messages.append(msg.decode()))
        fmu.instantiate(callbacks=callbacks)
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    with pytest.raises(Exception):
        fmu.completedIntegratorStep()  # not allowed in Event Mode
    assert any("completedIntegratorStep is not allowed" in m for m in messages)
    x = (np.ctypeslib.ctypes.c_double * 3)()
    with pytest.raises(Exception):
        fmu.getContinuousStates(x, 3)
    assert any("3 values given, the model has 2" in m for m in messages)
    fmu.getContinuousStates(x, 2)
    assert list(x[:2]) == [1.0, 0.0]
    fmu.terminate()
    fmu.freeInstance()
