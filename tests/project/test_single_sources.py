"""Names defined once: algorithms, reductions, result tail columns, exit codes, the identifier rule."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from tests.helpers.paths import REPO

ROOT = REPO
ENGINE = ROOT / "src" / "cosim"


def test_algorithm_names_come_from_the_algorithm_registry():
    from cosim.cli.main import _parser
    from cosim.master import registry as algorithms
    from cosim.spec import loader as spec

    schema = json.loads((ROOT / "src" / "cosim" / "spec" / "spec.schema.json").read_text())
    in_file = schema["$defs"]["experiment"]["properties"]["algorithm"]
    assert in_file["enum"] == list(algorithms.ALGORITHMS) == list(spec.ALGORITHMS)  # the file repeats them
    assert in_file["default"] == algorithms.DEFAULT_ALGORITHM == spec.ExperimentSpec(0, 1, 1).algorithm
    run = _parser()._subparsers._group_actions[0].choices["run"]
    assert next(a for a in run._actions if a.dest == "algorithm").choices == tuple(algorithms.ALGORITHMS)


def test_reduction_names_are_the_reducers():
    from cosim.master.observers import REDUCERS
    from cosim.spec.loader import REDUCTIONS

    assert REDUCTIONS == tuple(REDUCERS)
    t, x = np.array([0.0, 1.0, 3.0]), np.array([[1.0], [3.0], [-1.0]])
    # trapezoids over the samples: x: (1+3)/2*1 + (3-1)/2*2 = 4; |x|: 2 + 4 = 6; x*x: (1+9)/2 + (9+1)/2*2 = 15
    expected = {"final": -1.0, "initial": 1.0, "min": -1.0, "max": 3.0, "integral": 4.0, "integral_abs": 6.0,
                "mean": 4.0 / 3.0, "rms": np.sqrt(15.0 / 3.0), "time_of_max": 1.0, "time_of_min": 3.0}
    assert {name: float(reduce(t, x)[0]) for name, reduce in REDUCERS.items()} == pytest.approx(expected)


def test_tail_columns_and_statuses_are_defined_once():
    from cosim.analysis import table
    from cosim.execution import point_row
    from cosim.results import columns as table_columns
    from cosim.results import store as results

    # defined with the point's outcome that fills them (PointRow), named by the table's columns module
    assert results.TAIL_COLUMNS is table_columns.TAIL_COLUMNS is table.TAIL is point_row.TAIL_COLUMNS
    assert results.STATUSES is table_columns.STATUSES is point_row.STATUSES
    for path in ENGINE.rglob("*.py"):
        if path.relative_to(ENGINE).as_posix() != "execution/point_row.py":
            assert '"status", "message", "run_time", "worker"' not in path.read_text(), path


def test_exit_codes_are_defined_once():
    pattern = re.compile(r"^\s*EXIT_\w+\s*(,\s*EXIT_\w+\s*)*=", re.M)
    defining = [str(p.relative_to(ENGINE)) for p in ENGINE.rglob("*.py") if pattern.search(p.read_text())]
    assert defining == ["cli/exit_codes.py"]


def test_every_error_class_is_defined_in_the_errors_module():
    """One module holds the error family; the other modules import their errors from it."""
    pattern = re.compile(r"^class \w+\((\w+, )*\w*(Error|Problems|InUse)\b", re.M)
    defining = sorted({str(p.relative_to(ENGINE)) for p in ENGINE.rglob("*.py") if pattern.search(p.read_text())})
    assert [d for d in defining if not d.startswith("models/")] == ["errors.py"]


@pytest.mark.parametrize("name, expected", [("traj.q_via[2]", "traj_q_via_2"), ("e_el[1]", "e_el_1"),
                                            ("run_time", "run_time"), ("1st.x", "c_1st_x"), ("[3]", "c_3")])
def test_one_identifier_rule_for_columns_and_design_parameters(name, expected):
    from cosim.analysis.table import identifier
    from cosim.spec.design import expression_name

    assert identifier(name) == expression_name(name) == expected


def test_one_cli_entry_dispatches_to_subcommand_modules_that_never_import_it():
    import ast

    from cosim.cli import main as cli

    commands = set(cli._parser()._subparsers._group_actions[0].choices)
    assert {"validate", "run", "inspect", "sweep", "plot", "pareto", "report", "explore"} <= commands
    for path in ENGINE.rglob("*.py"):
        # the entry itself, `python -m cosim`, and the conformance tool that drives the command line like a user
        if path.relative_to(ENGINE).as_posix() in ("cli/main.py", "__main__.py", "cli/reference_check.py"):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                module = "." * node.level + (node.module or "")
                names = {a.name for a in node.names}
                assert module not in (".main", "cosim.cli.main"), path
                assert not (module in ("cosim.cli", ".") and "main" in names), path


def test_the_surrogate_command_offers_the_library_s_methods_and_row_limit():
    from cosim.analysis.surrogate import fit, study
    from cosim.cli import surrogate

    assert surrogate.METHODS == fit.METHODS and surrogate.MAX_ROWS == study.MAX_ROWS
