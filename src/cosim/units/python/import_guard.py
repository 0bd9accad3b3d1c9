"""Importing a Python unit's module without letting it end or hang the process that checks it.

A module runs its top-level code when imported.  If that code calls
``sys.exit()`` or ``os._exit()``, crashes in native code, sleeps or loops,
``cosim validate`` would end (with exit code 0 as if the spec were fine) or
hang, and so would a sweep's client.  Two guards stand in the way:

- :func:`import_in_child_first`: before a module is imported into this
  process for the first time, a child process imports it.  A child that ends
  without reporting back (``os._exit()``, a signal, a native crash) or takes
  longer than the ``import_seconds`` limit (``COSIM_IMPORT_SECONDS``; also a
  native call that never returns to Python) gives a UnitImportError naming the
  module, and this process never runs the import.  Worker children
  (:mod:`cosim.parallel.isolation`) turn this off: they are the isolation, a
  module that kills one costs a ``crashed`` point.
- :func:`guarded_import` around the import itself: SystemExit becomes a
  UnitImportError, and in the main thread a timer signal (SIGALRM) interrupts
  Python code that takes longer than the limit.
"""

from __future__ import annotations

import os
import secrets
import signal
import subprocess
import sys
import threading
from contextlib import contextmanager
from typing import Iterator

from cosim.errors import UnitImportError
from cosim.util import limits

CHECK_IN_CHILD = True  # False in the worker children, which are a child process already
_IN_CHECKING_CHILD = False  # True in the child of import_in_child_first: its parent keeps the time


class _ImportTimeout(BaseException):
    """Raised by the timer inside the import; a BaseException so that the module's own
    ``except Exception`` cannot swallow it."""


def _on_alarm(signum: int, frame: object) -> None:
    raise _ImportTimeout()


def _too_slow(what: str, seconds: float) -> UnitImportError:
    return UnitImportError(f"importing {what} took longer than {seconds:g} s (does it wait or loop at import "
                           f"time?); {limits.raise_hint('import_seconds')}")


@contextmanager
def guarded_import(what: str) -> Iterator[None]:
    """Run the import in the ``with`` body; SystemExit or a timeout in it raise UnitImportError.

    ``what`` names the module in messages.
    """
    seconds = float(limits.limit("import_seconds"))
    timed = (not _IN_CHECKING_CHILD and threading.current_thread() is threading.main_thread() and hasattr(signal, "setitimer")
             and signal.getitimer(signal.ITIMER_REAL)[0] == 0)  # never disturb a timer someone else set
    previous = None
    if timed:
        previous = signal.signal(signal.SIGALRM, _on_alarm)
        signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    except SystemExit as exc:
        raise UnitImportError(f"{what} called sys.exit({exc.code!r}) while being imported; a unit's module must "
                              "not exit (move that code under 'if __name__ == \"__main__\":')") from None
    except _ImportTimeout:
        raise _too_slow(what, seconds) from None
    finally:
        if timed:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)


def import_in_child_first(what: str, target: str, base_dir: str | None, source_zip: str | None) -> None:
    """Import the Python unit ``target`` (see PythonUnitType) in a child process; raise if that ends or hangs it.

    Returns when the child finished the import, also when the import raised an
    ordinary exception (the caller's own import then reports it as usual).
    Raises UnitImportError, naming ``what``, when the child ended without
    reporting back or was still importing after the ``import_seconds`` limit
    (it is then killed with everything it started).  Does nothing when
    :data:`CHECK_IN_CHILD` is off.
    """
    if not CHECK_IN_CHILD:
        return
    seconds = float(limits.limit("import_seconds"))
    token = secrets.token_hex(8)  # a module cannot print it by chance
    report_r, report_w = os.pipe()  # not stdout: the module may print, redirect or close it
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if isinstance(p, str) and p))
    try:
        child = subprocess.Popen(
            [sys.executable, "-c", "import sys; from cosim.units.python.unit import import_check_child; "
             "import_check_child(*sys.argv[1:])", str(report_w), token, target, base_dir or "", source_zip or ""],
            pass_fds=(report_w,), env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE, start_new_session=True)  # its own group: a timeout kills what it started
    finally:
        os.close(report_w)
    try:
        try:
            _, stderr = child.communicate(timeout=seconds)
        except subprocess.TimeoutExpired:
            _kill_group(child)
            raise _too_slow(what, seconds) from None
        except BaseException:  # Ctrl-C: the child is in its own session, so it must be stopped here
            _kill_group(child)
            raise
        with os.fdopen(report_r, "rb", closefd=False) as report:
            reported = report.read().decode(errors="replace") == token
    finally:
        os.close(report_r)
    if not reported:
        how = (f"killed by signal {signal.Signals(-child.returncode).name}" if child.returncode < 0
               else f"exit code {child.returncode}")
        last = next((line for line in reversed(stderr.decode(errors="replace").splitlines()) if line.strip()), "")
        raise UnitImportError(f"importing {what} ended the process ({how}{'; ' + last.strip() if last else ''}): "
                              "a unit's module must not exit or crash while being imported (os._exit(), a crash "
                              "in native code)")


def _kill_group(child: subprocess.Popen[bytes]) -> None:
    try:
        os.killpg(child.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    child.wait()


def enter_checking_child() -> None:
    """Called first in the child :func:`import_in_child_first` starts: it starts no child of its own, and sets
    no timer (its parent keeps the time)."""
    global CHECK_IN_CHILD, _IN_CHECKING_CHILD
    CHECK_IN_CHILD, _IN_CHECKING_CHILD = False, True
