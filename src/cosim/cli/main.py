"""The ``cosim`` command line: one function per subcommand.

Exit codes follow the kind of outcome: 0 everything ran, 1 a run failed,
2 a bad spec, file or usage (the user's to fix), 70 an internal error (ours);
:func:`cosim.cli.exit_codes.exit_code` decides them for every subcommand.
A user's mistake never shows a traceback.
"""

from __future__ import annotations

# Only the standard library's lightest modules at the top: the console script imports this module and then calls
# main(), whose first act is to install cosim's stop handlers.  A SIGTERM, SIGHUP or Ctrl-C that arrived while the
# rest (argparse, the error family, every subcommand's module) was still importing ended the process by the
# signal's default action (exit -15, -1, -2) instead of as a stop (exit 130) -- issue 38.
import os
import sys
from typing import TYPE_CHECKING, Any, Sequence

if TYPE_CHECKING:
    import argparse

    from cosim.cli.exit_codes import EXIT_INTERNAL, EXIT_OK, EXIT_RUN_FAILED, EXIT_USAGE
    from cosim.errors import UsageError

__all__ = ["EXIT_INTERNAL", "EXIT_OK", "EXIT_RUN_FAILED", "EXIT_USAGE", "UsageError", "main"]
_REEXPORTED = {"EXIT_INTERNAL": "cosim.cli.exit_codes", "EXIT_OK": "cosim.cli.exit_codes",
               "EXIT_RUN_FAILED": "cosim.cli.exit_codes", "EXIT_USAGE": "cosim.cli.exit_codes",
               "UsageError": "cosim.errors"}


