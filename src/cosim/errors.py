"""cosim's one error family and the exit codes it maps to.

Every error cosim raises on purpose derives from :class:`CosimError` and says
whose it is to fix:

- :class:`UserError` -- a spec, a file, a table or a command line the user
  must fix.  It carries structured :class:`Problem` objects (file, JSON or
  element path, what is wrong, the fix), decided where the problem is found,
  never guessed later from the text.  Exit code 2.
- :class:`UnitError` -- a unit (an FMU, a Python unit, a player) failed while
  running.  Exit code 1, like any failed run.
- :class:`InternalError` -- a bug in cosim.  Exit code 70.

:func:`exit_code` is the only place that turns an outcome into an exit code;
every ``cosim`` subcommand goes through it (see :mod:`cosim.cli.main`).
Anything that is not a CosimError escaping a command is treated as internal.

This module imports nothing from the rest of cosim, so any module (and
plug-ins outside the package) can raise these errors without import cycles.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from typing import Iterable, Sequence

EXIT_OK = 0  # everything ran
EXIT_RUN_FAILED = 1  # a run (or some sweep points) failed
EXIT_USAGE = 2  # a bad spec, file or command line: the user's to fix
EXIT_INTERNAL = 70  # a bug in cosim (EX_SOFTWARE)
EXIT_INTERRUPTED = 130  # Ctrl-C


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
    """The base of every error cosim raises on purpose; ``exit_code`` says how a command ends."""

    exit_code = EXIT_INTERNAL


class UserError(CosimError):
    """Something the user must fix; ``problems`` lists every reason found (see :class:`Problem`).

    Built from Problems, or from one message (with optional ``file``,
    ``path`` and ``fix``) for a mistake that has one obvious place.
    """

    exit_code = EXIT_USAGE

    def __init__(self, problems: Sequence[Problem] | Problem | str, *, file: str = "", path: str = "",
                 fix: str = ""):
        if isinstance(problems, str):
            problems = [Problem(file, path, problems, fix)]
        elif isinstance(problems, Problem):
            problems = [problems]
        self.problems: list[Problem] = list(problems)
        super().__init__("\n".join(str(p) for p in self.problems))

    def __reduce__(self):  # picklable across Dask and child processes whatever the subclass's signature
        return _rebuild_user_error, (type(self), self.problems, self.__dict__)


def _rebuild_user_error(cls: type, problems: list[Problem], state: dict) -> UserError:
    error = UserError.__new__(cls)
    UserError.__init__(error, problems)
    error.__dict__.update(state)
    return error


class UsageError(UserError):
    """A mistake in the command line itself (an option, a value, a missing file argument)."""


class SpecError(UserError):
    """A spec cannot be used; ``problems`` lists every reason found."""


def did_you_mean(name: str, candidates: Iterable[str]) -> str:
    """' Did you mean 'x'?' for the closest candidate, or '' when none is close."""
    close = difflib.get_close_matches(name, list(candidates), n=1, cutoff=0.6)
    return f" Did you mean '{close[0]}'?" if close else ""


def json_path(parts: Iterable[object]) -> str:
    """``$.units.a.parameters[0]`` from a sequence of keys and indices."""
    text = "$"
    for part in parts:
        text += f"[{part}]" if isinstance(part, int) else f".{part}"
    return text


class UnitError(CosimError):
    """A unit failed at run time: names the unit, the simulation time and what went wrong."""

    exit_code = EXIT_RUN_FAILED

    def __init__(self, unit: str, message: str, time: float | None = None):
        self.unit = unit
        self.time = time
        self.message = message
        where = f"unit '{unit}'" + (f" at t={time:g}" if time is not None else "")
        super().__init__(f"{where}: {message}")

    def __reduce__(self):
        return type(self), (self.unit, self.message, self.time)


class InternalError(CosimError):
    """A bug in cosim (an assumption of the engine that did not hold)."""

    exit_code = EXIT_INTERNAL


def exit_code(error: BaseException | None) -> int:
    """The exit code of a command that ended with ``error`` (None: success).

    The one mapping of the command line: UserError 2, UnitError 1,
    InternalError and anything unexpected 70, Ctrl-C 130.
    """
    if error is None:
        return EXIT_OK
    if isinstance(error, KeyboardInterrupt):
        return EXIT_INTERRUPTED
    if isinstance(error, CosimError):
        return error.exit_code
    return EXIT_INTERNAL

