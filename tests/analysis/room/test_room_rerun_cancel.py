"""A re-run in the decision room has a timeout and a Cancel (issue 38.6), driven in chromium.

A real sweep of two designs of a Python unit that runs at once, then a flag file beside it that makes its
``do_step`` sleep for an hour: the design's re-run hangs, as an FMU looping in doStep does.  Before, the re-run
ran in a thread of the server: the button stayed disabled and the core busy until the server ended, and nothing
could stop it.  Now it runs in a child process: past its timeout (COSIM_TIMEOUT_FLOOR, set to 4 s here) it is
stopped and the page says so; the Cancel button stops it at once; in both cases no child is left.
"""

from __future__ import annotations

import json
import multiprocessing
import time

import numpy as np
import pytest

from cosim.analysis.room import browser as B
from cosim.analysis.table import load_results

HANGS = """
import os, time
from cosim import PythonUnit, Variable

class HangsWhenFlagged(PythonUnit):
    variables = (Variable("k", "parameter", start=1.0), Variable("y", "output", start=0.0))

    def do_step(self, t, h):
        if os.path.exists(os.path.join(os.path.dirname(__file__), "hang")):
            time.sleep(3600)
        self.y = 2.0 * self.k
"""


@pytest.fixture
def hanging_study(tmp_path):
    import cosim

    (tmp_path / "hangs.py").write_text(HANGS)
    spec = {"name": "hangs", "units": {"u": {"python": "hangs.py:HangsWhenFlagged"}},
            "experiment": {"stop": 1.0, "step": 0.5},
            "objectives": {"y": {"signal": "u.y", "reduce": "final", "sense": "minimize"}},
            "design": {"parameters": {"u.k": {"values": [1.0, 2.0]}}}}
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    cosim.sweep(tmp_path / "spec.json", out=tmp_path / "out", workers=1, quiet=True)
    (tmp_path / "hang").write_text("")  # from now on a re-run hangs
    return tmp_path / "out"


def _status(driver) -> str:
    return driver.execute_script("return Bokeh.documents[0].get_model_by_name('rerun-status').text;")


def _disabled(driver, name: str) -> bool:
    return driver.execute_script(f"return Bokeh.documents[0].get_model_by_name('{name}').disabled;")


def _select_first(driver, folder) -> None:
    table = load_results(folder)
    x_name, y_name = driver.execute_script(
        "const d = Bokeh.documents[0]; return [d.get_model_by_name('choose-x').value, "
        "d.get_model_by_name('choose-y').value];")
    B.click_point(driver, table.values(x_name)[0], table.values(y_name)[0])
    B.wait_for(driver, "return Array.from(doc.get_model_by_name('show-selected').booleans).filter(Boolean).length"
                       " ? true : null;")  # the server has the selection
    B.show_tab(driver, 2)  # the Selection tab, built when first shown
    B.wait_for(driver, "const s = doc.get_model_by_name('selected'); return s && s.text.includes('" +
               str(table.df["point_id"].iloc[0]) + "') ? true : null;")


def _no_child_left(deadline: float = 10.0) -> bool:
    end = time.monotonic() + deadline
    while time.monotonic() < end:
        if not [p for p in multiprocessing.active_children() if p.name == "cosim-room-rerun"]:
            return True
        time.sleep(0.1)
    return False


def test_a_hanging_rerun_is_stopped_at_its_timeout_and_by_cancel(browser, hanging_study, monkeypatch):  # noqa: F811
    from cosim.analysis.room.data import Study
    from cosim.analysis.room.server import RoomServer

    monkeypatch.setenv("COSIM_TIMEOUT_FLOOR", "4")  # the re-run's timeout: max(floor, 10 x its run time)
    server = RoomServer(Study(load_results(hanging_study)))
    try:
        B.load(browser, server.link)
        _select_first(browser, hanging_study)  # a click on the cloud (the Points tab), then the Selection tab
        # the timeout: the page says when the re-run will be stopped, then that it was
        began = time.monotonic()
        B.click_widget(browser, "rerun")
        B.wait_for(browser, "return doc.get_model_by_name('rerun-status').text.includes('stopped after 4 s')"
                            " ? true : null;")
        assert _disabled(browser, "rerun") and not _disabled(browser, "rerun-cancel")
        B.wait_for(browser, "return doc.get_model_by_name('rerun-status').text.includes('no result within')"
                            " ? true : null;")
        took = time.monotonic() - began
        assert "re-run no result within 4 s" in _status(browser) and "it was stopped" in _status(browser)
        assert took >= 4.0
        assert not _disabled(browser, "rerun") and _disabled(browser, "rerun-cancel")
        assert _no_child_left()
        # Cancel: pressed while the re-run hangs, it ends it at once
        B.click_widget(browser, "rerun")
        B.wait_for(browser, "return doc.get_model_by_name('rerun-status').text.includes('stopped after')"
                            " ? true : null;")
        clicked = time.monotonic()
        B.click_widget(browser, "rerun-cancel")
        B.wait_for(browser, "return doc.get_model_by_name('rerun-status').text.includes('re-run cancelled')"
                            " ? true : null;")
        assert time.monotonic() - clicked < 4.0  # before the timeout would have
        assert not _disabled(browser, "rerun") and _disabled(browser, "rerun-cancel")
        assert _no_child_left()
        # and a re-run that can finish still draws its traces (the flag removed)
        (hanging_study.parent / "hang").unlink()
        B.click_widget(browser, "rerun")
        B.wait_for(browser, "return doc.get_model_by_name('rerun-status').text.includes(': ok in') ? true : null;")
        traces = browser.execute_script("const c = Bokeh.documents[0].get_model_by_name('traces');"
                                        "return c.children.map((f) => f.name);")
        assert traces and np.all([name.startswith("trace:") for name in traces])
    finally:
        server.stop()
