"""10^5 problems do not print 10^5 lines: a sample of 50 by kind, how many more, and --all-problems for all.

Real specs of real Python units with many wrong connections, checked by the
real command line (`cosim validate`, `cosim sweep`) in a fresh process; the
expected lines are built here from the connections the test wrote.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from pathlib import Path

from cosim.cli.problems import _share, print_problems
from cosim.errors import Problem
from tests.helpers.paths import REPO
from tests.helpers.triple_study import TRIPLE_UNIT

FIX = "run 'cosim inspect' on the spec to list the variables of '{}'"
MORE = "(add --all-problems to the command to list every one)"


def _cosim(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cosim.cli.main", *args], capture_output=True, text=True, cwd=cwd,
                          env=dict(os.environ, PYTHONPATH=str(REPO / "src")), timeout=600)


def _spec(folder: Path, wrong_from: int, wrong_to: int, wrong_design: bool = False) -> Path:
    """Units s and t; ``wrong_from`` connections from outputs s lacks, then ``wrong_to`` into inputs t lacks."""
    (folder / "triple.py").write_text(TRIPLE_UNIT)
    spec = {"units": {"s": {"python": "triple.py:Triple"}, "t": {"python": "triple.py:Triple"}},
            "connections": [{"from": f"s.out{i}", "to": "t.k"} for i in range(wrong_from)]
            + [{"from": "s.y", "to": f"t.in{i}"} for i in range(wrong_to)],
            "experiment": {"stop": 0.1, "step": 0.1}, "objectives": {"y": {"signal": "t.y", "reduce": "final"}},
            "design": {"parameters": {"s.k": {"values": [1, 2]}, **({"s.nope": {"values": [1]}} if wrong_design
                                                                      else {})}}}
    path = folder / "spec.json"
    path.write_text(json.dumps(spec))
    return path


def _from(i: int) -> str:
    return f"- spec.json: $.connections[{i}].from: unit 's' has no variable 'out{i}'."


def _to(i: int, first: int) -> str:
    return f"- spec.json: $.connections[{first + i}].to: unit 't' has no variable 'in{i}'."


def test_validate_of_10_5_wrong_connections_prints_50_by_kind_and_how_many_more(tmp_path):
    spec = _spec(tmp_path, 60_000, 40_000)
    done = _cosim("validate", spec.name, cwd=tmp_path)
    assert done.returncode == 2, done.stderr[-2000:]
    lines = done.stderr.splitlines()
    assert lines == ["100000 problems found; 50 of them, by kind (2 kinds):",
                     *[_from(i) for i in range(25)],
                     f"    fix (all 60000 of this kind): {FIX.format('s')}",
                     *[_to(i, 60_000) for i in range(25)],
                     f"    fix (all 40000 of this kind): {FIX.format('t')}",
                     f"... and 99950 more problems like these {MORE}"]


def test_sweep_shows_every_kind_in_its_sample_and_all_problems_lists_every_one(tmp_path):
    spec = _spec(tmp_path, 1500, 500, wrong_design=True)
    out = tmp_path / "out"
    done = _cosim("sweep", spec.name, "--out", str(out), cwd=tmp_path)
    assert done.returncode == 2, done.stderr[-2000:]
    lines = done.stderr.splitlines()
    assert lines[0] == "2001 problems found; 50 of them, by kind (3 kinds):"
    # the lone design problem has its place although 2000 connection problems were found before it
    design = ["- spec.json: $.design.parameters.s.nope: unit 's' has no variable 'nope'.", f"    fix: {FIX.format('s')}"]
    assert lines[1:] == [*[_from(i) for i in range(25)], f"    fix (all 1500 of this kind): {FIX.format('s')}",
                         *[_to(i, 1500) for i in range(24)], f"    fix (all 500 of this kind): {FIX.format('t')}",
                         *design, f"... and 1951 more problems like these {MORE}"]

    every = _cosim("--all-problems", "sweep", spec.name, "--out", str(out), cwd=tmp_path)
    assert every.returncode == 2
    lines = every.stderr.splitlines()
    assert lines[0] == "2001 problems found:"
    problems = [line for line in lines if line.startswith("- ")]
    assert problems == [*[_from(i) for i in range(1500)], *[_to(i, 1500) for i in range(500)], design[0]]
    assert lines.count(f"    fix: {FIX.format('s')}") == 1501 and lines.count(f"    fix: {FIX.format('t')}") == 500
    assert len(lines) == 1 + 2 * 2001, [line for line in lines if not line.startswith(("- ", "    fix: "))]


def test_few_problems_are_listed_as_before_and_a_sample_never_leaves_a_kind_out_while_there_are_places(tmp_path):
    spec = _spec(tmp_path, 30, 20)  # 50: the limit itself, each with its fix
    done = _cosim("validate", spec.name, cwd=tmp_path)
    assert done.returncode == 2
    lines = done.stderr.splitlines()
    assert lines[0] == "50 problems found:" and len(lines) == 101 and "more problems" not in done.stderr
    assert lines[1:3] == [_from(0), f"    fix: {FIX.format('s')}"]
    # the places, one per kind in turn: (sizes) -> shown
    assert _share(50, [60_000, 40_000]) == [25, 25]
    assert _share(50, [3, 100, 1]) == [3, 46, 1]
    assert _share(50, [1] * 70) == [1] * 50 + [0] * 20
    assert _share(50, [10, 10]) == [10, 10]

    many_kinds = io.StringIO()  # 70 kinds of one problem each: 50 shown, the last line says 20 kinds are not
    print_problems([Problem("f.json", f"$.units.u{i}", "wrong", f"fix u{i}") for i in range(70)], stream=many_kinds)
    lines = many_kinds.getvalue().splitlines()
    assert lines[0] == "70 problems found; 50 of them, by kind (70 kinds):" and len(lines) == 1 + 2 * 50 + 1
    assert lines[-3:] == ["- f.json: $.units.u49: wrong", "    fix: fix u49",
                          f"... and 20 more problems, of 20 kinds not shown {MORE}"]
