"""The one status line every study prints while it runs: a sweep's points, an optimisation's evaluations.

On a terminal the line is rewritten in place, at most five times a second; in a log (a file, a pipe) one line is
written per tenth of the work, so a long study leaves ten lines, not thousands.  A closed terminal never stops a
study: printing errors are ignored.
"""

from __future__ import annotations

import math
import sys
import time
from typing import TextIO

TERMINAL_INTERVAL = 0.2  # seconds between two rewrites of the line on a terminal


class StatusLine:
    """Shows ``text`` for ``done`` of ``total`` units of work on ``stream`` (default: stderr)."""

    def __init__(self, total: int, stream: TextIO | None = None):
        self.total = total
        self.stream = stream if stream is not None else sys.stderr
        try:
            self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        except (OSError, ValueError):  # a closed stream: nothing will be shown, and nothing raised
            self.tty = False
        self.started = time.perf_counter()
        self._last_time = -math.inf
        self._last_tenth = -1
        self._shown = False

    def elapsed(self) -> float:
        """Seconds since the line was made."""
        return time.perf_counter() - self.started

    def show(self, done: int, text: str) -> None:
        """Print ``text`` unless a line was shown too recently (terminal) or in this tenth of the work (log);
        the line of the finished work is always shown."""
        finished = done >= self.total
        now = time.perf_counter()
        tenth = int(10 * done / max(self.total, 1))
        if self.tty and now - self._last_time < TERMINAL_INTERVAL and not finished:
            return
        if not self.tty and tenth == self._last_tenth and not finished:
            return
        self._last_time, self._last_tenth = now, tenth
        self._print(text, end="\r" if self.tty else "\n")
        self._shown = True

    def close(self) -> None:
        """End the line on a terminal (the next output starts on a line of its own)."""
        if self.tty and self._shown:
            self._print("")

    def _print(self, text: str, end: str = "\n") -> None:
        try:
            print(text, end=end, file=self.stream, flush=True)
        except (OSError, ValueError):
            pass  # a closed terminal must not stop the study


def duration(seconds: float) -> str:
    """``m:ss`` or ``h:mm:ss``; ``?`` for an unknown (infinite) duration."""
    if not math.isfinite(seconds):
        return "?"
    seconds = int(round(seconds))
    return f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}" if seconds >= 3600 \
        else f"{seconds // 60}:{seconds % 60:02d}"
