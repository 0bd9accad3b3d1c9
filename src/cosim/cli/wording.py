"""The command line's own words for what the library says in its own: option names instead of parameters.

The library below the command line names no command-line option (its messages are read from Python too);
where a message should name one, the error carries what it is about, and :func:`in_command_line_words`
rewrites it for ``cosim``'s stderr.
"""

from __future__ import annotations

from cosim.errors import SchedulerAddressError, UsageError


def in_command_line_words(exc: BaseException) -> BaseException:
    """``exc`` as the command line says it (another error of the same exit code), or ``exc`` itself."""
    if isinstance(exc, SchedulerAddressError):
        return UsageError(f"--scheduler {exc.problems[0].message}")
    return exc
