"""The command line's own words for what the library says in its own: option names instead of parameters.

The library below the command line names no command-line option (its messages are read from Python too).  A
study names an option through the ``words`` of its :class:`~cosim.studies.options.Show` record
(:data:`cosim.studies.options.PYTHON_WORDS` by default); the commands give :data:`CLI_WORDS`.  An error raised
before a study has its words (a malformed scheduler address) carries what it is about, and
:func:`in_command_line_words` rewrites it for ``cosim``'s stderr.
"""

from __future__ import annotations

from typing import Mapping

from cosim.errors import SchedulerAddressError, UsageError

# the keys of cosim.studies.options.PYTHON_WORDS, as the command line names them
CLI_WORDS: Mapping[str, str] = {
    "out": "--out", "out_dir": "--out DIR", "resume": "--resume", "recompute": "--recompute",
    "again": "the same command", "n": "-n", "n_is": "-n ", "seed": "--seed", "method": "--method",
    "storage": "--storage", "study_name": "--study-name",
}


def in_command_line_words(exc: BaseException) -> BaseException:
    """``exc`` as the command line says it (another error of the same exit code), or ``exc`` itself."""
    if isinstance(exc, SchedulerAddressError):
        return UsageError(f"--scheduler {exc.problems[0].message}")
    return exc
