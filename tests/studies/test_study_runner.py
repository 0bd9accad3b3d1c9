"""One study runner over point sources (issue 34 item 2): the options records, the error family, the words.

The studies' own behaviour is tested in test_sweep, test_optimize, test_sensitivity_study, test_prune_* and
the resume and interrupt tests; here: what the runner promises of every study.
"""

from __future__ import annotations

import ast
import dataclasses
import re
from pathlib import Path

import pytest

from cosim.cli.main import main
from cosim.cli.wording import CLI_WORDS
from cosim.errors import OptimizeError, SensitivityError, StudyError, SweepError, UserError
from cosim.studies.optimize import Optimiser, Optimization
from cosim.studies.options import KEYWORDS, PYTHON_WORDS, How, Show, Stop, Where, split_options
from cosim.studies.runner import Study
from cosim.studies.sweep import DesignGrid, Sweep
from tests.helpers.paths import REPO
from tests.studies.test_optimize import bowls_spec

ENGINE = REPO / "src" / "cosim"


@pytest.fixture
def spec(write_spec):
    raw = bowls_spec()
    for parameter in raw["design"]["parameters"].values():
        parameter["step"] = 1.0  # a grid too, so that the same spec makes a Sweep
    return write_spec(raw)


def test_the_records_are_frozen_and_the_flat_names_land_in_them():
    options = split_options(out="o", resume=True, workers=2, timeout=3.0, budget=7, quiet=True, prune=True)
    assert options.where == Where(out=Path("o"), resume=True)
    assert options.how == How(workers=2, timeout=3.0, prune=True)
    assert options.stop == Stop(budget=7)
    assert options.show.quiet and not options.show.explore
    with pytest.raises(dataclasses.FrozenInstanceError):
        options.where.resume = False  # type: ignore[misc]
    with pytest.raises(TypeError, match="unexpected keyword argument.*no_such_option"):
        split_options(no_such_option=1)
    # a record given and a flat name: the name updates the record
    assert split_options(how=How(workers=3), timeout=5.0).how == How(workers=3, timeout=5.0)
    # every field of every record has a flat name, and no name is in two records
    fields = [f.name for record in (Where, How, Stop, Show) for f in dataclasses.fields(record)]
    assert sorted(fields) == sorted(KEYWORDS) and len(fields) == len(set(fields))


def test_a_study_is_a_point_source_run_by_the_one_runner(spec, tmp_path):
    sweep = Sweep(spec, where=Where(out=tmp_path / "s"), how=How(workers=2), show=Show(quiet=True))
    assert isinstance(sweep, Study) and isinstance(sweep.source, DesignGrid) and sweep.workers == 2
    same = Sweep(spec, out=tmp_path / "t", workers=2, quiet=True)  # the flat names: the same records
    assert (same.how, same.show.quiet) == (sweep.how, True) and len(same.space) == len(sweep.space) == 25
    run = Optimization(spec, tmp_path / "o", stop=Stop(budget=4), quiet=True, sampler="random", seed=1)
    assert isinstance(run.source, Optimiser) and run.settings.budget == 4 and run.settings.sampler == "random"
    with pytest.raises(TypeError, match="to the Optimiser, not beside it"):
        Optimization(spec, tmp_path / "p", optimiser=Optimiser(), seed=1)


def test_every_study_error_is_a_study_error(spec, tmp_path):
    assert all(issubclass(e, StudyError) and issubclass(e, UserError)
               for e in (SweepError, OptimizeError, SensitivityError))
    for make in (lambda: Sweep(spec, out=tmp_path / "a", timeout=float("nan"), quiet=True),
                 lambda: Optimization(spec, tmp_path / "b", timeout=-1, quiet=True),
                 lambda: Sweep(spec, out=tmp_path / "c", workers=0, quiet=True)):
        with pytest.raises(StudyError, match="must be"):
            make()


def test_a_study_names_options_in_its_callers_words(spec, tmp_path, capsys, local_cluster):
    with pytest.raises(SweepError) as python:
        Sweep(spec, resume=True, quiet=True)  # no folder to resume
    assert "(out=DIR)" in str(python.value) and "--" not in str(python.value)
    with pytest.raises(SweepError) as cli_words:
        Sweep(spec, resume=True, quiet=True, words=CLI_WORDS)
    assert "(--out DIR)" in str(cli_words.value)
    assert set(CLI_WORDS) == set(PYTHON_WORDS)  # the command line says every option the library may name
    folder = tmp_path / "held"
    Sweep(spec, out=folder, scheduler=local_cluster, quiet=True).run()
    assert main(["sweep", str(spec), "--out", str(folder), "-q"]) == 2  # rows there, no --resume
    err = capsys.readouterr().err
    assert "add --resume to finish that sweep, or choose another --out" in err and "resume=True" not in err


def _messages(path: Path) -> list[tuple[int, str]]:
    """(line, text) of every string literal of ``path`` that is not a docstring."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                  if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                  and node.body and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)}
    return [(node.lineno, node.value) for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings]


# Other programs' command lines, which a message may quote as they are: Dask's and Optuna's
OTHER_PROGRAMS = ("dask worker ADDRESS --nthreads", "optuna delete-study --storage", " --study-name '")


def test_no_library_message_names_a_command_line_option():
    """studies/, results/ and parallel/ speak to Python callers too: a command-line option in their messages
    is the command line's to add (cosim.cli.wording)."""
    found = []
    for package in ("studies", "results", "parallel"):
        for path in sorted((ENGINE / package).rglob("*.py")):
            for line, text in _messages(path):
                for match in re.finditer(r"(?<![\w-])--[a-z][a-z-]*", text):
                    if not any(other in text for other in OTHER_PROGRAMS):
                        found.append(f"{path.relative_to(ENGINE)}:{line}: {match.group()}")
    assert found == []
