"""Careless and hostile specs: values JSON does not allow, keys twice, deep nesting, huge design
spaces and expressions that would hang or exhaust the client.  Each ends in one clear problem with its
JSON path and exit code 2, quickly (the subprocess deadlines catch a hang), never exit 70 or a traceback."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import cosim
from cosim.cli.main import main
from cosim.errors import SpecError
from cosim.spec.design import DesignSpace
from cosim.spec.expressions import Expression, ExpressionError
from cosim.spec.loader import load_spec
from tests.helpers.paths import REPO
from tests.helpers.tools import python_unit


def _base(**design) -> dict:
    spec = {"units": {"g": {"python": python_unit("Gain")}, "c": {"python": python_unit("Clock")}},
            "connections": [{"from": "c.time", "to": "g.u"}],
            "experiment": {"stop": 0.3, "step": 0.1},
            "objectives": {"y": {"signal": "g.y", "reduce": "final"}}}
    if design:
        spec["design"] = design
    return spec


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "spec.json"
    path.write_text(text)
    return path


def _validate(capsys, path: Path) -> tuple[int, str]:
    code = main(["validate", str(path)])
    captured = capsys.readouterr()
    return code, captured.out + captured.err


def _cosim(*args: str, env: dict | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    full_env = dict(os.environ, PYTHONPATH=str(REPO), **(env or {}))
    return subprocess.run([sys.executable, "-m", "cosim.cli.main", *args], capture_output=True, text=True,
                          env=full_env, timeout=timeout)


@pytest.mark.parametrize("literal", ["Infinity", "NaN", "-Infinity", "1e400"])
def test_numbers_json_does_not_allow_are_refused(tmp_path, capsys, literal):
    text = json.dumps(_base()).replace('"stop": 0.3', f'"stop": {literal}')
    code, out = _validate(capsys, _write(tmp_path, text))
    assert code == 2 and "Traceback" not in out
    assert f"$.experiment.stop: {literal} is not a JSON number" in out


def test_a_key_given_twice_is_refused_with_its_path(tmp_path, capsys):
    text = json.dumps(_base()).replace('"stop": 0.3', '"stop": 0.3, "stop": 0.5')
    code, out = _validate(capsys, _write(tmp_path, text))
    assert code == 2 and "$.experiment.stop: key 'stop' is given more than once" in out


@pytest.mark.parametrize("depth", [100, 900, 100_000])
def test_deep_nesting_gives_a_clean_message(tmp_path, capsys, depth):
    spec = _base()
    text = json.dumps(spec)[:-1] + ', "description": ' + "[" * depth + "]" * depth + "}"
    code, out = _validate(capsys, _write(tmp_path, text))
    assert code == 2 and "RecursionError" not in out and "Traceback" not in out
    assert "nested more than 64 levels deep" in out or "nested too deeply" in out


@pytest.mark.parametrize("command", [["sweep", "--dry-run"], ["sweep"], ["optimize"], ["sensitivity"], ["run"],
                                     ["inspect"]])
def test_deep_nesting_gives_a_clean_message_from_every_command(tmp_path, capsys, monkeypatch, command):
    """Also the commands that read the spec's name for their default results folder before checking it."""
    monkeypatch.chdir(tmp_path)
    depth = 100_000  # deeper than Python's recursion limit, wherever the reader is called from
    text = json.dumps(_base())[:-1] + ', "description": ' + "[" * depth + "]" * depth + "}"
    code = main([command[0], str(_write(tmp_path, text)), *command[1:]])
    out = capsys.readouterr()
    assert code == 2 and "Traceback" not in out.err, out.err
    assert "nested more than 64 levels deep" in out.err or "nested too deeply" in out.err
    assert not (tmp_path / "results").exists()


def test_too_many_steps_is_refused_and_the_limit_can_be_raised(tmp_path):
    spec = _base()
    spec["experiment"] = {"stop": 1e9, "step": 1e-9}
    path = _write(tmp_path, json.dumps(spec))
    done = _cosim("validate", str(path), timeout=60)
    assert done.returncode == 2, done.stderr
    assert "$.experiment.step: (stop - start) / step is 1e+18 steps, more than the limit of 1e+08" in done.stderr
    assert "COSIM_MAX_STEPS" in done.stderr
    done = _cosim("validate", str(path), env={"COSIM_MAX_STEPS": "1e19"}, timeout=60)
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize("design, where, what", [
    ({"parameters": {"g.k": {"min": 0, "max": 1e9, "step": 1e-9}}}, "$.design.parameters.g.k",
     "1,000,000,000,000,000,001 values"),
    ({"method": "lhs", "samples": 2_000_000_000, "parameters": {"g.k": {"min": 0, "max": 1}}},
     "$.design.samples", "2,000,000,000 samples"),
    ({"parameters": {"g.k": {"min": 1, "max": 1000, "step": 1}, "c.offset": {"min": 1, "max": 1000, "step": 1},
                     "g.u": {"values": list(range(1000))}}},
     "$.design", "the grid has 1,000,000,000 points (1000 x 1000 x 1000)"),
])
def test_huge_design_spaces_are_counted_not_made(tmp_path, capsys, design, where, what):
    path = _write(tmp_path, json.dumps(_base(**design)))
    code, out = _validate(capsys, path)
    assert code == 2 and f"{where}: {what}" in out and "more than the limit of 1,000,000" in out, out
    with pytest.raises(SpecError, match="more than the limit"):
        DesignSpace(load_spec(path))


