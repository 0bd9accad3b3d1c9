"""cosim's one error family: every error cosim raises on purpose, in one module.

Every error cosim raises on purpose derives from :class:`CosimError` and says
whose it is to fix:

- :class:`UserError` -- a spec, a file, a table or a command line the user
  must fix.  It carries structured :class:`Problem` objects (file, JSON or
  element path, what is wrong, the fix), decided where the problem is found,
  never guessed later from the text.  Each part of cosim has its subclass
  (at the end of this module: archives, expressions, clusters, studies, analysis).
- :class:`UnitError` -- a unit (an FMU, a Python unit, a player) failed while
  running, like any failed run.
- :class:`InternalError` -- a bug in cosim.

Exit codes are the command line's business: :mod:`cosim.cli.exit_codes` maps
these classes to them (UserError 2, UnitError 1, anything else 70).

This module imports nothing from the rest of cosim, so any module (and
plug-ins outside the package) can raise these errors without import cycles.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterator, Sized
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Sequence


@dataclass(frozen=True)
class Problem:
    """One mistake: the file, the path inside it (JSON path or element path), what is wrong, how to fix it.

    ``file`` and ``path`` may be empty for a command-line mistake.
    """

    file: str
    path: str
    message: str
    fix: str = ""

    def __str__(self) -> str:
        where = ": ".join(part for part in (self.file, self.path) if part)
        text = f"{where}: {self.message}" if where else self.message
        if self.fix:
            text += f"\n    fix: {self.fix}"
        return text


class CosimError(Exception):
    """The base of every error cosim raises on purpose."""


class UserError(CosimError):
    """Something the user must fix; ``problems`` lists every reason found (see :class:`Problem`).

    Built from Problems, or from one message (with optional ``file``,
    ``path`` and ``fix``) for a mistake that has one obvious place.
    """


    def __init__(self, problems: Sequence[Problem] | Problem | str, *, file: str = "", path: str = "",
                 fix: str = ""):
        if isinstance(problems, str):
            problems = [Problem(file, path, problems, fix)]
        elif isinstance(problems, Problem):
            problems = [problems]
        self.problems: list[Problem] = list(problems)
        super().__init__("\n".join(str(p) for p in self.problems))

    # picklable across Dask and child processes whatever the subclass's signature
    def __reduce__(self) -> tuple[Any, ...]:
        return _rebuild_user_error, (type(self), self.problems, self.__dict__)


def _rebuild_user_error(cls: type[UserError], problems: list[Problem], state: dict[str, Any]) -> UserError:
    error: UserError = UserError.__new__(cls)
    UserError.__init__(error, problems)
    error.__dict__.update(state)
    return error


class UsageError(UserError):
    """A mistake in the command line itself (an option, a value, a missing file argument)."""


class SpecError(UserError):
    """A spec cannot be used; ``problems`` lists every reason found."""


SUGGESTION_POOL = 5000  # candidates above which did_you_mean suggests nothing
SUGGESTION_BUDGET = 1_000_000  # comparisons did_you_mean may make within one suggestions_bounded() block
_budget = {"depth": 0, "left": float("inf")}


@contextmanager
def suggestions_bounded() -> Iterator[None]:
    """Bound the comparisons :func:`did_you_mean` makes in the block to SUGGESTION_BUDGET (about 4 s), so
    that thousands of wrong names among thousands of candidates are reported in linear time; beyond it the
    problems come without a suggestion.  The outermost block sets the budget; outside any, it is unbounded."""
    if _budget["depth"] == 0:
        _budget["left"] = SUGGESTION_BUDGET
    _budget["depth"] += 1
    try:
        yield
    finally:
        _budget["depth"] -= 1
        if _budget["depth"] == 0:
            _budget["left"] = float("inf")


def can_suggest(candidates: int) -> bool:
    """Whether :func:`did_you_mean` would still look among ``candidates`` names (to skip building them)."""
    return candidates <= SUGGESTION_POOL and candidates <= _budget["left"]


def did_you_mean(name: str, candidates: Iterable[str]) -> str:
    """' Did you mean 'x'?' for the closest candidate, or '' when none is close.

    Also '' for more than SUGGESTION_POOL candidates, and once the block's budget is spent (see
    :func:`suggestions_bounded`): difflib compares the name with each candidate, so 10^5 wrong names among
    10^5 variables (a generated SSP) took hours to report, 6000 among 6000 two minutes.
    """
    if isinstance(candidates, Sized) and not can_suggest(len(candidates)):
        return ""
    pool = list(candidates)
    if not can_suggest(len(pool)):
        return ""
    _budget["left"] -= len(pool)
    close = difflib.get_close_matches(name, pool, n=1, cutoff=0.6)
    return f" Did you mean '{close[0]}'?" if close else ""


def json_path(parts: Iterable[object]) -> str:
    """``$.units.a.parameters[0]`` from a sequence of keys and indices."""
    text = "$"
    for part in parts:
        text += f"[{part}]" if isinstance(part, int) else f".{part}"
    return text


class UnitError(CosimError):
    """A unit failed at run time: names the unit, the simulation time and what went wrong.

    ``traceback``: when a Python unit's own code raised, the frames of that code (see :func:`unit_traceback`),
    else ``""``; ``str()`` of the error is the one line without them, :meth:`with_traceback_text` adds them.
    """

    def __init__(self, unit: str, message: str, time: float | None = None, traceback: str = ""):
        self.unit = unit
        self.time = time
        self.message = message
        self.traceback = traceback
        where = f"unit '{unit}'" + (f" at t={time:g}" if time is not None else "")
        super().__init__(f"{where}: {message}")

    @classmethod
    def raised(cls, unit: str, call: str, exc: BaseException, time: float | None) -> "UnitError":
        """The error for a unit whose ``call`` (``do_step``, ``initialize()``) raised ``exc``: its type and
        text in the message, the unit's own frames in ``traceback``."""
        return cls(unit, f"{call} raised {type(exc).__name__}: {exc}", time, unit_traceback(exc))

    def with_traceback_text(self) -> str:
        """The one-line message, then the unit's frames when its Python code raised (what a row keeps)."""
        return f"{self}\n{self.traceback}" if self.traceback else str(self)

    def __reduce__(self) -> tuple[Any, ...]:
        return type(self), (self.unit, self.message, self.time, self.traceback)


