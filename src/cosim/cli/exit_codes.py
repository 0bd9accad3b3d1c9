"""The exit codes of the ``cosim`` command, and the one mapping from an outcome to them.

0 everything ran, 1 a run (or some points of a study) failed, 2 a bad spec, file or command line (the user's to
fix), 70 a bug in cosim (EX_SOFTWARE), 130 interrupted (Ctrl-C, SIGTERM).  Every subcommand returns its code for
what it ran, and :func:`exit_code` decides the code of whatever it raises; the library below the command line
knows nothing of exit codes.
"""

from __future__ import annotations

from typing import Any

from cosim.errors import UnitError, UserError

EXIT_OK = 0  # everything ran
EXIT_RUN_FAILED = 1  # a run (or some sweep points) failed
EXIT_USAGE = 2  # a bad spec, file or command line: the user's to fix
EXIT_INTERNAL = 70  # a bug in cosim (EX_SOFTWARE)
EXIT_INTERRUPTED = 130  # Ctrl-C

# why a run failed (RunResult.failure) -> the code of a command that ran only that run
_RUN_FAILURES = {"unit": EXIT_RUN_FAILED, "user": EXIT_USAGE, "internal": EXIT_INTERNAL}


def exit_code(error: BaseException | None) -> int:
    """The exit code of a command that ended with ``error`` (None: success).

    UserError 2, UnitError 1, Ctrl-C 130; InternalError and anything unexpected 70.
    """
    if error is None:
        return EXIT_OK
    if isinstance(error, KeyboardInterrupt):
        return EXIT_INTERRUPTED
    if isinstance(error, UserError):
        return EXIT_USAGE
    if isinstance(error, UnitError):
        return EXIT_RUN_FAILED
    return EXIT_INTERNAL  # an InternalError, or anything unexpected


def run_exit_code(result: Any) -> int:
    """The exit code of a command that ran one point (``cosim run``): 0 when ``result`` is ok, else by why it
    failed (a unit 1, a user's file found unusable while running 2, a bug 70)."""
    if result.ok:
        return EXIT_OK
    return _RUN_FAILURES.get(result.failure, EXIT_RUN_FAILED)
