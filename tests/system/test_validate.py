"""`cosim validate`: every mistake of a spec at once, with its JSON path, exit code 2."""

from __future__ import annotations

import json
import re
import shutil
import zipfile
from pathlib import Path

import pytest

from cosim.cli.main import main
from tests.helpers.tools import python_unit


def validate(capsys, path: Path) -> tuple[int, str]:
    code = main(["validate", str(path)])
    captured = capsys.readouterr()
    return code, captured.out + captured.err


def rewrite_fmu(source: Path, target: Path, *, drop_prefix: str | None = None,
                edit_xml=None, extra: dict[str, bytes] | None = None) -> Path:
    """Copy an FMU, dropping members, editing modelDescription.xml or adding members."""
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(target, "w") as zout:
        for item in zin.infolist():
            if drop_prefix and item.filename.startswith(drop_prefix):
                continue
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml" and edit_xml:
                data = edit_xml(data.decode()).encode()
            zout.writestr(item, data)
        for name, data in (extra or {}).items():
            zout.writestr(name, data)
    return target


def test_a_spec_with_many_mistakes_lists_each_with_its_path(tmp_path, capsys, built_fmu):
    gain2 = shutil.copy(built_fmu("gain_array", 2), tmp_path / "gain2.fmu")
    shutil.copy(built_fmu("linear_ode", 3), tmp_path / "ode3.fmu")
    shutil.copy(built_fmu("motor_gear_energy", 3), tmp_path / "energy.fmu")
    rewrite_fmu(Path(gain2), tmp_path / "nobinary.fmu", drop_prefix="binaries/")
    rewrite_fmu(Path(gain2), tmp_path / "me_only.fmu", edit_xml=lambda x: re.sub(
        r"<CoSimulation([^>]*?)/?>", r"<ModelExchange\1/>", x, count=1))
    spec = {
        "name": "many mistakes",
        "colour": "blue",                                                   # 1 unknown top-level field
        "units": {
            "ode": {"fmu": "ode3.fmu", "parameters": {"a": "fast", "x0": 1.0}},   # 2 Real given a string
            "energy": {"fmu": "energy.fmu", "parameters": {"eta_motor": [1.5, 0.9, 0.9, 0.9, 0.9, 0.9, 0.9]}},
            #                                                                   3 outside [0, 1]
            "missing": {"fmu": "does_not_exist.fmu"},                         # 4 missing FMU file
            "nobin": {"fmu": "nobinary.fmu"},                                 # 5 no binary for this platform
            "me": {"fmu": "me_only.fmu", "interface": "co-simulation"},       # 6 an interface it does not offer
            "g1": {"fmu": "gain2.fmu"},
            "g2": {"fmu": "gain2.fmu"},
            "clock": {"python": python_unit("Clock"), "paramters": {}},      # 7 misspelt field
            "clock2": {"python": python_unit("Clock")},
        },
        "connections": [
            {"from": "ode.yy", "to": "energy.tau[1]"},                        # 8 unknown variable (did you mean y)
            {"from": "ghost.y", "to": "ode.u"},                               # 9 unknown unit
            {"from": "ode.y", "to": "clock2.time"},                           # 10 output connected to output
            {"from": "clock2.done", "to": "energy.omega[2]"},                 # 11 Boolean into Real
            {"from": "g1.y", "to": "g2.u"},
            {"from": "g2.y", "to": "g1.u"},                # a loop g1 <-> g2 of Real signals: solved, not a mistake
            {"from": "clock2.time", "to": "energy.tau[3]"},                   # 17 s into N.m
            {"from": "ode.y", "to": "energy.tau[3]"},                         # 13 input fed twice
        ],
        "experiment": {"stop": 1.0, "step": 0.01, "algorithm": "gauss_seidel"},   # 14 bad algorithm name
        "objectives": {
            "e": {"signal": "energy.e_total", "reduce": "average"},           # 15 bad reduction
            "r": {"expr": "e / duration"},                                    # 16 unknown objective in expr
        },
    }
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(spec, indent=2))
    code, text = validate(capsys, path)
    assert code == 2
    assert "Traceback" not in text
    expected = [
        ("$.colour", "unknown field 'colour'"),
        ("$.units.ode.parameters.a", "'a' is Real, got str 'fast'"),
        ("$.units.energy.parameters.eta_motor", "1.5 is outside the range of 'eta_motor' [0, 1]"),
        ("$.units.missing.fmu", "file not found"),
        ("$.units.nobin.fmu", "no binary for this platform"),
        ("$.units.me.fmu", 'asks for "interface": "co-simulation" but the FMU offers only model-exchange'),
        ("$.units.clock.paramters", "unknown field 'paramters'. Did you mean 'parameters'?"),
        ("$.connections[0].from", "unit 'ode' has no variable 'yy'. Did you mean 'y'?"),
        ("$.connections[1].from", "unknown unit 'ghost'"),
        ("$.connections[2].to", "'clock2.time' is an output, not an input"),
        ("$.connections[3]", "type mismatch: 'clock2.done' is Boolean, 'energy.omega[2]' is Real"),
        ("$.connections[7].to", "input 'energy.tau[3]' is already fed by connection 6"),
        ("$.connections[6]", "units do not fit (different quantities): 'clock2.time' is in 's', "
                             "'energy.tau[3]' is in 'N.m'"),
        ("$.experiment.algorithm", "'gauss_seidel' is not allowed. Did you mean 'gauss-seidel'?"),
        ("$.objectives.e.reduce", "unknown reduction 'average'"),
        ("$.objectives.r.expr", "'duration' is not an objective"),
    ]
    for json_path, message in expected:
        line = f"{path}: {json_path}: "
        assert any(t.startswith(f"- {line}") and message in t for t in text.splitlines()), (json_path, text)
    assert f"{len(expected)} problems found" in text
    assert "algebraic loop" not in text  # cosim solves loops of Real signals (tests/master/test_algebraic_loops.py)
    assert text.count("    fix: ") >= len(expected) - 1