def test_the_points_limit_is_raised_on_purpose(tmp_path, monkeypatch):
    design = {"parameters": {"g.k": {"min": 1, "max": 2000, "step": 1}, "c.offset": {"min": 1, "max": 1000, "step": 1}}}
    path = _write(tmp_path, json.dumps(_base(**design)))
    with pytest.raises(SpecError, match=r"the grid has 2,000,000 points \(2000 x 1000\)"):
        DesignSpace(load_spec(path))
    monkeypatch.setenv("COSIM_MAX_POINTS", "3000000")
    space = DesignSpace(load_spec(path))
    assert len(space) == 2_000_000 and space.head(2)[1].values == {"g.k": 1, "c.offset": 2}


def test_a_bad_limit_setting_is_a_usage_error(tmp_path):
    path = _write(tmp_path, json.dumps(_base()))
    done = _cosim("validate", str(path), env={"COSIM_MAX_POINTS": "lots"}, timeout=60)
    assert done.returncode == 2 and "COSIM_MAX_POINTS: 'lots' is not a positive whole number" in done.stderr


def test_a_hundred_thousand_explicit_values_dry_run_promptly(tmp_path):
    path = _write(tmp_path, json.dumps(_base(parameters={"g.k": {"values": [i / 7 for i in range(100_000)]}})))
    done = _cosim("sweep", str(path), "--dry-run", "--workers", "1", timeout=120)
    assert done.returncode == 0, done.stderr
    assert "100000 points" in done.stdout and "sample" in done.stdout


def test_repeated_values_in_a_long_list_are_named(tmp_path):
    values = list(range(50_000)) + [7, 9]
    path = _write(tmp_path, json.dumps(_base(parameters={"g.k": {"values": values}})))
    with pytest.raises(SpecError, match="values repeat: 7, 9"):
        DesignSpace(load_spec(path))


@pytest.mark.parametrize("constraint, reason", [
    ("9**9**9 > 1", "too large"),
    ("2**2**40 > 1", "too large"),
    ("g_k ** 1e6 > 1", "too large"),
    ("g_k * 1e308 * 10 > 1", "too large"),
    ("1e308 + 1e308 > 1", "too large"),
    ("-1e308 - 1e308 < 1", "too large"),
    ("g_k // 0 > 1", "division by zero"),
    ("g_k % 0 > 1", "division by zero"),
    ("sqrt(-g_k) > 1", "invalid operation"),
    ("1/0 > 1", "division by zero"),
    ("max() > 1", "max() takes at least 1 argument(s), got 0"),
    ("sin(1, 2) > 0", "sin() takes 1 argument(s), got 2"),
    ("1" + "+1" * 100_000 + " > 0", "characters, more than the limit of 10000"),
    ("-" * 5000 + "1 < 0", "nested too deeply"),
    ("-" * 150 + "1 < 0", "nested more than 100 levels deep"),
    ("abs(" * 150 + "1" + ")" * 150 + " > 0", "nested more than 100 levels deep"),
    ("1" + "0" * 400 + " > 1", "is too large"),
])
def test_hostile_constraints_end_in_one_line_with_the_path(tmp_path, constraint, reason):
    path = _write(tmp_path, json.dumps(_base(parameters={"g.k": {"values": [2, 3]}}, constraint=constraint)))
    with pytest.raises(SpecError) as caught:
        list(DesignSpace(load_spec(path)))
    problem = caught.value.problems[0]
    assert problem.path == "$.design.constraint" and reason in problem.message, problem.message
    assert "\n" not in problem.message and len(problem.message) < 300


def test_a_hostile_constraint_through_the_command_line(tmp_path):
    path = _write(tmp_path, json.dumps(_base(parameters={"g.k": {"values": [2, 3]}}, constraint="9**9**9 > g_k")))
    done = _cosim("sweep", str(path), "--dry-run", timeout=60)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "$.design.constraint: '9**9**9 > g_k': cannot evaluate: the result is too large" in done.stderr


def test_a_hostile_objective_fails_its_point_at_once(tmp_path):
    spec = _base()
    spec["objectives"]["big"] = {"expr": "9**9**9 * y"}
    result = cosim.run(str(_write(tmp_path, json.dumps(spec))))
    assert result.status == "failed" and "the result is too large" in result.message


def test_expressions_still_compute_what_they_did():
    assert Expression("2**10 + 7 // 2 - 7 % 4").evaluate({}) == 1024 + 3 - 3
    assert Expression("max(a, 3) * min(a)").evaluate({"a": 2.0}) == 6.0
    assert Expression("(-8) ** 2").evaluate({}) == 64.0
    assert Expression("x[2] ** 2").evaluate({"x": [1.0, 3.0]}) == 9.0
    assert Expression("1/0").evaluate({}) == float("inf")  # an objective may be infinite; a constraint may not
    with pytest.raises(ExpressionError, match="division by zero"):
        Expression("1/0 > 0").evaluate({}, strict=True)
