"""A re-run of designs (:func:`cosim.analysis.rerun.rerun_rows`) in a child process, with a timeout and a cancel.

The decision room's "Re-run selected" ran the designs in a thread of the server: a design that hangs (an FMU
looping in doStep) or runs for hours kept the button disabled and a core busy until the server ended, and
nothing could stop it.  :class:`RerunJob` runs them in a child process instead (started fresh, so no state of
the server's process is shared), and ends it at its timeout or when cancelled; killing a process stops a hung
FMU too, which no thread could.  The timeout is ``max(COSIM_TIMEOUT_FLOOR, 10 * the rows' own run times)``, as
a sweep's per-point timeout starts, unless given.
"""

from __future__ import annotations

import multiprocessing
import signal
import threading
from typing import Any, Sequence

import numpy as np

from cosim.analysis.table import AnalysisError, ResultsTable
from cosim.util.limits import limit

TIMES_RUN_TIME = 10.0  # a re-run may take this many times the rows' recorded run times (at least the floor)


class RerunStopped(Exception):
    """The re-run did not finish: ``why`` says whether it timed out or was cancelled."""


def rerun_timeout(table: ResultsTable, rows: Sequence[int]) -> float:
    """Seconds the re-run of ``rows`` may take: ten times their recorded ``run_time`` in all, at least the
    ``timeout_floor_seconds`` limit (COSIM_TIMEOUT_FLOOR)."""
    floor = float(limit("timeout_floor_seconds"))
    if "run_time" not in table.df.columns:
        return floor
    times = table.df["run_time"].to_numpy(float)[list(rows)]
    total = float(np.nansum(times)) if len(times) else 0.0
    return max(floor, TIMES_RUN_TIME * total)


def _child(conn: Any, table: ResultsTable, rows: list[int], spec_path: Any) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a terminal's Ctrl-C is the server's to handle
    from cosim.analysis.rerun import rerun_rows

    try:
        outcome: tuple[str, Any] = ("ok", rerun_rows(table, rows, spec_path))
    except Exception as exc:  # noqa: BLE001 - a bad spec or value: its text goes back, shown in the page
        outcome = ("error", str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
    conn.send(outcome)
    conn.close()


class RerunJob:
    """``rerun_rows(table, rows, spec_path)`` in a child process; :meth:`wait` gives its Reruns.

    ``timeout`` seconds (None: :func:`rerun_timeout`) bound it; :meth:`cancel` ends it from any thread.
    """

    def __init__(self, table: ResultsTable, rows: Sequence[int], spec_path: Any = None,
                 timeout: float | None = None):
        self.rows = [int(r) for r in rows]
        self.timeout = rerun_timeout(table, self.rows) if timeout is None else float(timeout)
        self._cancelled = threading.Event()
        context = multiprocessing.get_context("spawn")
        self._inbox, outbox = context.Pipe(duplex=False)
        self._process = context.Process(target=_child, args=(outbox, table, self.rows, spec_path), daemon=True,
                                        name="cosim-room-rerun")
        self._process.start()
        outbox.close()

    def cancel(self) -> None:
        """End the re-run now (its :meth:`wait` raises RerunStopped)."""
        self._cancelled.set()
        self._end()

    def wait(self) -> list[Any]:
        """The Reruns, once the child sends them.  Raises RerunStopped when cancelled or past the timeout,
        AnalysisError with the child's message when the spec or a row's values do not fit, or the child died."""
        try:
            deadline = self.timeout
            while deadline > 0 and not self._cancelled.is_set():
                step = min(0.2, deadline)
                if self._inbox.poll(step):
                    try:
                        kind, body = self._inbox.recv()
                    except (EOFError, OSError):  # the child died without a word (or was ended by cancel)
                        break
                    if kind == "ok":
                        return list(body)
                    raise AnalysisError(str(body))
                if not self._process.is_alive() and not self._inbox.poll(0):
                    break
                deadline -= step
            if self._cancelled.is_set():
                raise RerunStopped("cancelled")
            if deadline <= 0:
                raise RerunStopped(f"no result within {self.timeout:g} s (the timeout: 10 times the designs' run "
                                   "time, at least COSIM_TIMEOUT_FLOOR); it was stopped")
            raise AnalysisError(f"the process re-running the designs died (exit {self._process.exitcode})")
        finally:
            self._end()

    def _end(self) -> None:
        if self._process.is_alive():
            self._process.kill()
        self._process.join(timeout=5)
