"""The unit-kind registry: built-in kinds own their schema fields; a kind added from outside the package works
in validate, run and sweep (found through the ``cosim.unit_kinds`` entry point, as an installed plug-in is)."""

from __future__ import annotations

import importlib
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from cosim import errors
from cosim.cli.exit_codes import EXIT_USAGE
from cosim.cli.main import main
from cosim.units import registry as unit_kinds
from cosim.units.kind import UnitKind
from cosim.units.registry import register_unit_kind, unregister_unit_kind
from tests.helpers.paths import REPO

ROOT = REPO
PLUGIN = ROOT / "examples" / "plugin_unit_kind"


def lag_of_square_wave(t_end: float, frequency: float, amplitude: float, tau: float) -> tuple[float, float]:
    """(x(t_end), max x) of tau x' = u - x, x(0) = 0, u a square wave +-amplitude: exact, half-period by half-period."""
    half = 0.5 / frequency
    x, t, peak, sign = 0.0, 0.0, 0.0, 1.0
    while t < t_end - 1e-12:
        dt = min(half, t_end - t)
        x = sign * amplitude + (x - sign * amplitude) * math.exp(-dt / tau)
        peak, t, sign = max(peak, x), t + dt, -sign
    return x, peak


def install_plugin(site: Path) -> None:
    """What `pip install examples/plugin_unit_kind` leaves in site-packages: the module and its entry point."""
    site.mkdir(parents=True, exist_ok=True)
    shutil.copy(PLUGIN / "cosim_signals.py", site)
    info = site / "cosim_signals-0.1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: cosim-signals\nVersion: 0.1.0\n")
    entry = [line for line in (PLUGIN / "pyproject.toml").read_text().splitlines() if line.startswith("signal =")]
    (info / "entry_points.txt").write_text("[cosim.unit_kinds]\n" + entry[0].replace('"', "") + "\n")  # TOML -> INI


def test_builtin_kinds_own_the_unit_fields_of_the_schema_file():
    """specs/spec.schema.json lists the built-in kinds' fields for editors; they must be the registry's."""
    schema = json.loads((ROOT / "src" / "cosim" / "spec" / "spec.schema.json").read_text())
    in_file = schema["$defs"]["unit"]["properties"]
    builtin = [unit_kinds.unit_kind(name) for name in unit_kinds.BUILTIN_KINDS]
    owned = {name: fragment for kind in builtin for name, fragment in kind.fields.items()}
    assert {k: v for k, v in in_file.items() if k not in unit_kinds.COMMON_FIELDS} == owned
    assert [b["required"] for b in schema["$defs"]["unit"]["oneOf"]] == [[k] for k in unit_kinds.BUILTIN_KINDS]


def test_builtin_kinds_are_declared_as_plug_ins_declare_theirs():
    """Each built-in kind sits beside its units and is named by the cosim.unit_kinds entry points of
    pyproject.toml, exactly as the registry loads it; the registry imports none of them."""
    import tomllib

    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]["cosim.unit_kinds"]
    assert declared == unit_kinds.BUILTIN_KINDS
    for name, target in declared.items():
        module, _, attribute = target.partition(":")
        kind = getattr(importlib.import_module(module), attribute)
        assert kind is unit_kinds.unit_kind(name) and kind.name == name
    registry_source = (ROOT / "src" / "cosim" / "units" / "registry.py").read_text()
    assert not any(f"import {t.partition(':')[0]}" in registry_source or f"from {t.partition(':')[0]} import"
                   in registry_source for t in declared.values())


def test_a_kind_installed_from_outside_runs_in_validate_run_and_sweep(tmp_path):
    site = tmp_path / "site"
    install_plugin(site)
    shutil.copy(PLUGIN / "spec.json", tmp_path)
    shutil.copy(PLUGIN / "lag.py", tmp_path)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), str(ROOT), os.environ.get("PYTHONPATH", "")]))

    def cosim(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "cosim.cli.main", *args], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=300)

    done = cosim("validate", "spec.json")
    assert done.returncode == 0, done.stderr
    done = cosim("inspect", "spec.json")
    assert done.returncode == 0 and "source: signal square (0 inputs, 1 outputs)" in done.stdout, done.stdout
    done = cosim("run", "spec.json", "--set", "source.frequency=2", "--out", "traces.parquet")
    assert done.returncode == 0, done.stderr
    traces = pd.read_parquet(tmp_path / "traces.parquet")
    # the square wave: +0.5 in the first half period, -0.5 in the second
    assert traces["source.y"].iloc[1:250].eq(0.5).all() and traces["source.y"].iloc[251:500].eq(-0.5).all()
    x_end, _ = lag_of_square_wave(1.0, 2.0, 0.5, 0.1)
    assert traces["lag.x"].iloc[-1] == pytest.approx(x_end, abs=0.01)  # one-step delay of a sampled input
    done = cosim("sweep", "spec.json", "--out", "sweep", "--workers", "1")
    assert done.returncode == 0, done.stderr
    table = pd.read_parquet(tmp_path / "sweep" / "results.parquet")
    assert list(table["status"]) == ["ok"] * 3
    for frequency, x_end, x_max in zip(table["source.frequency"], table["x_end"], table["x_max"]):
        expected_end, expected_max = lag_of_square_wave(1.0, frequency, 0.5, 0.1)
        assert x_end == pytest.approx(expected_end, abs=0.01) and x_max == pytest.approx(expected_max, abs=0.01)


