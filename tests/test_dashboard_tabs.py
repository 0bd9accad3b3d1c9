"""Issue 28.15: closing a dashboard tab while a study runs prints nothing on the study's terminal.

A tab closed while its page loads made bokeh assert that its (not yet made) session exists, or cancelled its
session's work; tornado and bokeh logged that at ERROR in the middle of the progress line.  Here a real sweep
with its dashboard, and chromium opening its status page in tabs closed again after 0.5-2 s, as a user
clicking around does; and the filter against the exceptions bokeh's own code raises.
"""

from __future__ import annotations

import asyncio
import logging
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cosim.parallel.dashboard import tab_closed_while_loading, web_server_tracebacks_as_lines

from .test_hostile_files import _spec
from .test_room_browser import browser  # noqa: F401  (fixture)

SRC = Path(__file__).resolve().parent.parent / "src"


def bokeh_without_session() -> AssertionError:
    """The AssertionError bokeh itself raises when a connection's session is asked for before it was made."""
    from bokeh.server.connection import ServerConnection

    connection = ServerConnection.__new__(ServerConnection)
    connection._session = None
    try:
        connection.session
    except AssertionError as exc:
        return exc
    pytest.fail("bokeh no longer asserts on a missing session: see what a closed tab logs now")


def test_the_errors_of_a_tab_gone_are_dropped_and_other_errors_kept_as_one_line(caplog):
    assert tab_closed_while_loading(bokeh_without_session())
    assert tab_closed_while_loading(asyncio.CancelledError())
    try:
        raise AssertionError("ours")  # an assertion of some other code: an error worth its line
    except AssertionError as exc:
        other = exc
    assert not tab_closed_while_loading(other) and not tab_closed_while_loading(KeyError("x"))
    logger = logging.getLogger("tornado.application")
    with caplog.at_level(logging.ERROR, logger="tornado.application"), web_server_tracebacks_as_lines():
        for exc in (bokeh_without_session(), asyncio.CancelledError(), other):
            logger.error("Uncaught exception GET /status/ws (127.0.0.1)", exc_info=(type(exc), exc,
                                                                                   exc.__traceback__))
    assert [r.getMessage() for r in caplog.records] == [
        "Uncaught exception GET /status/ws (127.0.0.1) (AssertionError: ours)"]


def test_closing_dashboard_tabs_during_a_sweep_prints_no_error(tmp_path, browser):  # noqa: F811
    spec = _spec(tmp_path, 40, pause=1.0)  # 20 s on 2 workers: time for a dozen tabs
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli.main", "sweep", str(spec), "--out", str(tmp_path / "o"),
                             "--workers", "2", "--batch-size", "1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=dict(os.environ, PYTHONPATH=str(SRC)), start_new_session=True)
    first = proc.stderr.readline()
    link = re.search(r"dashboard: (http://\S+/status)", first)
    assert link, first
    browser.get("about:blank")
    home = browser.current_window_handle
    closed = 0
    for i in range(12):
        if proc.poll() is not None:
            break
        browser.switch_to.new_window("tab")
        browser.get(link.group(1))
        time.sleep(0.5 + (i % 3) * 0.7)  # closed while loading, just loaded, or after its first updates
        browser.close()
        browser.switch_to.window(home)
        closed += 1
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert closed >= 6, closed  # the tabs were opened and closed while the sweep ran
    lines = [line for line in err.splitlines() if not line.startswith("[")]  # the progress line's updates
    assert lines == [], lines
