"""`cosim explore DIR`: the decision room served on loopback, its printed link, and its usage errors."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import urllib.request

from cosim.analysis.room.server import is_loopback

from .test_analysis_explorer import linear_ode_sweep


def test_explore_serves_the_room_on_loopback_and_prints_its_link(tmp_path, write_spec):
    folder = linear_ode_sweep(tmp_path / "decay", write_spec).parent
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli.main", "explore", str(folder)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        line = proc.stdout.readline()
        assert "the decision room of decay is at http://127.0.0.1:" in line, (line, proc.stderr.read()
                                                                               if proc.poll() is not None else "")
        link = line.split(" is at ")[1].split()[0]
        assert "token" not in link
        page = urllib.request.urlopen(link, timeout=60).read().decode()
        assert "<title>cosim: decay</title>" in page
        # bokeh's bundles but MathJax's (1.8 MB of JavaScript for TeX the room never typesets)
        scripts = [name for name in ("bokeh.min.js", "bokeh-gl.min.js", "bokeh-widgets.min.js", "bokeh-tables.min.js",
                                     "bokeh-mathjax.min.js") if f"/static/js/{name}?" in page]
        assert scripts == ["bokeh.min.js", "bokeh-gl.min.js", "bokeh-widgets.min.js", "bokeh-tables.min.js"]
    finally:
        os.killpg(proc.pid, signal.SIGINT)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    err = proc.stderr.read()
    assert proc.returncode == 130, err  # stopped as every command is (issue 28.6): interrupted
    assert err.strip().splitlines()[-1] == "cosim: interrupted" and "Traceback" not in err, err


def test_explore_mistakes_are_one_line_and_exit_2(tmp_path, write_spec):
    folder = linear_ode_sweep(tmp_path / "decay", write_spec).parent
    for extra, message in ((["--port", "70000"], "between 1 and 65535"),
                           (["--host", "192.0.2.1"], "cannot serve at 192.0.2.1")):
        done = subprocess.run([sys.executable, "-m", "cosim.cli.main", "explore", str(folder), *extra],
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 2 and message in done.stderr and "Traceback" not in done.stderr, done.stderr
    done = subprocess.run([sys.executable, "-m", "cosim.cli.main", "explore", str(tmp_path / "nothing")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "no such results table" in done.stderr


def test_loopback_addresses():
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("10.1.2.3") and not is_loopback("login1")



def _wait(condition, timeout: float = 30.0) -> None:
    import time

    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "not within the time"
        time.sleep(0.05)


def test_a_page_gets_the_room_built_before_it_asked_and_a_folder_with_new_rows_gets_them(tmp_path, write_spec):
    """The room's models are built when the server starts and again after a page took them (RoomsAhead), so a
    page's address is answered without building them; a page of a watched folder whose rows changed meanwhile
    gets a room of the new rows instead."""
    import time

    import pandas as pd

    from cosim.analysis.room import app
    from cosim.analysis.room.live import LiveStudy
    from cosim.analysis.room.server import RoomServer

    table = linear_ode_sweep(tmp_path / "decay", write_spec)
    server = RoomServer(LiveStudy(table.parent, every=0.2))
    try:
        ahead = server.server.rooms_ahead
        _wait(lambda: ahead.spare is not None)  # built at the start, before any page
        built = ahead.spare
        assert built.doc is None and len(built.study.ids) == 3
        page = urllib.request.urlopen(server.link, timeout=60).read().decode()
        assert "<title>cosim: decay</title>" in page
        assert built.doc is not None and built.doc.roots == [built.tabs]  # the page's document shows it
        assert ahead.spare is None
        _wait(lambda: ahead.spare is not None, timeout=app.AHEAD_AFTER + 30)  # the next page's, a while after
        stale = ahead.spare
        assert stale is not built and stale.doc is None

        rows = pd.read_parquet(table)  # the study writes a fourth row
        more = pd.concat([rows, rows.iloc[[0]].assign(point_id="pd", **{"ode.a": -4.0})], ignore_index=True)
        more.to_parquet(table, index=False)
        time.sleep(0.5)  # longer than the folder's `every`: the next look reads the table again
        urllib.request.urlopen(server.link, timeout=60).read()
        assert stale.doc is None  # not given to the page: it shows three rows
        _wait(lambda: ahead.spare is not None, timeout=app.AHEAD_AFTER + 30)
        assert len(ahead.spare.study.ids) == 4
    finally:
        server.stop()