@pytest.fixture
def signal_kind():
    sys.path.insert(0, str(PLUGIN))
    try:
        import cosim_signals

        yield register_unit_kind(cosim_signals.KIND)
    finally:
        unregister_unit_kind("signal")
        sys.path.remove(str(PLUGIN))


def test_an_explicitly_registered_kind_is_named_in_messages(tmp_path, capsys, signal_kind):
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"units": {"a": {"parameters": {}}, "b": {"signal": "triangle"}},
                                "experiment": {"stop": 1, "step": 0.1}}))
    assert main(["validate", str(spec)]) == EXIT_USAGE
    err = capsys.readouterr().err
    assert "$.units.a: a unit needs exactly one of 'fmu', 'python', 'player', 'connectors' or 'signal'" in err
    assert '"signal": "sine"' in err
    assert "$.units.b.signal: 'triangle' is not allowed" in err and "use one of: sawtooth, sine, square" in err


def test_a_kind_reports_its_own_problems_at_the_unit(tmp_path, capsys):
    def create(unit_spec, folder):
        raise errors.UserError("no such device", file=unit_spec.source, fix="plug the device in")

    register_unit_kind(UnitKind("device", {"device": {"type": "string"}}, create, example='"device": "/dev/x"'))
    try:
        spec = tmp_path / "spec.json"
        spec.write_text(json.dumps({"units": {"d": {"device": "/dev/none"}}, "experiment": {"stop": 1, "step": 0.1}}))
        assert main(["validate", str(spec)]) == EXIT_USAGE
        err = capsys.readouterr().err
        assert "$.units.d.device: device '/dev/none': no such device" in err and "fix: plug the device in" in err
    finally:
        unregister_unit_kind("device")


def test_registering_checks_names():
    create = unit_kinds.unit_kind("fmu").create
    with pytest.raises(errors.InternalError, match="already registered"):
        register_unit_kind(UnitKind("fmu", {"fmu": {}}, create))
    with pytest.raises(errors.InternalError, match="common unit field"):
        register_unit_kind(UnitKind("odd", {"odd": {}, "parameters": {}}, create))
    with pytest.raises(errors.InternalError, match="one of its fields"):
        register_unit_kind(UnitKind("odd", {"other": {}}, create))
    with pytest.raises(errors.InternalError, match="cannot be removed"):
        unregister_unit_kind("python")
    assert list(unit_kinds.unit_kinds())[:3] == ["fmu", "python", "player"]


def test_a_field_of_another_kind_is_reported_naming_the_kinds_that_take_it(tmp_path, capsys):
    def create(unit_spec, folder):
        return unit_kinds.PYTHON.create(unit_spec, folder)

    register_unit_kind(UnitKind("gadget", {"gadget": {"type": "string"}, "columns": {"type": "array"},
                                           "speed": {"type": "number"}}, create))
    try:
        spec = tmp_path / "spec.json"
        spec.write_text(json.dumps({"units": {
            "f": {"fmu": "builtin:linear_ode_fmi3", "columns": ["x"]},  # a player's field: was silently ignored
            "p": {"player": "t.csv", "tolerance": 1e-6, "speed": 2},
            "g": {"gadget": "tests.helpers.units_for_tests:Gain", "columns": ["y"]}},  # its own field: no problem
            "experiment": {"stop": 1, "step": 0.1}}))
        assert main(["validate", str(spec)]) == EXIT_USAGE
        err = capsys.readouterr().err
        assert "$.units.f.columns: 'columns' applies to player or gadget units only" in err
        assert "$.units.p.tolerance: 'tolerance' applies to fmu units only" in err
        assert "$.units.p.speed: 'speed' applies to gadget units only" in err
        assert "$.units.g.columns" not in err
    finally:
        unregister_unit_kind("gadget")


def test_an_ssp_export_refuses_a_plug_in_kind_by_name(tmp_path, capsys, signal_kind):
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"units": {"source": {"signal": "sine"}}, "experiment": {"stop": 1, "step": 0.1}}))
    assert main(["export", str(spec), "-o", str(tmp_path / "x.ssp")]) == EXIT_USAGE
    err = capsys.readouterr().err
    assert "$.units.source: a signal unit cannot be exported to an SSP" in err and "Traceback" not in err
    assert not (tmp_path / "x.ssp").exists()