def test_malformed_json_names_line_and_column(tmp_path, capsys):
    path = tmp_path / "spec.json"
    path.write_text('{\n  "units": {\n    "a": {"fmu": "x.fmu"}\n  }\n  "experiment": {}\n}\n')
    code, text = validate(capsys, path)
    assert code == 2
    assert "malformed JSON at line 5, column 3" in text and "Traceback" not in text


def test_missing_required_fields_and_wrong_types(tmp_path, capsys):
    path = tmp_path / "spec.json"
    path.write_text(json.dumps({"units": {"a": {"python": python_unit("Clock"), "parameters": {"t_end": 1}}},
                                "experiment": {"stop": "ten"}}))
    code, text = validate(capsys, path)
    assert code == 2
    assert "$.experiment: missing field 'step'" in text
    assert "$.experiment.stop: expected number, got str" in text


def test_unit_needs_one_kind(tmp_path, capsys):
    path = tmp_path / "spec.json"
    path.write_text(json.dumps({"units": {"a": {"parameters": {}}}, "experiment": {"stop": 1, "step": 1}}))
    code, text = validate(capsys, path)
    assert code == 2 and "$.units.a: a unit needs exactly one of 'fmu', 'python', 'player' or 'connectors'" in text


def test_fmu_escaping_its_folder_is_refused(tmp_path, capsys, built_fmu):
    evil = rewrite_fmu(built_fmu("linear_ode", 2), tmp_path / "evil.fmu", extra={"../../escape.txt": b"x"})
    path = tmp_path / "spec.json"
    path.write_text(json.dumps({"units": {"a": {"fmu": str(evil)}}, "experiment": {"stop": 1, "step": 0.1},
                                "objectives": {"y": {"signal": "a.y", "reduce": "final"}}}))
    code, text = validate(capsys, path)  # found when the spec is checked: no worker ever extracts it
    assert code == 2 and "Traceback" not in text
    assert "$.units.a.fmu: FMU" in text and "(../../escape.txt): archive member escapes the extraction folder" in text
    assert "fix: re-export the FMU with relative member paths" in text
    code = main(["run", str(path)])
    text = capsys.readouterr()
    assert code == 2 and "escapes the extraction folder" in text.err and "internal error" not in text.err
    assert not (tmp_path.parent / "escape.txt").exists()


