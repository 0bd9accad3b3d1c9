"""One error family: every error cosim raises on purpose is a CosimError, and one mapping gives exit codes."""

from __future__ import annotations

import pickle

import pytest

from cosim import errors
from cosim.cli.exit_codes import EXIT_INTERNAL, EXIT_OK, EXIT_RUN_FAILED, EXIT_USAGE, exit_code
from cosim.cli.main import main
from cosim.errors import (
    CosimError,
    InternalError,
    Problem,
    UnitError,
    UsageError,
    UserError,
)


def old_names():
    """Every error class cosim had before the family, importable where it always was."""
    from cosim.analysis.table import AnalysisError
    from cosim.cli.main import UsageError as CliUsageError
    from cosim.errors import SpecError
    from cosim.fmus.build import FmuBuildError
    from cosim.fmus.model_description import ModelJsonError
    from cosim.spec.expressions import ExpressionError
    from cosim.studies.sweep import SweepError
    from cosim.units.fmu.description import FmuProblems
    from cosim.units.protocol import UnitError as OldUnitError

    return {"SpecError": SpecError, "UsageError": CliUsageError, "AnalysisError": AnalysisError,
            "ExpressionError": ExpressionError, "SweepError": SweepError, "FmuProblems": FmuProblems,
            "FmuBuildError": FmuBuildError, "ModelJsonError": ModelJsonError, "UnitError": OldUnitError}


def test_every_old_error_class_belongs_to_the_family_with_its_exit_code():
    classes = old_names()
    for name, cls in classes.items():
        assert issubclass(cls, CosimError), name
        expected = EXIT_RUN_FAILED if name == "UnitError" else EXIT_USAGE
        error = cls("u", "m") if name == "UnitError" else UserError.__new__(cls)
        assert exit_code(error) == expected, name
    assert issubclass(classes["ExpressionError"], ValueError)  # still a ValueError for old callers
    assert issubclass(classes["AnalysisError"], ValueError)


def test_exit_codes_come_from_one_mapping():
    assert exit_code(None) == EXIT_OK == 0
    assert exit_code(UserError("x")) == EXIT_USAGE == 2
    assert exit_code(UnitError("motor", "fmi2DoStep returned Error", 0.5)) == EXIT_RUN_FAILED == 1
    assert exit_code(InternalError("bug")) == EXIT_INTERNAL == 70
    assert exit_code(ZeroDivisionError()) == EXIT_INTERNAL  # anything unexpected is ours
    assert exit_code(KeyboardInterrupt()) == 130


def test_user_errors_carry_structured_problems_and_survive_pickling():
    from cosim.units.fmu.description import FmuProblems

    problem = Problem("spec.json", "$.units.a.fmu", "file not found", "check the path")
    error = FmuProblems("a.fmu", [problem, "plain text"])
    assert error.problems[0] is problem and error.problems[1] == Problem("a.fmu", "", "plain text")
    assert error.messages == ["file not found", "plain text"]
    again = pickle.loads(pickle.dumps(error))
    assert type(again) is FmuProblems and again.problems == error.problems and again.path == "a.fmu"
    unit = pickle.loads(pickle.dumps(UnitError("motor", "boom", 1.5)))
    assert (unit.unit, unit.message, unit.time, str(unit)) == ("motor", "boom", 1.5, "unit 'motor' at t=1.5: boom")
    single = UserError("bad value", file="f.json", path="$.a", fix="write a number")
    assert str(single) == "f.json: $.a: bad value\n    fix: write a number"


def test_every_subcommand_maps_errors_through_main(tmp_path, capsys, monkeypatch):
    assert main(["sweep", "spec.json", "--batch-size", "0"]) == EXIT_USAGE
    assert capsys.readouterr().err.strip() == "cosim: error: --batch-size must be at least 1"
    assert main(["plot", str(tmp_path / "none.parquet"), "--x", "a", "--y", "b", "-o", str(tmp_path / "f.png")]) \
        == EXIT_USAGE
    assert "no such results table" in capsys.readouterr().err

    from cosim.system import validate

    def broken(path, experiment=None, variant=None):  # check_spec's signature (command-line overrides, variant)
        raise KeyError("an assumption of ours")

    monkeypatch.setattr(validate, "check_spec", broken)
    assert main(["validate", "spec.json"]) == EXIT_INTERNAL
    err = capsys.readouterr().err
    assert "internal error" in err and "Traceback" in err and "KeyError" in err


def test_problem_without_place_prints_as_a_command_line_error():
    assert str(UsageError("--out x.txt: use a .parquet or .csv file name")) == \
        "--out x.txt: use a .parquet or .csv file name"
    assert errors.Problem("", "", "m", "f").__str__() == "m\n    fix: f"


@pytest.mark.parametrize("cls", [UserError, UsageError])
def test_user_error_accepts_a_single_problem(cls):
    problem = Problem("f", "$", "m")
    assert cls(problem).problems == [problem]