class LoopError(UnitError):
    """An algebraic loop that did not converge (cosim.master.loops): names the loop, the time and the residual.

    A UnitError, so the run is a failed row like any unit's failure; ``unit`` holds the loop's name.
    """

    def __init__(self, loop: str, message: str, time: float | None = None, traceback: str = ""):
        self.unit = loop
        self.time = time
        self.message = message
        self.traceback = traceback
        CosimError.__init__(self, f"algebraic {loop}" + (f" at t={time:g}" if time is not None else "")
                            + f": {message}")


class StepControlError(UnitError):
    """The adaptive algorithm's steps kept missing the tolerance (cosim.master.adaptive): names the counts, the
    step, the time and the signal farthest off.  A UnitError, so the run is a failed row; ``unit`` holds the unit
    of that signal."""

    def __init__(self, unit: str, message: str, time: float | None = None, traceback: str = ""):
        self.unit = unit
        self.time = time
        self.message = message
        self.traceback = traceback
        CosimError.__init__(self, "adaptive steps" + (f" at t={time:g}" if time is not None else "")
                            + f": {message}")


#: bounds of the traceback a row keeps: the innermost frames of the unit's code, and at most so many characters
UNIT_TRACEBACK_FRAMES = 12
UNIT_TRACEBACK_CHARS = 4000
_COSIM_DIR = Path(__file__).resolve().parent
#: set (to "1") by ``cosim --debug``; inherited by the processes that run points, whose unit errors then keep
#: their whole traceback
DEBUG_VARIABLE = "COSIM_DEBUG"


def _cosim_own(filename: str) -> bool:
    """Whether a frame's file is cosim's engine (not a unit: the built-in units of cosim.models are units)."""
    try:
        relative = Path(filename).resolve().relative_to(_COSIM_DIR)
    except ValueError:
        return False
    return relative.parts[:1] != ("models",)


def unit_traceback(exc: BaseException, frames: int = UNIT_TRACEBACK_FRAMES, chars: int = UNIT_TRACEBACK_CHARS) -> str:
    """The traceback of ``exc`` raised by a unit's code, as Python prints it, without cosim's calling frames.

    Under ``cosim --debug`` (:data:`DEBUG_VARIABLE` set): the whole traceback, unbounded.  Else bounded for a
    results row: the ``frames`` innermost frames (a line says how many outer ones were left out)
    and at most ``chars`` characters (the end kept: the frame that raised and the exception).  ``""`` when no
    frame is the unit's (the error came from cosim itself).
    """
    import os
    import traceback

    if os.environ.get(DEBUG_VARIABLE):  # `cosim --debug`: everything, cosim's frames and the chain included
        return "".join(traceback.format_exception(exc)).rstrip("\n")
    stack = traceback.extract_tb(exc.__traceback__)
    while stack and _cosim_own(stack[0].filename):
        stack = traceback.StackSummary.from_list(stack[1:])
    if not stack:
        return ""
    left_out = max(0, len(stack) - frames)
    lines = ["Traceback (most recent call last):\n"]
    if left_out:
        lines.append(f"  ... {left_out} outer frame{'s' if left_out != 1 else ''} left out\n")
    lines += traceback.format_list(stack[left_out:]) + traceback.format_exception_only(type(exc), exc)
    text = "".join(lines).rstrip("\n")
    if len(text) > chars:
        text = "... (cut to its last " + str(chars) + " characters)\n" + text[-chars:]
    return text