def __getattr__(name: str) -> Any:
    """The names this module re-exports, imported on first use (see the comment on the imports)."""
    if name in _REEXPORTED:
        import importlib

        return getattr(importlib.import_module(_REEXPORTED[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

# The subcommand modules, each with a function registering its subcommands (and their handlers) on the
# parser; this module only builds the parser from them, dispatches, and maps outcomes to exit codes.
SUBCOMMAND_MODULES = (
    ("spec", "add_parsers"),  # validate, run, inspect
    ("new", "add_new_parser"),  # new
    ("export", "add_export_parsers"),  # export, export-fmu
    ("sweep", "add_sweep_parser"),  # sweep
    ("optimize", "add_optimize_parser"),  # optimize
    ("sensitivity", "add_sensitivity_parser"),  # sensitivity
    ("analysis", "add_analysis_parsers"),  # plot, pareto, report, explore
    ("surrogate", "add_surrogate_parsers"),  # surrogate, export-surrogate
)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``cosim`` console script; returns the exit code.

    Every subcommand returns its own code for what it ran (0, or 1 when a run
    failed); whatever it raises is reported here and mapped by
    :func:`cosim.cli.exit_codes.exit_code`: a UserError lists its problems
    (exit 2), anything unexpected prints a traceback (exit 70).  A stop (Ctrl-C, SIGTERM, SIGHUP) at any
    moment after this function began, also while the command's modules are still importing, ends it with
    "cosim: interrupted" and exit 130.
    """
    from cosim.parallel.cluster.interrupts import restore_signals, stop_cleanly_on_signals

    previous = stop_cleanly_on_signals()  # first of all, before the heavy imports (see the imports' comment)
    _SAID_INTERRUPTED.clear()  # a new command (main called again in one process: tests, notebooks)
    try:
        try:
            return _command(argv)
        except KeyboardInterrupt:  # a stop before the command ran: while importing, parsing, configuring
            _say_interrupted()
            return _exit_interrupted()
        finally:
            if argv is None:  # cosim is the program, and it ends now
                _end_at_once_on_signals()
                _skip_final_collections()
                _forget_caught_keyboard_interrupts()
            else:
                restore_signals(previous)  # main() may be called from a program with handlers of its own
    except KeyboardInterrupt:
        # the stop's KeyboardInterrupt raised once more while main() ended (in the block above's handler or
        # finally), after the command had been stopped: seen once in CI's suite as exit -2, Python ending an
        # uncaught KeyboardInterrupt by SIGINT (tests/studies/test_stop_races.py). A stop all the same.
        _say_interrupted()
        if argv is None:
            _end_at_once_on_signals()
            _forget_caught_keyboard_interrupts()
        return _exit_interrupted()


_SAID_INTERRUPTED: list[bool] = []  # whether "cosim: interrupted" was printed by this process


def _say_interrupted() -> None:
    """Print ``cosim: interrupted`` on stderr, once per process."""
    if not _SAID_INTERRUPTED:
        _SAID_INTERRUPTED.append(True)
        print("cosim: interrupted", file=sys.stderr)


def _exit_interrupted() -> int:
    from cosim.cli.exit_codes import EXIT_INTERRUPTED

    return EXIT_INTERRUPTED


def _command(argv: Sequence[str] | None) -> int:
    """Parse ``argv`` (None: sys.argv) and run its subcommand; its exit code (see :func:`main`)."""
    from cosim.cli.exit_codes import EXIT_RUN_FAILED, EXIT_USAGE, exit_code
    from cosim.errors import DEBUG_VARIABLE
    from cosim.parallel.cluster.interrupts import raise_if_stopped

    parser = _parser()
    arguments = list(sys.argv[1:] if argv is None else argv)
    arguments = _global_options_first(arguments)
    args = parser.parse_args(arguments)
    _configure_logging(args)
    if args.debug:  # the processes that run points inherit it: their unit errors keep the whole traceback
        os.environ[DEBUG_VARIABLE] = "1"
    if not getattr(args, "handler", None):
        parser.print_help()
        return EXIT_USAGE
    stdout = sys.stdout
    sys.stdout = _ReaderMayLeave(stdout)  # `cosim sweep ... | head`: the command goes on and says how it ended
    try:
        code = args.handler(args)
        raise_if_stopped()  # a stop whose KeyboardInterrupt was swallowed on its way never ends as success
        return code
    except BrokenPipeError:  # written past the wrapper: the command did not finish, so it did not succeed
        _discard_stdout()
        print("cosim: standard output was closed before the command finished", file=sys.stderr)
        return EXIT_RUN_FAILED
    except BaseException as exc:  # noqa: BLE001 - every outcome gets its exit code here, and only here
        if isinstance(exc, SystemExit):
            raise
        from cosim.cli.wording import in_command_line_words

        report_error(in_command_line_words(exc), debug=args.debug, all_problems=args.all_problems)
        return exit_code(exc)
    finally:
        sys.stdout = stdout


def _end_at_once_on_signals() -> None:
    """The command is done and its process ends: a Ctrl-C, SIGTERM or SIGHUP from now on ends it at once, quietly.

    Python's own handlers raised KeyboardInterrupt wherever the interpreter was while it shut down (a weakref
    callback, a module's exit hook), which printed "Exception ignored ... KeyboardInterrupt" with a traceback
    after ``cosim: interrupted`` when an impatient user pressed Ctrl-C again.  What the command wrote is
    flushed first.  The exit code is the stop's 130 when the command was stopped (a second signal does not
    change how it ended: seen once in the suite as 143 after "cosim: interrupted"), otherwise 128 + the
    signal's number, as a shell reports a process a signal ended.
    """
    import signal

    from cosim.cli.exit_codes import EXIT_INTERRUPTED
    from cosim.parallel.cluster.interrupts import stop_requested

    code_if_signalled = EXIT_INTERRUPTED if stop_requested() is not None or _SAID_INTERRUPTED else None

    def end(signum: int, frame: Any) -> None:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except Exception:  # noqa: BLE001 - a closed pipe, or a write this signal interrupted
                pass
        os._exit(code_if_signalled or 128 + signum)

    for name in ("SIGINT", "SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), end)


def _forget_caught_keyboard_interrupts() -> None:
    """The command is done and its process ends: the exit code is the one main() returns, also after a stop.

    CPython marks a KeyboardInterrupt "unhandled" when it ends code run by ``eval`` or ``exec`` of a string
    (``run_eval_code_obj``), even when a caller catches it later; at exit a process run as ``python -m`` (as
    ``python -m cosim.cli.main`` is) then ends itself by SIGINT (bpo-1054041), whatever exit code it gave.  A stop that came while a module built a
    namedtuple or a dataclass (both ``eval``/``exec`` strings) ended as exit -2 after "cosim: interrupted"
    (6 of 80 SIGTERMs 0.1-0.7 s after the start, 2026-12-07; tests/studies/test_stop_races.py in CI).  cosim handles
    every KeyboardInterrupt itself, so the mark is cleared.  The mark is CPython 3.11's exported
    ``_Py_UnhandledKeyboardInterrupt``; where the interpreter has no such symbol this does nothing.
    """
    import ctypes

    try:
        ctypes.c_int.in_dll(ctypes.pythonapi, "_Py_UnhandledKeyboardInterrupt").value = 0
    except (AttributeError, ValueError, OSError):  # another interpreter, or another CPython's layout
        pass


def _skip_final_collections() -> None:
    """The command is done and its process ends: spare the interpreter's garbage collections at exit.

    After a sweep the process holds Dask, bokeh, pandas and pyarrow; collecting
    their objects once more at exit took 0.3-2 s (more under load) and frees
    nothing the operating system would not.  ``gc.freeze`` exempts the objects
    alive now; exit handlers still run.  Only when cosim is the program
    (``argv`` not given): a caller of ``main([...])`` goes on living.
    """
    import gc

    gc.freeze()


class _ReaderMayLeave:
    """Standard output that a reader may close early (``| head``): from then on, what is written is dropped.

    Without it the first print after the reader left raised BrokenPipeError in the middle
    of a command, and its outcome (points failed: exit 1) was lost: every command ended 0.
    The command now runs to its end and returns its own exit code; only its output is cut.
    """

    def __init__(self, stream: Any):
        self._stream = stream
        self._closed = False

    def write(self, text: str) -> int:
        if not self._closed:
            try:
                return self._stream.write(text)
            except BrokenPipeError:
                self._reader_left()
        return len(text)

    def flush(self) -> None:
        if not self._closed:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._reader_left()

    def _reader_left(self) -> None:
        self._closed = True
        _discard_stdout()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


def _discard_stdout() -> None:
    """Point stdout at /dev/null, so the interpreter's final flush into the closed pipe raises nothing."""
    import os

    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)


def report_error(exc: BaseException, debug: bool = False, all_problems: bool = False) -> None:
    """Print what a user needs to know about ``exc`` on stderr: no traceback for a user's mistake, unless
    ``debug`` (``cosim --debug``), which prints every error's whole traceback after its message.  Many
    problems are listed as a sample by kind unless ``all_problems`` (see :mod:`cosim.cli.problems`)."""
    import traceback

    from cosim.cli.problems import print_problems
    from cosim.errors import UnitError, UserError

    if isinstance(exc, UserError):
        print_problems(exc.problems, every=all_problems)
    elif isinstance(exc, KeyboardInterrupt):
        _say_interrupted()
        return
    elif isinstance(exc, UnitError):  # a unit that failed outside a run's result: its own frames
        print(f"cosim: {exc.with_traceback_text()}", file=sys.stderr)
    else:
        print("cosim: internal error (please report it with the text below)", file=sys.stderr)
        debug = True
    if debug:
        traceback.print_exception(exc)


GLOBAL_FLAGS = ("--debug", "--all-problems", "-q", "--quiet", "-v", "-vv", "--verbose")  # cli.problems.ALL_PROBLEMS


def _global_options_first(arguments: list[str]) -> list[str]:
    """The options of every command (--debug, --all-problems, -q, -v, --log-level LEVEL) moved to the front, so that
    ``cosim sweep spec.json -q`` works as well as ``cosim -q sweep spec.json``."""
    front, rest, i = [], [], 0
    while i < len(arguments):
        a = arguments[i]
        if a == "--":  # everything after it is positional
            rest.extend(arguments[i:])
            break
        if a in GLOBAL_FLAGS or a.startswith("--log-level="):
            front.append(a)
        elif a == "--log-level" and i + 1 < len(arguments):
            front.extend(arguments[i:i + 2])
            i += 1
        else:
            rest.append(a)
        i += 1
    return front + rest


def _configure_logging(args: argparse.Namespace) -> None:
    """Python logging at the level asked: --log-level, else -q (errors only, and studies without progress
    line or notes), -v (info) or -vv (debug); left alone (warnings and above shown) when none is given."""
    import logging

    # A log record that cannot be written (Dask's threads logging while the process exits and stderr is closed)
    # is dropped, as a program in production does, instead of printing "--- Logging error ---" with a traceback.
    logging.raiseExceptions = False
    if not (args.log_level or args.quiet or args.verbose):
        return  # as Python leaves it (a program calling main() keeps its own logging)
    level = args.log_level or ("ERROR" if args.quiet else {1: "INFO"}.get(args.verbose, "DEBUG"))
    root = logging.getLogger()
    handler = next((h for h in root.handlers if getattr(h, "cosim_cli", False)), None)
    if handler is None:  # main() may run more than once in a process: one handler
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("cosim %(levelname)s %(name)s: %(message)s"))
        handler.cosim_cli = True  # type: ignore[attr-defined]
        root.addHandler(handler)
    handler.setLevel(level)  # libraries that set their own loggers' levels (Dask: INFO) still reach only this far
    root.setLevel(level)
    logging.getLogger("cosim").setLevel(level)


