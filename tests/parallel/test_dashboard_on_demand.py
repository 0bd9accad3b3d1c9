"""The dashboard of the local cluster cosim starts is built when a browser first opens it, not at every start.

A fresh interpreter (so no earlier test has imported the dashboard) starts cosim's local cluster the way a
sweep does (with cosim's points page registered), checks that the dashboard's code is not loaded, opens the
printed link over real HTTP and checks that it is served then (after one redirect) with the points page in its
navigation bar, as are the other dashboard pages and the web server's own routes.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from tests.helpers.paths import REPO

SCRIPT = """
import sys, urllib.error, urllib.request
from cosim.parallel.dashboard.points import open_board
from cosim.parallel.cluster.choice import choose_cluster
from cosim.parallel.cluster.client import dask_client

def status(url):
    try:
        with urllib.request.urlopen(url, timeout=60) as response:
            return response.status, response.geturl(), response.read().decode(errors="replace")
    except urllib.error.HTTPError as exc:
        return exc.code, url, ""

if __name__ == "__main__":
    with dask_client(choose_cluster(1)) as (client, _, link):
        root = link.rsplit("/", 1)[0]
        board = open_board(client, "sweep", "study", 10, dashboard=link)  # what a sweep registers
        print("loaded at start:", "distributed.dashboard.scheduler" in sys.modules)
        print("health:", status(root + "/health")[0])
        print("points page:", status(board.link)[0])
        code, url, body = status(link)
        print("link:", code, url == link, "bokeh" in body.lower(), 'href="cosim"' in body)
        print("loaded after:", "distributed.dashboard.scheduler" in sys.modules)
        print("progress page:", status(root + "/individual-progress")[0])
        print("unknown page:", status(root + "/no-such-page")[0])
"""


def test_the_dashboard_is_loaded_when_its_link_is_first_opened(tmp_path):
    pytest.importorskip("bokeh", reason="distributed serves its dashboard only with bokeh (an optional extra)")
    script = tmp_path / "dashboard_on_demand.py"
    script.write_text(SCRIPT)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=180,
                          env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [
        "loaded at start: False",
        "health: 200",
        "points page: 200",  # cosim's points page (dashboard.points) is served without the dashboard
        "link: 200 True True True",  # the same address, after the redirect, a bokeh page linking the points page
        "loaded after: True",
        "progress page: 200",
        "unknown page: 404",
    ], done.stdout + done.stderr
