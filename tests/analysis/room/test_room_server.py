"""`cosim explore DIR`: the decision room served on loopback, its printed link, and its usage errors."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import urllib.request

from cosim.analysis.room.server import is_loopback
from tests.analysis.test_analysis_explorer import linear_ode_sweep


def test_explore_serves_the_room_on_loopback_and_prints_its_link(tmp_path, write_spec):
    folder = linear_ode_sweep(tmp_path / "decay", write_spec).parent
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli.main", "explore", str(folder)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        line = proc.stdout.readline()
        assert "the decision room of decay is at http://127.0.0.1:" in line, (line, proc.stderr.read()
                                                                               if proc.poll() is not None else "")
        link = line.split(" is at ")[1].split()[0]
        assert "?token=" in link  # on loopback too (issue 38.3)
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

