"""The decision room against a hostile results folder, and its token, in real chromium (issue 38, items 1-3).

A folder whose every string (the study's name, kind, objective, unit, parameter, design ids, statuses,
messages, the spec path a re-run reads) is an ``<img src=x onerror=...>`` that would record its name in
``window.__pwned`` is served by the room; the page is driven through every view that shows those strings
(count text, selects, tables, hover, titles, status, messages, the narrowed list, the selection, the re-run's
status) and the test checks that nothing ran and that no element of the page (shadow roots included) carries
an ``on...`` attribute: escaping is checked by itself, not only hidden behind the Content-Security-Policy,
which a second test checks by putting a live payload into the page itself.  Issue 39.2's sinks are driven
too: the ranking's and the shortlist's headers (parameters, objectives, units, design ids), a link whose
query names payloads, and the Study tab of a hostile optimisation (history, importances, slices, contour).

The token tests run ``cosim explore`` as the user does and open its printed link in chromium.
"""

from __future__ import annotations

import html
import json
import os
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pandas as pd
import pytest

from cosim.analysis.room import browser as B
from tests.helpers.tools import require_tool


def payload(sink: str) -> str:
    return f"<img src=x onerror=\"window.__pwned=(window.__pwned||[]).concat(['{sink}'])\">"


OBJECTIVE, PARAMETER = payload("objective"), payload("parameter")


@pytest.fixture(scope="module")
def browser():
    require_tool("chromium", "chromium")
    require_tool("chromedriver", "chromium-driver")
    try:
        import selenium  # noqa: F401
    except ImportError:
        if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
            pytest.fail("selenium is not installed (the test extra of pyproject.toml); CI=true, so this test "
                        "must run")
        pytest.skip("selenium is not installed (pip install -e .[test])")
    driver = B.chromium()
    driver.set_script_timeout(120)  # a page that never draws (the token link before issue 38) fails, not hangs
    yield driver
    driver.quit()


def hostile_folder(folder: Path) -> Path:
    """A results folder of 4 designs whose every string is a payload naming where it came from."""
    folder.mkdir(parents=True, exist_ok=True)
    spec = {"name": payload("study-name"), "units": {},
            "experiment": {"stop": 1.0, "step": 0.1},
            "objectives": {OBJECTIVE: {"signal": "u.y", "reduce": "final", "unit": payload("unit"),
                                       "sense": "minimize"}},
            "design": {"parameters": {PARAMETER: {"values": [1.0, 2.0, 3.0, 4.0]}}}}
    pd.DataFrame({"point_id": [payload(f"point-id-{k}") for k in range(4)],
                  PARAMETER: [1.0, 2.0, 3.0, 4.0], OBJECTIVE: [4.0, 3.0, 2.0, 1.0],
                  "status": ["ok", "ok", "failed", payload("status")],
                  "message": ["", "", payload("message"), payload("message-2")],
                  "run_time": 0.01, "worker": payload("worker")}).to_parquet(folder / "results.parquet", index=False)
    (folder / "metadata.json").write_text(json.dumps({
        "spec": spec, "kind": payload("kind"), "spec_path": str(folder / "missing" / payload("spec-path"))}))
    return folder


# every element of the page, shadow roots included, with an attribute of an event handler
HANDLERS = """
const out = [];
const walk = (root) => {
  for (const el of root.querySelectorAll('*')) {
    for (const a of el.attributes) if (a.name.toLowerCase().startsWith('on')) out.push(el.tagName + ' ' + a.name);
    if (el.shadowRoot) walk(el.shadowRoot);
  }
};
walk(document);
return out;
"""


def hover(driver, x: float, y: float) -> None:
    from selenium.webdriver.common.actions.action_builder import ActionBuilder

    sx, sy = B.on_screen(driver, x, y)
    actions = ActionBuilder(driver)
    actions.pointer_action.move_to_location(int(round(sx)), int(round(sy)))
    actions.perform()
    time.sleep(0.5)


def text_of(driver, name: str) -> str:
    return driver.execute_script(f"return Bokeh.documents[0].get_model_by_name('{name}').text;")


