"""Spec details (relative paths, port mapping, builtin FMUs) and the safe expression language."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

import cosim
from cosim.errors import SpecError
from cosim.spec.expressions import Expression, ExpressionError
from cosim.spec.loader import load_spec
from cosim.system.validate import check_spec
from tests.helpers.paths import HELPERS


def test_relative_paths_resolve_against_the_spec_folder(tmp_path, built_fmu, monkeypatch):
    folder = tmp_path / "study"
    (folder / "models").mkdir(parents=True)
    shutil.copy(built_fmu("linear_ode", 2), folder / "models" / "ode.fmu")
    shutil.copy(HELPERS / "units_for_tests.py", folder / "my_units.py")
    (folder / "spec.json").write_text(json.dumps({
        "units": {"ode": {"fmu": "models/ode.fmu", "parameters": {"a": -1.0}},
                  "gain": {"python": "my_units.py:Gain", "parameters": {"k": 2.0}}},
        "connections": [{"from": "ode.y", "to": "gain.u"}],
        "experiment": {"stop": 1.0, "step": 0.01},
        "objectives": {"g": {"signal": "gain.y", "reduce": "final"}},
    }))
    monkeypatch.chdir(tmp_path)  # somewhere else than the spec's folder
    result = cosim.run("study/spec.json")
    assert result.ok, result.message
    assert result.objectives["g"] == pytest.approx(2.0 * np.exp(-1.0), rel=1e-12)


def test_port_mapping_lets_a_replacement_fmu_use_other_names(write_spec):
    """The spec speaks of 'state' and 'drive'; the FMU calls them 'y' and 'u'."""
    spec = {
        "units": {"ode": {"fmu": "builtin:linear_ode_fmi3", "ports": {"state": "y", "drive": "u"},
                          "start": {"drive": 1.0}, "parameters": {"a": -2.0, "x0": 0.0}}},
        "experiment": {"stop": 3.0, "step": 0.01},
        "record": ["ode.state"],
        "objectives": {"x": {"signal": "ode.state", "reduce": "final"}},
    }
    result = cosim.run(str(write_spec(spec)))
    assert result.ok, result.message
    assert result.objectives["x"] == pytest.approx(0.5 * (1 - np.exp(-6.0)), rel=1e-12)
    assert list(result.traces.columns) == ["time", "ode.state"]


def test_port_mapping_to_a_missing_variable_is_reported(write_spec):
    spec = {"units": {"ode": {"fmu": "builtin:linear_ode_fmi3", "ports": {"state": "yy"}}},
            "experiment": {"stop": 1.0, "step": 0.1}}
    with pytest.raises(SpecError) as info:
        check_spec(write_spec(spec))
    assert any(p.path == "$.units.ode.ports.state" and "Did you mean 'y'" in p.message for p in info.value.problems)


def test_unknown_builtin_fmu_lists_the_available_ones(write_spec):
    spec = {"units": {"m": {"fmu": "builtin:motor_fmi3"}}, "experiment": {"stop": 1.0, "step": 0.1}}
    with pytest.raises(SpecError) as info:
        check_spec(write_spec(spec))
    text = str(info.value)
    assert "$.units.m.fmu: no built-in FMU 'motor_fmi3'" in text and "builtin:motor_gear_energy_fmi3" in text


def test_spec_digest_ignores_formatting_but_not_content(tmp_path):
    content = {"units": {"a": {"python": "x:Y"}}, "experiment": {"stop": 1, "step": 0.1}}
    (tmp_path / "a.json").write_text(json.dumps(content))
    (tmp_path / "b.json").write_text(json.dumps(content, indent=4))
    content["experiment"]["stop"] = 2
    (tmp_path / "c.json").write_text(json.dumps(content))
    digests = [load_spec(tmp_path / f"{n}.json").digest for n in "abc"]
    assert digests[0] == digests[1] != digests[2]


@pytest.mark.parametrize("text,values,expected", [
    ("a + b * 2", {"a": 1, "b": 3}, 7),
    ("(a + b) ** 2 / 4", {"a": 1, "b": 3}, 4.0),
    ("sum(e) / max(e)", {"e": [1.0, 2.0, 5.0]}, 1.6),
    ("e[2] - min(a, b)", {"e": [1.0, 2.0], "a": 5, "b": -1}, 3.0),
    ("sqrt(abs(x)) + pi * 0", {"x": -16}, 4.0),
    ("a > 1 and not b < 0", {"a": 2, "b": 1}, True),
    ("-x // 3 % 2", {"x": 7}, 1),
])
def test_expressions_compute(text, values, expected):
    assert Expression(text).evaluate(values) == pytest.approx(expected)


@pytest.mark.parametrize("text", [
    "__import__('os').system('true')", "a.__class__", "open('x')", "[1, 2]", "lambda: 1", "a if b else c",
    "'text'", "x[y]", "exec('1')", "f(x=1)",
])
def test_expressions_refuse_everything_outside_the_whitelist(text):
    with pytest.raises(ExpressionError):
        Expression(text)


def test_expression_errors_name_the_problem():
    with pytest.raises(ExpressionError, match="unknown function 'foo'"):
        Expression("foo(1)")
    with pytest.raises(ExpressionError, match="cannot parse"):
        Expression("1 +")
    with pytest.raises(ExpressionError, match="index 4 outside 1..3"):
        Expression("e[4]").evaluate({"e": [1, 2, 3]})
    with pytest.raises(ExpressionError, match="unknown name 'q'"):
        Expression("q + 1").evaluate({})
    assert Expression("a / b").names == {"a", "b"}
    assert np.isinf(Expression("a / b").evaluate({"a": 1.0, "b": 0.0}))


def test_without_a_compiler_a_builtin_fmu_gives_a_clear_problem(write_spec, tmp_path, monkeypatch):
    monkeypatch.setenv("CC", str(tmp_path / "no-such-gcc"))
    monkeypatch.setenv("COSIM_FMU_CACHE", str(tmp_path / "empty-cache"))
    spec = {"units": {"m": {"fmu": "builtin:linear_ode_fmi3"}}, "experiment": {"stop": 1.0, "step": 0.1}}
    with pytest.raises(SpecError) as info:
        check_spec(write_spec(spec))
    (problem,) = info.value.problems
    assert problem.path == "$.units.m.fmu" and "no C compiler" in problem.message
    assert "apt-get install gcc" in problem.fix


def test_absurd_counts_in_a_spec_are_refused_at_their_path(write_spec, capsys):
    """Issue 38.6: counts a run or a study takes from a spec are bounded; `cosim validate` names the JSON path
    and the fix (before: a max_iterations of 10^9 or a budget of 10^12 was taken as written)."""
    from cosim.cli.main import main

    unit = {"python": f"{HELPERS / 'units_for_tests.py'}:Gain", "parameters": {"k": 2.0}}
    spec = {"units": {"g": unit}, "experiment": {"stop": 1.0, "step": 0.1,
                                                "loop_solver": {"max_iterations": 10 ** 9}},
            "objectives": {"y": {"signal": "g.y", "reduce": "final", "sense": "minimize"}},
            "design": {"parameters": {"g.k": {"min": 0.0, "max": 1.0}}}}
    assert main(["validate", str(write_spec(spec))]) == 2
    err = capsys.readouterr().err
    assert "$.experiment.loop_solver.max_iterations" in err and "use a number at most 100000" in err, err
    spec["experiment"]["loop_solver"]["max_iterations"] = 200
    spec["optimize"] = {"budget": 10 ** 12, "batch": 8}
    assert main(["validate", str(write_spec(spec))]) == 2  # an optimize section: checked for optimize
    err = capsys.readouterr().err
    assert "$.optimize.budget" in err and "budget 1,000,000,000,000 is more than the limit of 1,000,000" in err, err
    assert "COSIM_MAX_POINTS" in err


def test_a_keyword_argument_to_a_known_function_is_named_as_such():
    """`max(x, initial=0)` said "unknown function 'max'" while listing max among the allowed ones (issue 38.7)."""
    with pytest.raises(ExpressionError) as caught:
        Expression("max(x, initial=0)")
    message = str(caught.value)
    assert "unknown function" not in message, message
    assert "max() takes no keyword arguments (got initial=); give its arguments by position, e.g. max(x, 0)" in message
    with pytest.raises(ExpressionError, match=r"sqrt\(\) takes no keyword arguments \(got x=\)"):
        Expression("sqrt(x=2)")
    assert Expression("max(x, 0)").evaluate({"x": -3.0}) == 0.0
