"""Issue 28.15: closing a dashboard tab while a study runs prints nothing on the study's terminal, and the end of
a study says that the dashboard link printed at its start is gone with the cluster.

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

import pytest

from cosim.parallel.dashboard.web_server import tab_closed_while_loading, web_server_tracebacks_as_lines
from tests.helpers.paths import REPO
from tests.helpers.triple_study import triple_spec

SRC = REPO / "src"


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
    spec = triple_spec(tmp_path, 60, pause=1.0)  # 30 s on 2 workers: time for a dozen tabs
    # ... and once the tabs are done, the rest of the points without their pause (the sweep went on sleeping
    # for up to 30 s after the last tab): each point pauses only while the file `tabs_open` exists
    tabs_open = tmp_path / "tabs_open"
    tabs_open.touch()
    unit = (tmp_path / "triple.py").read_text()
    assert "        time.sleep(self.pause)\n" in unit
    (tmp_path / "triple.py").write_text(unit.replace(
        "        time.sleep(self.pause)\n",
        f"        if __import__('os').path.exists({str(tabs_open)!r}):\n            time.sleep(self.pause)\n"))
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
        try:
            browser.get(link.group(1))
        except Exception:  # noqa: BLE001 - selenium's WebDriverException: refused once the sweep has ended
            browser.close()
            browser.switch_to.window(home)
            assert proc.wait(timeout=60) is not None
            break
        time.sleep(0.5 + (i % 3) * 0.7)  # closed while loading, just loaded, or after its first updates
        browser.close()
        browser.switch_to.window(home)
        closed += 1
    tabs_open.unlink()
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert closed >= 6, closed  # the tabs were opened and closed while the sweep ran
    lines = [line for line in err.splitlines() if not line.startswith("[")]  # the progress line's updates
    assert lines == [f"cosim: the dashboard closed with the cluster this study started; the results: cosim explore "
                     f"{tmp_path / 'o'} (or cosim report {tmp_path / 'o'})"], lines


def _sweep(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cosim.cli.main", "sweep", *args], capture_output=True, text=True,
                          timeout=300, env=dict(os.environ, PYTHONPATH=str(SRC)))


def test_the_end_of_a_study_says_its_dashboard_is_gone_and_where_the_results_are(tmp_path, local_cluster):
    """The link printed at the start of a study of a few seconds was dead before it could be clicked, and
    nothing said why (issue 28.15): the cluster cosim started for the study, and its dashboard, end with it."""
    import urllib.error
    import urllib.request

    spec = triple_spec(tmp_path, 4)
    done = _sweep(str(spec), "--out", str(tmp_path / "o"), "--workers", "1")
    assert done.returncode == 0, done.stderr
    link = re.search(r"dashboard: (http://\S+/status)", done.stderr).group(1)
    last = done.stderr.strip().splitlines()[-1]
    assert last == (f"cosim: the dashboard closed with the cluster this study started; the results: cosim explore "
                    f"{tmp_path / 'o'} (or cosim report {tmp_path / 'o'})"), done.stderr
    with pytest.raises(urllib.error.URLError):  # what the line says: nothing answers there any more
        urllib.request.urlopen(link, timeout=10)
    # nothing to say when no cluster was started (every point already in the folder) ...
    again = _sweep(str(spec), "--out", str(tmp_path / "o"), "--workers", "1", "--resume")
    assert again.returncode == 0 and "dashboard" not in again.stderr, again.stderr
    # ... on a running scheduler, whose dashboard stays, or under -q
    elsewhere = _sweep(str(spec), "--out", str(tmp_path / "p"), "--scheduler", local_cluster)
    assert elsewhere.returncode == 0 and "closed with the cluster" not in elsewhere.stderr, elsewhere.stderr
    quiet = _sweep(str(spec), "--out", str(tmp_path / "q"), "--workers", "1", "-q")
    assert quiet.returncode == 0 and quiet.stderr == "", quiet.stderr
