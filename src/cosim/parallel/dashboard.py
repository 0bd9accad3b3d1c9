"""What the Dask dashboard shows of cosim's work, and what its web server may print.

- :func:`task_key`: the key of a task running a batch of points.  Dask groups
  tasks by the key's leading words (its *prefix*, ``dask.utils.key_split``),
  so every batch of one study falls under one progress bar named after it
  (``cosim sweep NAME``), and the rest of the key names the task's points,
  as the dashboard's task stream, worker and task pages show it:
  ``cosim sweep NAME-points 4..6 of 40-<unique>``.  Dask's bars count
  these tasks; the points page of :mod:`cosim.parallel.dashboard_points`
  counts points.  A point's own status is
  a row of the results table, never a task error: a failing point leaves no
  traceback in a worker's log.
- :func:`web_server_tracebacks_as_lines`: the dashboard of a cluster cosim
  starts runs inside the ``cosim`` process (the scheduler is local), and its
  web server (tornado, bokeh) logs an uncaught exception of a page handler
  with a full traceback on the terminal (e.g. ``GET /sitemap.json`` raises in
  distributed 2026.8).  While a study runs such records are logged as one
  line with the exception's type and message instead, and bokeh's error about a browser tab closed while
  its page loaded (:func:`tab_closed_while_loading`) not at all.
"""

from __future__ import annotations

import logging
import uuid
from contextlib import contextmanager
from typing import Iterator, Sequence

# loggers of the dashboard's web server (and of asyncio, where its unretrieved task errors end)
WEB_SERVER_LOGGERS = ("tornado.application", "tornado.general", "bokeh", "asyncio")


def task_key(kind: str, study: str, indices: Sequence[int], total: int, run: str = "") -> str:
    """A unique Dask key for the task running the points at ``indices`` (0-based) of the ``total`` of ``study``.

    ``kind`` is the command (``sweep``, ``optimize``); the prefix
    ``cosim KIND STUDY`` is what the progress bar shows.  ``run`` (letters
    and digits) identifies this run of the study for the points page of
    :mod:`cosim.parallel.dashboard_points`: the key then ends ``-RUN.<unique>``.
    """
    name = study.replace("-", "_") or "study"  # '-' separates a key's prefix from the rest
    first, last = indices[0] + 1, indices[-1] + 1
    if len(indices) == 1:
        which = f"point {first}"
    elif last - first + 1 == len(indices):
        which = f"points {first}..{last}"
    else:  # not consecutive
        which = f"{len(indices)} points from {first}"
    unique = f"{run}.{uuid.uuid4().hex[:16]}" if run else uuid.uuid4().hex
    return f"cosim {kind} {name}-{which} of {total}-{unique}"


def tab_closed_while_loading(exc: BaseException) -> bool:
    """Whether ``exc`` is the web server's reaction to a browser tab that went away while its page loaded.

    A dashboard tab closed (or reloaded) while its page loads ends the websocket before or while bokeh attaches
    a session to it.  Bokeh then trips over the missing session (``bokeh/server/connection.py``: ``assert
    self._session is not None``, from its ``on_close`` or from a message still being handled), or the work of
    the destroyed session is cancelled (``asyncio.CancelledError``); tornado and bokeh log either as an error,
    with a traceback, in the middle of the study's progress.  Nothing went wrong that the user could act on:
    the tab is simply gone.
    """
    import asyncio

    if isinstance(exc, asyncio.CancelledError):
        return True
    if not isinstance(exc, AssertionError):
        return False
    tb, innermost = exc.__traceback__, None
    while tb is not None:
        innermost, tb = tb, tb.tb_next
    if innermost is None:
        return False
    code = innermost.tb_frame.f_code
    return code.co_name == "session" and code.co_filename.replace("\\", "/").endswith("bokeh/server/connection.py")


class _OneLine(logging.Filter):
    """Replace a record's traceback by one line naming the exception; drop the report of a tab closed while its
    page loaded (:func:`tab_closed_while_loading`)."""

    def filter(self, record: logging.LogRecord) -> bool:
        if record.exc_info and record.exc_info[1] is not None:
            exc = record.exc_info[1]
            if tab_closed_while_loading(exc):
                return False
            first = record.getMessage().splitlines()[0] if record.getMessage() else ""
            record.msg, record.args = f"{first} ({type(exc).__name__}: {exc})", None
            record.exc_info, record.exc_text, record.stack_info = None, None, None
        return True


@contextmanager
def web_server_tracebacks_as_lines() -> Iterator[None]:
    """Within the block, the dashboard web server's errors are logged as single lines (module docstring).

    The filter sits on each logger (records logged there) and on its handlers
    (records of child loggers such as ``bokeh.server.views.ws`` that propagate
    to them).
    """
    one_line = _OneLine()
    places: list[logging.Filterer] = []
    for name in WEB_SERVER_LOGGERS:
        logger = logging.getLogger(name)
        places += [logger, *logger.handlers]
    for place in places:
        place.addFilter(one_line)
    try:
        yield
    finally:
        for place in places:
            place.removeFilter(one_line)