def _parser() -> argparse.ArgumentParser:
    import argparse
    import importlib

    from cosim import __version__
    from cosim.cli.problems import ALL_PROBLEMS, SHOWN

    parser = argparse.ArgumentParser(prog="cosim", description="FMI co-simulation orchestrator.")
    parser.add_argument("--version", action="version", version=f"cosim {__version__}")
    parser.add_argument("--debug", action="store_true",
                        help="print every error's whole traceback (also a user's mistake), and keep the whole "
                             "traceback, cosim's frames included, of a Python unit that raised (anywhere on the "
                             "command line)")
    parser.add_argument(ALL_PROBLEMS, action="store_true",
                        help=f"list every problem of a spec or file; without it, above {SHOWN} problems a sample "
                             "by kind is listed, with how many more there are (anywhere on the command line)")
    loudness = parser.add_mutually_exclusive_group()
    loudness.add_argument("-q", "--quiet", action="store_true",
                          help="only errors: no progress line or notes from sweep, optimize and sensitivity, log "
                               "level ERROR (anywhere on the command line)")
    loudness.add_argument("-v", "--verbose", action="count", default=0,
                          help="log level INFO (-vv: DEBUG) (anywhere on the command line)")
    parser.add_argument("--log-level", choices=("DEBUG", "INFO", "WARNING", "ERROR"), type=str.upper,
                        help="the level of Python logging (cosim's and its libraries'); default WARNING")
    sub = parser.add_subparsers(title="commands")
    for module, register in SUBCOMMAND_MODULES:
        getattr(importlib.import_module(f"cosim.cli.{module}"), register)(sub)
    from cosim.cli.examples import add_examples

    add_examples(sub)
    return parser


if __name__ == "__main__":  # python -m cosim.cli.main
    sys.exit(main())