def test_fmu_found_unsafe_only_when_instantiated_is_a_user_error(tmp_path, built_fmu):
    """An FMU replaced by an unsafe archive after the check: the run fails as the user's, never as internal."""
    from cosim import Execution, build_system, load_spec
    from cosim.cli.exit_codes import EXIT_USAGE, run_exit_code

    fmu = tmp_path / "a.fmu"
    shutil.copy(built_fmu("linear_ode", 2), fmu)
    path = tmp_path / "spec.json"
    path.write_text(json.dumps({"units": {"a": {"fmu": "a.fmu"}}, "experiment": {"stop": 1, "step": 0.1},
                                "objectives": {"y": {"signal": "a.y", "reduce": "final"}}}))
    system = build_system(load_spec(path))
    rewrite_fmu(built_fmu("linear_ode", 2), fmu, extra={"../../escape.txt": b"x"})
    result = Execution(system).run()
    assert result.status == "failed" and result.failure == "user" and run_exit_code(result) == EXIT_USAGE
    assert "escapes the extraction folder" in result.message and "internal error" not in result.message
    assert not (tmp_path.parent / "escape.txt").exists()


def test_valid_spec_prints_the_order(tmp_path, capsys):
    path = tmp_path / "spec.json"
    path.write_text(json.dumps({
        "units": {"g": {"python": python_unit("Gain")}, "c": {"python": python_unit("Clock")}},
        "connections": [{"from": "c.time", "to": "g.u"}], "experiment": {"stop": 1, "step": 0.1}}))
    code, text = validate(capsys, path)
    assert code == 0 and "order: c -> g" in text


@pytest.mark.parametrize("design, path, fragment", [
    ('{"parameters": {"ode.a": {"values": [1, 2, 1]}}}', "$.design.parameters.ode.a", "values repeat: 1"),
    ('{"parameters": {"ode.a": {"min": 0, "max": 1, "step": NaN}}}', "$.design.parameters.ode.a", "NaN"),
    ('{"parameters": {"ode.a": {"min": 0, "max": 1, "step": 0.5}}, "constraint": "ode.b < 1"}',
     "$.design.constraint", "unknown name(s) in the constraint: ode.b"),
    ('{"parameters": {"ode.a": {"min": 0, "max": 1, "step": 0.5}}, "constraint": "ode.a[3] < 1"}',
     "$.design.constraint", "index 3 outside 1..1"),
])
def test_validate_refuses_the_design_a_sweep_refuses(tmp_path, capsys, design, path, fragment):
    spec = tmp_path / "spec.json"
    spec.write_text('{"units": {"ode": {"fmu": "builtin:linear_ode_fmi3"}}, "experiment": {"stop": 1, "step": 0.1},'
                    f' "design": {design}}}')
    code, text = validate(capsys, spec)
    assert code == 2 and path in text and fragment in text, text
    assert main(["sweep", str(spec), "--dry-run"]) == 2  # the same problem, found by the sweep
    assert fragment in capsys.readouterr().err


def test_a_misspelt_connection_end_is_suggested_only_what_it_may_be(tmp_path, capsys):
    """Issue 39: 'energy.p_tota' as a connection's target was answered "Did you mean 'p_total'?", an output
    that cannot be a target; 'to' is suggested inputs only, 'from' outputs only."""
    spec = {
        "units": {"energy": {"fmu": "builtin:motor_gear_energy_fmi3"},
                  "drive": {"python": python_unit("Clock")}},
        "connections": [{"from": "drive.time", "to": "energy.p_tota"},      # p_total is an output: no suggestion
                        {"from": "drive.time", "to": "energy.omeg[1]"},     # omega is an input
                        {"from": "energy.p_totl", "to": "energy.tau[1]"}],  # p_total is an output
        "experiment": {"stop": 1.0, "step": 0.01},
    }
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(spec))
    code, text = validate(capsys, path)
    assert code == 2 and "Traceback" not in text
    lines = {line.split(": ")[1]: line for line in text.splitlines() if line.startswith(f"- {path}")}
    assert lines["$.connections[0].to"].endswith("unit 'energy' has no variable 'p_tota'.")
    assert lines["$.connections[1].to"].endswith("unit 'energy' has no variable 'omeg[1]'. Did you mean 'omega'?")
    assert lines["$.connections[2].from"].endswith("unit 'energy' has no variable 'p_totl'. Did you mean 'p_total'?")