def test_every_string_of_a_hostile_folder_reaches_the_page_escaped(browser, tmp_path):
    from cosim.analysis.room.live import LiveStudy
    from cosim.analysis.room.server import RoomServer

    folder = hostile_folder(tmp_path / "hostile")
    server = RoomServer(LiveStudy(folder))  # watched: the live note lists the statuses too
    try:
        count, _ = B.load(browser, server.link)
        # the count text names the objective and the statuses, escaped: shown as text
        assert html.escape(OBJECTIVE) in count and html.escape(payload("status")) in count
        assert browser.title == "cosim: " + payload("study-name")
        # the cloud's hover over an ok design and over a crossed one (its id and status)
        hover(browser, 1.0, 4.0)
        hover(browser, 4.0, 1.0)
        # the parameter narrowed: the narrowed list names it
        B.set_filter(browser, PARAMETER, 1.0, 3.5)
        assert html.escape(PARAMETER) in text_of(browser, "narrowed")
        # every tab built: the ranking's titles and ids, weights, radar, summary, dimensions' selects
        for tab in (1, 2, 3, 4, 0):
            B.show_tab(browser, tab)
        # one objective with a sense: the radar has one spoke, and the Decide tab says how to get more
        assert "states one objective with a sense" in text_of(browser, "radar-note")
        # the parameter chosen under "maximise" too (the second way in), and a histogram of it
        browser.execute_script("const d = Bokeh.documents[0]; d.get_model_by_name('maximise').value = [arguments[0]];"
                               "d.get_model_by_name('choose-colour').value = arguments[0];", PARAMETER)
        B.wait_for(browser, "return doc.is_idle && doc.get_model_by_name('count').text.includes('max ');")
        # two designs selected: the selection's table (ids, values, status, message) and its export
        browser.execute_script("Bokeh.documents[0].get_model_by_name('cloud-source').selected.indices = [0, 1];")
        selected = B.wait_for(browser, "const t = doc.get_model_by_name('selected').text; "
                                       "return doc.is_idle && t.includes('design(s) selected') ? t : null;")
        assert html.escape(payload("point-id-0"), quote=False) in selected
        # the ranking's headers name the parameter and the objective with its unit; the two designs pinned: the
        # shortlist's headers are their ids, its rows the names with units (issue 39.2)
        titles = browser.execute_script("return Bokeh.documents[0].get_model_by_name('ranking').columns"
                                        ".map((c) => c.title);")
        assert titles[3:] == [html.escape(PARAMETER), html.escape(f"{OBJECTIVE} [{payload('unit')}] (min)"),
                              html.escape(f"{PARAMETER} (max)")]  # the parameter maximised above
        B.show_tab(browser, 1)
        B.click_widget(browser, "pin")
        pinned = B.wait_for(browser, "const t = doc.get_model_by_name('shortlist'); return doc.is_idle && "
                                     "t.columns.length === 4 && 'd1' in t.source.data ? [t.columns.map((c) => c.title), "
                                     "Array.from(t.source.data.quantity)] : null;")
        assert pinned == [["", "", html.escape(payload("point-id-0")), html.escape(payload("point-id-1"))],
                          [PARAMETER, f"{OBJECTIVE} [{payload('unit')}]", PARAMETER]]  # cells: text
        # a re-run, which fails on the spec path the folder names: its status quotes it
        B.show_tab(browser, 2)
        B.click_widget(browser, "rerun")
        status = B.wait_for(browser, "const t = doc.get_model_by_name('rerun-status').text; "
                                     "return t.includes('re-run failed') ? t : null;")
        assert "&lt;img" in status and "<img" not in status
        # the failures table (messages, statuses) and everything else: nothing ran, no handler in the page
        B.show_tab(browser, 0)
        time.sleep(1.0)  # an <img src=x> fails to load within milliseconds: its handler would have run by now
        assert browser.execute_script("return window.__pwned ?? null;") is None
        assert browser.execute_script(HANDLERS) == []
        assert B.console_errors(browser) == []
    finally:
        server.stop()


