"""What the web server of the Dask dashboard may print while a study runs.

The dashboard of a cluster cosim starts runs inside the ``cosim`` process (the scheduler is local), and its web
server (tornado, bokeh) logs an uncaught exception of a page handler with a full traceback on the terminal
(e.g. ``GET /sitemap.json`` raises in distributed 2026.8).  Within :func:`web_server_tracebacks_as_lines` such
records are logged as one line with the exception's type and message instead, and bokeh's error about a
browser tab closed while its page loaded (:func:`tab_closed_while_loading`) not at all.
"""

from __future__ import annotations

import logging
from contextlib import contextmanager
from typing import Iterator

# loggers of the dashboard's web server (and of asyncio, where its unretrieved task errors end)
WEB_SERVER_LOGGERS = ("tornado.application", "tornado.general", "bokeh", "asyncio")


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