class InternalError(CosimError):
    """A bug in cosim (an assumption of the engine that did not hold)."""


# -- the user errors of each part of cosim (one family, one module) --------------------------------------

# Files and archives


class ArchiveError(UserError):
    """An archive is refused; ``problems`` says why: each a Problem with the archive as its file,
    the member (when one is to blame) as its path, the rule or limit broken, and the fix."""

    def __init__(self, path: str | Path, problems: list[Problem]):
        self.path = str(path)
        super().__init__(problems)


class ModelJsonError(UserError, ValueError):
    """``model.json`` is malformed; the message names the file and the problem."""


class FmuBuildError(UserError, RuntimeError):
    """An FMU could not be built; the message says what to do about it (a user error: e.g. no C compiler)."""


class FmuProblems(UserError):
    """An FMU cannot be used; ``problems`` lists every reason as a :class:`Problem` with its fix.

    A plain string in ``problems`` becomes a Problem without a fix.
    ``path`` is the FMU's file (or its ``builtin:`` name).
    """

    def __init__(self, path: str, problems: Sequence[Problem | str]):
        self.path = path
        super().__init__([p if isinstance(p, Problem) else Problem(path, "", p) for p in problems])

    @property
    def messages(self) -> list[str]:
        """What is wrong, one text per problem (without file and fix)."""
        return [p.message for p in self.problems]


# Expressions


class ExpressionError(UserError, ValueError):
    """The expression is malformed, uses something not allowed, or names an unknown value."""


# Clusters and results folders


class ClusterError(UserError):
    """No Dask workers can be had (scheduler unreachable or without workers)."""


class SchedulerAddressError(ClusterError):
    """A scheduler address that does not have the form of one (``address``; ``why``: what the parser said)."""

    def __init__(self, address: str, why: str):
        self.address, self.why = address, why
        super().__init__(f"'{address}' is not a Dask scheduler address ({why}); write it as tcp://HOST:PORT, as "
                         "`dask scheduler` prints it, e.g. tcp://127.0.0.1:8786")


class ClusterFileError(UserError):
    """A cluster file that cannot be read, or whose cluster cannot be made as it says."""


class FolderInUse(UserError):
    """Another cosim process holds the results folder's lock."""


# Studies: one family (cosim.studies.runner runs them all); each kind of study raises its own subclass


class StudyError(UserError):
    """A study cannot start or go on as asked: its options, its results folder, its cluster (the base of every
    study's error; the message names options in the words of the caller, see cosim.studies.options)."""


class SweepError(StudyError):
    """A sweep cannot start as asked (results folder in use, resume of another spec, no workers)."""


class OutputError(SweepError):
    """The results folder cannot be written: read-only, full, no permission."""


class OptimizeError(StudyError):
    """An optimisation cannot start as asked (results folder in use, resume with other settings, no workers)."""


class SensitivityError(StudyError):
    """A sensitivity study cannot be done as asked."""


# Analysis


class AnalysisError(UserError, ValueError):
    """A user mistake when analysing a table: a missing file, unknown column, bad filter."""


# -- signals inside cosim, turned into Problems by whoever catches them -----------------------------------------


class UnitConversionError(ValueError):
    """Two units cannot be converted into each other (base of the two below)."""


class UnknownUnit(UnitConversionError):
    """A unit string that neither the FMU defines nor the unit syntax explains."""


class IncompatibleUnits(UnitConversionError):
    """Two known units of different quantities (e.g. N.m and A)."""


class AnnotationNumberError(ValueError):
    """An SSP tool annotation's attribute that should hold a positive number does not (cosim.ssp.annotations;
    the SSP schema does not check the tools' own elements).  The reader turns it into a Problem at
    ``element``."""

    def __init__(self, element: Any, attribute: str):
        super().__init__(f"{attribute}=\"{element.get(attribute)}\" is not a number")
        self.element = element
        self.attribute = attribute


class UnitImportError(ImportError):
    """A unit's module exited or hung while being imported."""


class KernelUnavailable(RuntimeError):
    """The kernel cannot be built here (no C compiler, a compile error); the message says why."""