def test_a_hostile_optimisation_reaches_its_study_tab_escaped(browser, tmp_path):
    """The Study tab of an optimisation (issue 39.2): history, importances, slices and contour name the
    objective, its unit and the parameters in titles, axis labels, factors, tooltips and a Select; none runs."""
    from selenium.webdriver.common.actions.action_builder import ActionBuilder

    from cosim.analysis.room.data import Study
    from cosim.analysis.room.server import RoomServer
    from cosim.analysis.table import load_results

    folder = tmp_path / "hostile-optimisation"
    folder.mkdir()
    other = payload("parameter-2")
    spec = {"name": payload("study-name"), "units": {}, "experiment": {"stop": 1.0, "step": 0.1},
            "objectives": {OBJECTIVE: {"signal": "u.y", "reduce": "final", "unit": payload("unit"),
                                       "sense": "minimize"}},
            "design": {"parameters": {PARAMETER: {"min": 0.0, "max": 1.0, "unit": payload("parameter-unit")},
                                      other: {"min": 0.0, "max": 1.0}}}}
    x = [0.1, 0.9, 0.5, 0.3, 0.7, 0.2, 0.8, 0.6]
    y = [0.2, 0.8, 0.1, 0.9, 0.4, 0.6, 0.3, 0.7]
    pd.DataFrame({"point_id": [payload(f"point-id-{k}") for k in range(8)], PARAMETER: x, other: y,
                  OBJECTIVE: [a * a + b for a, b in zip(x, y)], "trial": range(8), "batch": [0] * 4 + [1] * 4,
                  "sampler": payload("sampler"), "feasible": True, "status": "ok", "message": "",
                  "run_time": 0.01}).to_parquet(folder / "results.parquet", index=False)
    (folder / "metadata.json").write_text(json.dumps({
        "spec": spec, "kind": "optimization", "optimize": {"objectives": {OBJECTIVE: "minimize"}}}))
    server = RoomServer(Study(load_results(folder)))
    try:
        B.load(browser, server.link)
        B.show_tab(browser, 3)
        B.wait_for(browser, "return doc.is_idle && doc.get_model_by_name('contour') !== null;")
        assert browser.execute_script("return Bokeh.documents[0].get_model_by_name('importances-source')"
                                      ".data.parameter.length;") == 2
        # hover over the importance bars and the history's points: their tooltips name parameters and values
        for name in ("importances", "history", "contour"):
            where = browser.execute_script(B.WIDGET_ON_SCREEN, name)
            hover_at = ActionBuilder(browser)
            hover_at.pointer_action.move_to_location(int(where[0]), int(where[1]))
            hover_at.perform()
            time.sleep(0.3)
        time.sleep(1.0)
        assert browser.execute_script("return window.__pwned ?? null;") is None
        assert browser.execute_script(HANDLERS) == []
        assert B.console_errors(browser) == []
    finally:
        server.stop()


def test_a_hostile_link_is_shown_as_text(browser, tmp_path):
    """A link typed (or sent) with payloads for the view's columns and designs (issue 39.2: the view lives in
    the link): the page names what it left out, escaped, and nothing runs; a payload that is the table's own
    column or design is taken, and shown escaped."""
    from urllib.parse import urlencode

    from cosim.analysis.room.data import Study
    from cosim.analysis.room.server import RoomServer
    from cosim.analysis.table import load_results

    server = RoomServer(Study(load_results(hostile_folder(tmp_path / "hostile"))))
    try:
        query = urlencode([("x", payload("link-x")), ("f", payload("link-filter") + "~1~2"), ("tab", "1"),
                           ("pin", payload("link-pin")), ("pin", payload("point-id-1")), ("colour", PARAMETER),
                           ("rank", payload("link-rank"))])
        B.load(browser, server.link + "&" + query)
        note = text_of(browser, "view-link")
        for sink in ("link-x", "link-filter", "link-pin", "link-rank"):
            assert html.escape(payload(sink)) in note
        pinned = B.wait_for(browser, "const t = doc.get_model_by_name('shortlist'); return doc.is_idle && "
                                     "t.columns.length === 3 ? t.columns.map((c) => c.title) : null;")
        assert pinned == ["", "", html.escape(payload("point-id-1"))]
        assert browser.execute_script("return Bokeh.documents[0].get_model_by_name('choose-colour').value;") \
            == PARAMETER
        time.sleep(1.0)
        assert browser.execute_script("return window.__pwned ?? null;") is None
        assert browser.execute_script(HANDLERS) == []
        assert B.console_errors(browser) == []
    finally:
        server.stop()


