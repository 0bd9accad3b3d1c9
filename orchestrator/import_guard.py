"""Importing a Python unit's module without letting it end or hang the process that checks it.

A module runs its top-level code when imported.  If that code calls
``sys.exit()``, the SystemExit would end ``cosim validate`` with exit code 0
as if the spec were fine; if it sleeps or loops, validate (or a sweep's
client) would hang.  :func:`guarded_import` turns both into an ImportError
that names the module: SystemExit is caught, and in the main thread a timer
signal (SIGALRM) interrupts an import that takes longer than the
``import_seconds`` limit (``COSIM_IMPORT_SECONDS``).  The timer interrupts
Python code and sleeps; native code that blocks without returning to Python
is not interrupted (a sweep's worker children have their own load deadline).
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Iterator

from . import limits


class UnitImportError(ImportError):
    """A unit's module exited or hung while being imported."""


class _ImportTimeout(BaseException):
    """Raised by the timer inside the import; a BaseException so that the module's own
    ``except Exception`` cannot swallow it."""


def _on_alarm(signum: int, frame: object) -> None:
    raise _ImportTimeout()


@contextmanager
def guarded_import(what: str) -> Iterator[None]:
    """Run the import in the ``with`` body; SystemExit or a timeout in it raise UnitImportError.

    ``what`` names the module in messages.
    """
    seconds = float(limits.limit("import_seconds"))
    timed = (threading.current_thread() is threading.main_thread() and hasattr(signal, "setitimer")
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
        raise UnitImportError(f"importing {what} took longer than {seconds:g} s (does it wait or loop at import "
                              f"time?); {limits.raise_hint('import_seconds')}") from None
    finally:
        if timed:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
