"""The motor_gear_energy FMU (FMI 2 and 3) and Python unit against an independent implementation.

The reference below is written from the thesis (section 7.2.2) and the unit's
documentation (fmus/README.md), scalar by scalar, deliberately unlike the C and numpy code: the
gear table is searched by hand and the mechanical power is computed from the
motor speed in rpm converted back to rad/s (n * 2 pi / 60), the unit the
thesis's eq. 7-16 gets wrong when read literally.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException

from cosim.fmus.build import ensure_built
from cosim.fmus.testing import FmuInstance

N = 7
OUTPUTS = ("n_motor", "eta_gear", "tau_motor", "i_motor", "p_el")
DEFAULTS = dict(gear_ratio=[100.0] * N, r_terminal=[0.22] * N, k_m=[0.134] * N, eta_motor=[0.92] * N,
                eta_gear_speed=[500.0, 1000.0, 2000.0, 3000.0], eta_gear_value=[0.75, 0.69, 0.63, 0.58])
# Another motor per joint, to catch parameters that are read from the wrong element.
CUSTOM = dict(gear_ratio=[50.0, 80.0, 100.0, 120.0, 160.0, 101.0, 99.0], r_terminal=[0.1, 0.2, 0.3, 0.0, 0.5, 0.22, 1.0],
              k_m=[0.05, 0.1, 0.134, 0.2, 0.3, 0.4, 0.15], eta_motor=[0.8, 0.85, 0.9, 0.92, 0.95, 1.0, 0.7],
              eta_gear_speed=[100.0, 1500.0, 2500.0, 5000.0], eta_gear_value=[0.9, 0.8, 0.5, 0.45])


def gear_efficiency(speed_rpm: float, speeds: list[float], values: list[float]) -> float:
    a = abs(speed_rpm)
    if a <= speeds[0]:
        return values[0]
    if a >= speeds[-1]:
        return values[-1]
    for k in range(len(speeds) - 1):
        lo, hi = speeds[k], speeds[k + 1]
        if lo <= a <= hi:
            w = (a - lo) / (hi - lo)
            return (1.0 - w) * values[k] + w * values[k + 1]
    raise AssertionError("unreachable")


def reference_joint(tau: float, omega: float, j: int, p: dict, recuperation: bool) -> dict[str, tuple[float, float]]:
    """Outputs of joint ``j`` as (value, scale): scale bounds the rounding of value."""
    R = p["gear_ratio"][j]
    n = omega * 60.0 / (2.0 * math.pi) * R  # eq. 7-13, rpm
    eta_g = gear_efficiency(n, p["eta_gear_speed"], p["eta_gear_value"])
    eta_m = p["eta_motor"][j]
    if tau * omega >= 0.0:  # motoring, standstill under load included
        tau_m = tau / (eta_g * eta_m) / R
    else:  # recuperating
        tau_m = eta_g * eta_m * tau / R
    current = tau_m / p["k_m"][j]
    loss = p["r_terminal"][j] * current**2
    p_motor = tau_m * (n * 2.0 * math.pi / 60.0)  # motor torque x motor speed in rad/s
    p_el = loss + p_motor
    if not recuperation:
        p_el = max(p_el, 0.0)
    return {"n_motor": (n, abs(n)), "eta_gear": (eta_g, 1.0), "tau_motor": (tau_m, abs(tau_m)),
            "i_motor": (current, abs(current)), "p_el": (p_el, loss + abs(p_motor))}


def reference(tau, omega, p, recuperation):
    joints = [reference_joint(float(tau[j]), float(omega[j]), j, p, recuperation) for j in range(N)]
    out = {k: (np.array([jo[k][0] for jo in joints]), np.array([jo[k][1] for jo in joints])) for k in OUTPUTS}
    out["p_total"] = (out["p_el"][0].sum(), out["p_el"][1].sum())
    return out


def assert_matches(actual, expected, scale, what):
    """Relative 1e-12, with an absolute floor of 1e-12 times the size of the terms summed (cancellation)."""
    actual, expected, scale = np.atleast_1d(actual), np.atleast_1d(expected), np.atleast_1d(scale)
    tol = 1e-12 * np.maximum(np.abs(expected), scale) + 1e-300
    bad = np.abs(actual - expected) > tol
    assert not bad.any(), f"{what}: {actual[bad]} != {expected[bad]}"


def random_operating_points(rng: np.random.Generator, count: int, ratio: np.ndarray):
    """Joint torques and speeds covering every branch of the model."""
    rpm_to_omega = 2.0 * math.pi / 60.0 / ratio
    kinds = rng.integers(0, 6, size=(count, N))
    omega = np.select(
        [kinds == 0, kinds == 1, kinds == 2, kinds == 3, kinds == 4],
        [np.zeros((count, N)),                                                  # standstill
         rng.uniform(-400, 400, (count, N)) * rpm_to_omega,                     # below the first table point
         rng.uniform(-3000, 3000, (count, N)) * rpm_to_omega,                   # inside the table
         rng.choice([-1, 1], (count, N)) * rng.uniform(3000, 9000, (count, N)) * rpm_to_omega,  # beyond the last
         rng.choice([500.0, 1000.0, 2000.0, 3000.0, -1000.0], (count, N)) * rpm_to_omega],      # on table points
        rng.normal(0, 1.5, (count, N)))
    tau = rng.uniform(-90, 90, (count, N))
    tau[rng.random((count, N)) < 0.05] = 0.0  # no load
    return tau, omega


@pytest.fixture(scope="module", params=[2, 3], ids=["fmi2", "fmi3"])
def fmu(request, tmp_path_factory):
    path = ensure_built("motor_gear_energy", request.param)
    with FmuInstance(path, unzip_parent=tmp_path_factory.mktemp("unzip")) as inst:
        yield inst


def start(inst: FmuInstance, params: dict, recuperation: bool) -> None:
    if inst.instantiated:
        inst.free_instance()
    inst.instantiate()
    inst.initialize(recuperation=recuperation, **params)


@pytest.mark.parametrize("params_name", ["defaults", "custom"])
@pytest.mark.parametrize("recuperation", [True, False])
def test_outputs_match_independent_reference(fmu, params_name, recuperation):
    params = DEFAULTS if params_name == "defaults" else CUSTOM
    start(fmu, params, recuperation)
    rng = np.random.default_rng(7 + recuperation + 2 * (params_name == "custom"))
    count = 300
    taus, omegas = random_operating_points(rng, count, np.array(params["gear_ratio"]))
    seen = {"motoring": 0, "braking": 0, "standstill_load": 0, "below_first": 0, "beyond_last": 0, "clipped": 0}
    for tau, omega in zip(taus, omegas):
        fmu.set("tau", tau)
        fmu.set("omega", omega)
        ref = reference(tau, omega, params, recuperation)
        for name in (*OUTPUTS, "p_total"):
            assert_matches(fmu.get(name), *ref[name], what=f"{name} at tau={tau} omega={omega}")
        n = np.abs(ref["n_motor"][0])
        power = tau * omega
        seen["motoring"] += int(np.sum(power > 0))
        seen["braking"] += int(np.sum(power < 0))
        seen["standstill_load"] += int(np.sum((omega == 0) & (tau != 0)))
        seen["below_first"] += int(np.sum((n < params["eta_gear_speed"][0]) & (omega != 0)))
        seen["beyond_last"] += int(np.sum(n > params["eta_gear_speed"][-1]))
        seen["clipped"] += int(np.sum(reference(tau, omega, params, True)["p_el"][0] < 0))
    # 4 parameter/recuperation combinations x 2 FMI versions x 300 points x 7 joints; each branch often.
    assert min(seen.values()) > 100, seen


def test_physics_by_hand(fmu):
    """Spot values computed on paper, independent of any table search."""
    start(fmu, DEFAULTS, True)
    # Joint 1 motoring slowly (eta_gear = 0.75), joint 2 holding a load at standstill,
    # joint 3 braking at 2000 rpm (eta_gear = 0.63), joint 4 unloaded, 5-7 idle.
    omega_2000rpm = 2000.0 * 2 * math.pi / 60 / 100
    fmu.set("tau", [10.0, 20.0, -5.0, 0.0, 0.0, 0.0, 0.0])
    fmu.set("omega", [0.2, 0.0, omega_2000rpm, 1.0, 0.0, 0.0, 0.0])
    tau_m = fmu.get("tau_motor")
    p_el = fmu.get("p_el")
    eta1, eta3 = 0.75 * 0.92, 0.63 * 0.92
    assert tau_m[0] == pytest.approx(10.0 / (100 * eta1), rel=1e-14)
    # Motoring power = copper loss + tau*omega/eta: the mechanical part uses rad/s, not rpm (60/2pi too large).
    i1 = 10.0 / (100 * eta1) / 0.134
    assert p_el[0] == pytest.approx(0.22 * i1**2 + 10.0 * 0.2 / eta1, rel=1e-13)
    i2 = 20.0 / (100 * eta1) / 0.134  # standstill under load is motoring: current / eta, not * eta
    assert fmu.get("i_motor")[1] == pytest.approx(i2, rel=1e-14)
    assert p_el[1] == pytest.approx(0.22 * i2**2, rel=1e-13)
    i3 = -5.0 * eta3 / 100 / 0.134
    assert p_el[2] == pytest.approx(0.22 * i3**2 - 5.0 * omega_2000rpm * eta3, rel=1e-13)
    assert p_el[2] < 0  # recuperating
    assert fmu.get("eta_gear")[2] == pytest.approx(0.63, rel=1e-14)
    assert fmu.get("n_motor")[2] == pytest.approx(2000.0, rel=1e-14)
    n4 = 1.0 * 100 * 60 / (2 * math.pi)  # 954.9 rpm: between the 500 and 1000 rpm points
    assert fmu.get("eta_gear")[3] == pytest.approx(0.75 + (0.69 - 0.75) * (n4 - 500) / 500, rel=1e-14)
    assert p_el[3] == 0.0  # no load, no power
    assert fmu.get("p_total") == pytest.approx(p_el.sum(), rel=1e-14)


@pytest.mark.parametrize("recuperation", [True, False])
def test_energies_integrate_held_power_exactly(fmu, recuperation):
    start(fmu, DEFAULTS, recuperation)
    rng = np.random.default_rng(11)
    taus, omegas = random_operating_points(rng, 200, np.array(DEFAULTS["gear_ratio"]))
    t, e_el, e_total, e_drawn = 0.0, np.zeros(N), 0.0, 0.0
    for k, (tau, omega) in enumerate(zip(taus, omegas)):
        h = 1e-3 * (1 + k % 3)  # variable communication steps
        fmu.set("tau", tau)
        fmu.set("omega", omega)
        fmu.step(t, h)
        p_el = reference(tau, omega, DEFAULTS, recuperation)["p_el"][0]
        p_phys = reference(tau, omega, DEFAULTS, True)["p_el"][0]
        e_el += p_el * h
        e_total = e_el.sum()
        e_drawn += np.maximum(p_phys, 0.0).sum() * h
        t += h
    np.testing.assert_allclose(fmu.get("e_el"), e_el, rtol=1e-11, atol=1e-12)
    assert fmu.get("e_total") == pytest.approx(e_total, rel=1e-11)
    assert fmu.get("e_total_no_recuperation") == pytest.approx(e_drawn, rel=1e-11)
    if recuperation:
        assert fmu.get("e_total") < fmu.get("e_total_no_recuperation")  # braking energy came back
    else:
        assert fmu.get("e_total") == pytest.approx(fmu.get("e_total_no_recuperation"), rel=1e-11)


@pytest.mark.parametrize("port,value", [("tau", math.nan), ("omega", math.inf), ("tau", -math.inf)])
def test_non_finite_input_is_an_error_with_a_message(fmu, port, value):
    start(fmu, DEFAULTS, True)
    bad = np.ones(N)
    bad[2] = value
    fmu.set(port, bad)
    fmu.messages.clear()
    with pytest.raises(FMICallException) as get_error:
        fmu.get("p_el")
    assert "error" in str(get_error.value)
    with pytest.raises(FMICallException):
        fmu.step(0.0, 1e-3)
    assert any(status == 3 and f"{port}[3]" in text for status, text in fmu.messages), fmu.messages
    # A finite input makes the instance usable again.
    fmu.set(port, np.ones(N))
    fmu.step(0.0, 1e-3)
    assert np.all(np.isfinite(fmu.get("e_el")))


@pytest.mark.parametrize("name,value,expected", [
    ("r_terminal", [0.22, -0.1, 0.22, 0.22, 0.22, 0.22, 0.22], "r_terminal[2]"),
    ("k_m", [0.134] * 6 + [0.0], "k_m[7]"),
    ("gear_ratio", [-100.0] + [100.0] * 6, "gear_ratio[1]"),
    ("eta_motor", [0.92] * 3 + [1.2] + [0.92] * 3, "eta_motor[4]"),
    ("eta_gear_value", [0.75, 0.0, 0.63, 0.58], "eta_gear_value[2]"),
    ("eta_gear_speed", [500.0, 2000.0, 1000.0, 3000.0], "strictly increasing"),
    ("eta_gear_speed", [500.0, 500.0, 2000.0, 3000.0], "strictly increasing"),
])
def test_bad_parameters_are_refused_at_initialization(fmu, name, value, expected):
    if fmu.instantiated:
        fmu.free_instance()
    fmu.instantiate()
    fmu.messages.clear()
    with pytest.raises(FMICallException):
        fmu.initialize(**{name: value})
    assert any(status == 3 and expected in text for status, text in fmu.messages), fmu.messages
    with pytest.raises(FMICallException):  # no stepping after a failed initialization
        fmu.step(0.0, 1e-3)
    fmu.reset()  # reset restores the start values: the defaults initialize fine
    fmu.initialize()
    fmu.step(0.0, 1e-3)


def test_python_unit_agrees_with_the_fmu(tmp_path):
    from cosim.models.motor_gear_energy import MotorGearEnergy

    rng = np.random.default_rng(3)
    with FmuInstance(ensure_built("motor_gear_energy", 3), unzip_parent=tmp_path) as fmu:
        for params, recuperation in ((DEFAULTS, True), (CUSTOM, False)):
            if fmu.instantiated:
                fmu.free_instance()
            fmu.instantiate()
            fmu.initialize(recuperation=recuperation, **params)
            unit = MotorGearEnergy("e")
            unit.set_values({**params, "recuperation": recuperation})
            unit.exit_initialization()
            taus, omegas = random_operating_points(rng, 200, np.array(params["gear_ratio"]))
            t = 0.0
            names = [*OUTPUTS, "p_total", "e_el", "e_total", "e_total_no_recuperation"]
            for tau, omega in zip(taus, omegas):
                fmu.set("tau", tau)
                fmu.set("omega", omega)
                unit.set_values({"tau": tau, "omega": omega})
                got = unit.get_values(names)
                for name in names:
                    expected = fmu.get(name)
                    np.testing.assert_allclose(got[name], expected, rtol=1e-12, atol=1e-9, err_msg=name)
                fmu.step(t, 1e-3)
                unit.do_step(t, 1e-3)
                t += 1e-3
            assert unit.get_values(["e_total"])["e_total"] == pytest.approx(fmu.get("e_total"), rel=1e-12)


def test_python_unit_has_the_fmu_ports():
    from fmpy import read_model_description

    from cosim.models.motor_gear_energy import MotorGearEnergy

    md = read_model_description(str(ensure_built("motor_gear_energy", 3)))
    fmu_ports = {(v.name, v.causality, v.type.replace("Float64", "Real"),
                  int(v.dimensions[0].start) if v.dimensions else 1)
                 for v in md.modelVariables if v.causality != "independent"}
    unit_ports = {(v.name, v.causality, v.type, v.size) for v in MotorGearEnergy.describe_class().variables}
    assert unit_ports == fmu_ports
    fmu_deps = {o.variable.name: sorted(d.name for d in o.dependencies) for o in md.outputs}
    unit_deps = {k: sorted(v) for k, v in MotorGearEnergy.describe_class().feedthrough.items()}
    assert unit_deps == fmu_deps


def test_python_unit_refuses_bad_values():
    from cosim.models.motor_gear_energy import MotorGearEnergy
    from cosim.units.protocol import UnitError

    unit = MotorGearEnergy("e")
    unit.set_values({"r_terminal": -1.0})
    with pytest.raises(UnitError, match=r"r_terminal\[1\]"):
        unit.exit_initialization()
    unit = MotorGearEnergy("e")
    unit.exit_initialization()
    unit.set_values({"tau[4]": math.nan})
    with pytest.raises(UnitError, match=r"tau\[4\]"):
        unit.get_values(["p_el"])


@pytest.mark.parametrize("version", [2, 3])
def test_swapping_fmu_and_python_unit_through_the_engine(version):
    """The engine's FMU unit and the Python unit answer the same calls with the same values."""
    from cosim.models.motor_gear_energy import MotorGearEnergy
    from cosim.units.fmu.description import FmuUnitType

    rng = np.random.default_rng(5)
    units = [FmuUnitType(str(ensure_built("motor_gear_energy", version))).instantiate("e"), MotorGearEnergy("e")]
    for unit in units:
        unit.setup(0.0, 1.0)
        unit.enter_initialization()
        unit.set_values({"recuperation": False, "k_m[2]": 0.2})
        unit.exit_initialization()
    ports = [f"{name}[{j}]" for name in ("p_el", "tau_motor", "e_el") for j in range(1, N + 1)]
    ports += ["p_total", "e_total", "e_total_no_recuperation"]
    taus, omegas = random_operating_points(rng, 50, np.full(N, 100.0))
    for k, (tau, omega) in enumerate(zip(taus, omegas)):
        inputs = {f"tau[{j + 1}]": tau[j] for j in range(N)} | {f"omega[{j + 1}]": omega[j] for j in range(N)}
        values = []
        for unit in units:
            unit.set_values(inputs)
            unit.do_step(k * 0.01, 0.01)
            values.append(unit.get_values(ports))
        for port in ports:
            assert values[0][port] == pytest.approx(values[1][port], rel=1e-12, abs=1e-9), port
    assert values[0]["e_total"] > 0
    for unit in units:
        unit.terminate()