def test_the_page_runs_no_inline_script_it_did_not_write(browser, tmp_path):
    """The second wall: a payload put into the page unescaped (here by the test itself) still does not run."""
    from cosim.analysis.room.data import Study
    from cosim.analysis.room.server import RoomServer
    from cosim.analysis.table import load_results

    server = RoomServer(Study(load_results(hostile_folder(tmp_path / "hostile"))))
    try:
        page = urllib.request.urlopen(server.link, timeout=60)
        policy = page.headers["Content-Security-Policy"]
        assert "script-src 'self' 'unsafe-eval' 'sha256-" in policy and "unsafe-inline" not in policy
        assert "object-src 'none'" in policy and "base-uri 'none'" in policy
        B.load(browser, server.link)  # bokeh's own inline scripts ran: the page is drawn
        browser.execute_script("Bokeh.documents[0].get_model_by_name('count').text = arguments[0];",
                               payload("unescaped"))
        B.wait_for(browser, "const r = (n) => { for (const e of n.querySelectorAll('*')) { "
                            "if (e.tagName === 'IMG' && e.getAttribute('src') === 'x') return true; "
                            "if (e.shadowRoot && r(e.shadowRoot)) return true; } return false; }; return r(document);")
        time.sleep(1.0)
        assert browser.execute_script("return window.__pwned ?? null;") is None
        refused = B.console_errors(browser)
        assert any("Content Security Policy" in line for line in refused), refused
    finally:
        server.stop()


# -- the token ------------------------------------------------------------------------------------------------


def explore(folder: Path, *extra: str) -> tuple[subprocess.Popen, list[str]]:
    """``cosim explore FOLDER EXTRA...`` started; (the process, its first stdout lines once the link is out)."""
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli.main", "explore", str(folder), *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    lines = [proc.stdout.readline()]
    if "--no-token" in extra:
        lines.append(proc.stdout.readline())
    assert " is at http://" in lines[0], (lines, proc.stderr.read() if proc.poll() is not None else "")
    return proc, lines


def stop(proc: subprocess.Popen) -> str:
    os.killpg(proc.pid, signal.SIGINT)
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    err = proc.stderr.read()
    assert proc.returncode == 130, err
    return err


def test_the_token_link_of_a_room_on_every_address_opens_in_chromium(browser, tmp_path):
    folder = hostile_folder(tmp_path / "f")
    proc, (line,) = explore(folder, "--host", "0.0.0.0")
    try:
        link = line.split(" is at ")[1].split()[0]
        assert "?token=" in link
        port = int(link.split(":")[2].split("/")[0])
        B.load(browser, link)  # drawn: the page's websocket carried the cookie its page set
        assert browser.execute_script("return Bokeh.documents[0].get_model_by_name('count').text;")
        # the same room without the token, from a browser that never had it: refused, one line each at most
        for _ in range(3):
            with pytest.raises(urllib.error.HTTPError) as refused:
                urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=60)
            assert refused.value.code == 403
            with pytest.raises(urllib.error.HTTPError) as refused:
                urllib.request.urlopen(urllib.request.Request(
                    f"http://127.0.0.1:{port}/ws", headers={"Connection": "Upgrade", "Upgrade": "websocket",
                                                          "Sec-WebSocket-Version": "13",
                                                          "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ=="}),
                    timeout=60)
            assert refused.value.code == 403
    finally:
        err = stop(proc)
    assert "Traceback" not in err, err
    assert len(err.strip().splitlines()) <= 1 + 6, err  # 'cosim: interrupted' and one line per refusal at most
    assert "Host wildcard" not in err


def test_loopback_has_a_token_by_default_and_no_token_warns(browser, tmp_path):
    folder = hostile_folder(tmp_path / "f")
    proc, (line,) = explore(folder)
    try:
        link = line.split(" is at ")[1].split()[0]
        assert link.startswith("http://127.0.0.1:") and "?token=" in link
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(link.split("?")[0], timeout=60)
        assert refused.value.code == 403
        B.load(browser, link)
    finally:
        stop(proc)
    proc, (line, warning) = explore(folder, "--no-token")
    try:
        link = line.split(" is at ")[1].split()[0]
        assert "token" not in link
        assert "warning: --no-token: every user of this machine can read this study" in warning
        assert urllib.request.urlopen(link, timeout=60).status == 200
    finally:
        stop(proc)


def test_the_surrogate_tab_of_a_hostile_folder_shows_every_string_escaped(browser, tmp_path):
    """Surrogates fitted on a folder whose objective, parameters and ids are payloads: the Surrogate tab's
    choosers, Q² text, held design, picked design and a failed "simulate here" (the spec path is missing)."""
    from cosim.analysis.room.data import Study
    from cosim.analysis.room.server import RoomServer
    from cosim.analysis.surrogate import fit_table, surrogate_folder, write
    from cosim.analysis.table import load_results

    folder = tmp_path / "hostile"
    folder.mkdir()
    second = payload("parameter-2")
    spec = {"name": payload("study-name"), "units": {}, "experiment": {"stop": 1.0, "step": 0.1},
            "objectives": {OBJECTIVE: {"signal": "u.y", "reduce": "final", "sense": "minimize"}},
            "design": {"parameters": {PARAMETER: {"min": 0.0, "max": 1.0}, second: {"min": 0.0, "max": 1.0}}}}
    x = [i / 9 for i in range(10)]
    pd.DataFrame({"point_id": [payload(f"point-id-{k}") for k in range(10)], PARAMETER: x,
                  second: [(3 * v) % 1 for v in x], OBJECTIVE: [v * v for v in x], "status": "ok", "message": "",
                  "run_time": 0.01, "worker": payload("worker")}).to_parquet(folder / "results.parquet", index=False)
    (folder / "metadata.json").write_text(json.dumps({
        "spec": spec, "kind": "sweep", "spec_path": str(folder / "missing" / payload("spec-path"))}))
    write(fit_table(load_results(folder), method="poly"), surrogate_folder(folder))
    server = RoomServer(Study(load_results(folder)))
    try:
        B.load(browser, server.link)
        B.console_errors(browser)  # the previous test's page, whose server stopped, trying to reconnect
        titles = browser.execute_script("return Bokeh.documents[0].get_model_by_name('tabs').tabs.map((t) => t.title);")
        B.show_tab(browser, titles.index("Surrogate"))
        quality = B.wait_for(browser, "const m = doc.get_model_by_name('surrogate-quality'); "
                                      "return m && m.text ? m.text : null;")
        assert html.escape(OBJECTIVE) in quality and "<img" not in quality
        assert html.escape(payload("point-id-0")) in text_of(browser, "surrogate-held")
        B.click_point(browser, 0.5, 0.5, figure="surrogate-map")
        picked = B.wait_for(browser, "const t = doc.get_model_by_name('surrogate-pick-text').text; "
                                     "return t.includes('Picked design') ? t : null;")
        assert html.escape(PARAMETER) in picked and "<img" not in picked
        B.click_widget(browser, "simulate-here")
        status = B.wait_for(browser, "const t = doc.get_model_by_name('simulate-status').text; "
                                     "return t.includes('failed') ? t : null;")
        assert "&lt;img" in status and "<img" not in status
        time.sleep(1.0)
        assert browser.execute_script("return window.__pwned ?? null;") is None
        assert browser.execute_script(HANDLERS) == []
        assert B.console_errors(browser) == []
    finally:
        server.stop()
