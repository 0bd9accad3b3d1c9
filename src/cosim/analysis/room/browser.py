"""Driving the decision room in a real browser: Debian's chromium through selenium and chromium-driver.

Used by the browser tests (tests/analysis/room/test_room_browser.py), the load benchmark (benchmarks/room_load.py) and the
screenshots of docs/decision-room.md (docs/decision_room_screenshots.py).  The page is read and changed
through its Bokeh document (``Bokeh.documents[0]``, models found by the names :mod:`.views` gives them);
clicks are real mouse clicks at the viewport position of a point or widget.  selenium is imported when a
browser is started.
"""

from __future__ import annotations

import json
import shutil
import time
from typing import Any

# resolves with the 'count' text once the document is idle and the server's first refresh arrived
WAIT_LOADED = """
const done = arguments[arguments.length - 1];
(function check() {
  const B = window.Bokeh, doc = B && B.documents && B.documents[0];
  const count = doc && doc.get_model_by_name('count');
  if (doc && doc.is_idle && count && count.text) requestAnimationFrame(() => done(count.text));
  else setTimeout(check, 20);
})();
"""

# sets a model's property; resolves, once the document is idle again and two frames drawn, with the new value
# of the JS expression `watch` (a function body of `doc`), when it changed to something other than null
SET_AND_WAIT = """
const [name, attr, value, watch, done] = arguments;
const doc = Bokeh.documents[0];
const look = () => new Function('doc', watch)(doc);
const before = look();
const start = performance.now();
doc.get_model_by_name(name)[attr] = value;
(function check() {
  const now = look();
  if (now !== before && now !== null && doc.is_idle) requestAnimationFrame(() => requestAnimationFrame(() => done(now)));
  else if (performance.now() - start > 100000) done('no change within 100 s');
  else setTimeout(check, 5);
})();
"""

# resolves with the value of the JS expression (a function body of `doc`) once it is neither null nor false
WAIT_FOR = """
const [js, done] = arguments;
const f = new Function('doc', js);
(function check() {
  const value = f(Bokeh.documents[0]);
  if (value !== null && value !== undefined && value !== false) requestAnimationFrame(() => done(value));
  else setTimeout(check, 50);
})();
"""

COUNT_TEXT = "return doc.get_model_by_name('count').text;"
# a JS function of the document: the cloud's design ids in row order (the hover's text of them, views.hover_ids)
CLOUD_IDS = ("(doc) => { const a = doc.get_model_by_name('cloud-ids').args; "
             "const ids = a instanceof Map ? a.get('ids') : a.ids; return ids === '' ? [] : ids.split('\\n'); }")
RANKING_SCORES = "const s = doc.get_model_by_name('ranking').source.data.score; return s.length ? s.join() : null;"
RANKING_IDS = "const ids = doc.get_model_by_name('ranking').source.data.point_id; return ids.length ? ids.join() : null;"

# the viewport position of data point (x, y) of a figure (by name), scrolled into view when outside it
POINT_ON_SCREEN = """
const [x, y, name] = arguments;
const view = Bokeh.index.find_one(Bokeh.documents[0].get_model_by_name(name));
let rect = view.canvas_view.el.getBoundingClientRect();
if (rect.top < 0 || rect.bottom > window.innerHeight) {  // scrolled into the viewport first
  view.canvas_view.el.scrollIntoView({block: 'center'});
  rect = view.canvas_view.el.getBoundingClientRect();
}
return [rect.left + view.frame.x_scale.compute(x), rect.top + view.frame.y_scale.compute(y)];
"""

# the viewport position of a widget's centre, scrolled into view when outside it
WIDGET_ON_SCREEN = """
const view = Bokeh.index.find_one(Bokeh.documents[0].get_model_by_name(arguments[0]));
let rect = view.el.getBoundingClientRect();
if (rect.top < 0 || rect.bottom > window.innerHeight) {
  view.el.scrollIntoView({block: 'center'});
  rect = view.el.getBoundingClientRect();
}
return [rect.left + rect.width / 2, rect.top + rect.height / 2];
"""


def chromium(width: int = 1400, height: int = 1000) -> Any:
    """A headless Debian chromium under selenium (chromium and chromedriver from PATH).

    Raises RuntimeError naming the Debian package when one of them is missing, ImportError without selenium.
    """
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    binary, driver = shutil.which("chromium"), shutil.which("chromedriver")
    if binary is None or driver is None:
        raise RuntimeError("the decision room's browser needs Debian's chromium and chromium-driver packages")
    options = webdriver.ChromeOptions()
    options.binary_location = binary
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})  # the page's console, for console_errors
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", f"--window-size={width},{height}",
                "--disable-dev-shm-usage"):
        options.add_argument(arg)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})  # the console, for browser.get_log("browser")
    browser = webdriver.Chrome(service=Service(driver), options=options)
    browser.set_script_timeout(600)
    browser.set_page_load_timeout(600)
    return browser


def console_errors(browser: Any) -> list[str]:
    """The page's errors in chromium's console since the last call (each read empties the log): uncaught
    exceptions of bokeh's scripts, ``console.error`` and failed requests, as chromium words them (level SEVERE)."""
    return [entry["message"] for entry in browser.get_log("browser") if entry["level"] == "SEVERE"]


def load(browser: Any, link: str) -> tuple[str, float]:
    """Open the room at ``link``; (its count text, seconds from the request until the page is drawn)."""
    start = time.perf_counter()
    browser.get(link)
    text = browser.execute_async_script(WAIT_LOADED)
    return text, time.perf_counter() - start


def set_and_wait(browser: Any, name: str, attr: str, value: Any, watch: str) -> tuple[Any, float]:
    """Set ``name.attr = value`` in the page; (the new value of ``watch``, seconds until it came and was drawn).

    Raises RuntimeError when ``watch`` did not change within 100 s."""
    start = time.perf_counter()
    now = browser.execute_async_script(SET_AND_WAIT, name, attr, value, watch)
    if now == "no change within 100 s":
        raise RuntimeError(f"setting {name}.{attr} = {value!r}: {watch} did not change within 100 s")
    return now, time.perf_counter() - start


def set_filter(browser: Any, column: str, lo: float, hi: float, watch: str = COUNT_TEXT) -> tuple[Any, float]:
    """Narrow ``column`` to [lo, hi] with the page's range filter: choose the column (the server sets the slider
    to it), then set the range; (the new value of ``watch``, seconds from setting the range until drawn)."""
    browser.execute_script("Bokeh.documents[0].get_model_by_name('filter-column').value = arguments[0];", column)
    wait_for(browser, "const f = doc.get_model_by_name('filter'); "
                      f"return doc.is_idle && f.tags[0] === {json.dumps(column)};")
    return set_and_wait(browser, "filter", "value", [float(lo), float(hi)], watch)


def wait_for(browser: Any, js: str) -> Any:
    return browser.execute_async_script(WAIT_FOR, js)


def click_at(browser: Any, x: float, y: float) -> None:
    """A real mouse click at viewport position (x, y)."""
    from selenium.webdriver.common.actions.action_builder import ActionBuilder

    actions = ActionBuilder(browser)
    actions.pointer_action.move_to_location(int(round(x)), int(round(y)))
    actions.pointer_action.click()
    actions.perform()


def on_screen(browser: Any, x: float, y: float, figure: str = "cloud") -> tuple[float, float]:
    """The viewport position of data point (x, y) of ``figure``."""
    return tuple(browser.execute_script(POINT_ON_SCREEN, float(x), float(y), figure))


def click_point(browser: Any, x: float, y: float, figure: str = "cloud") -> None:
    """Click data point (x, y) of the cloud (or another figure)."""
    click_at(browser, *on_screen(browser, x, y, figure))


def drag(browser: Any, start: tuple[float, float], end: tuple[float, float], figure: str) -> None:
    """A real mouse drag in ``figure`` from data point ``start`` to ``end`` (in steps, as a hand moves)."""
    from selenium.webdriver.common.actions.action_builder import ActionBuilder

    (x0, y0), (x1, y1) = on_screen(browser, *start, figure), on_screen(browser, *end, figure)
    actions = ActionBuilder(browser)
    actions.pointer_action.move_to_location(int(round(x0)), int(round(y0)))
    actions.pointer_action.pointer_down()
    for k in range(1, 11):
        actions.pointer_action.move_to_location(int(round(x0 + (x1 - x0) * k / 10)),
                                                int(round(y0 + (y1 - y0) * k / 10)))
    actions.pointer_action.pointer_up()
    actions.perform()


def click_widget(browser: Any, name: str) -> None:
    click_at(browser, *browser.execute_script(WIDGET_ON_SCREEN, name))


def show_tab(browser: Any, index: int) -> None:
    """Switch to tab ``index`` (0 Points, 1 Decide, 2 Selection, 3 Study, 4 Dimensions) and wait until it is built (the
    server builds a tab the first time it is shown) and drawn."""
    browser.execute_script(f"Bokeh.documents[0].get_model_by_name('tabs').active = {index};")
    wait_for(browser, f"const c = doc.get_model_by_name('tabs').tabs[{index}].child; "
                      "return doc.is_idle && (c.children === undefined || c.children.length > 0);")


def count_true(browser: Any, name: str) -> int:
    """How many rows the BooleanFilter ``name`` keeps (``show-ok``, ``show-greyed``, ``show-front``, ...)."""
    return browser.execute_script(f"return Array.from(Bokeh.documents[0].get_model_by_name('{name}').booleans)"
                                  ".filter(Boolean).length;")


def binned_image(browser: Any) -> dict[str, Any]:
    """The binned cloud's image (a large table's): x, y (its lower left corner), dw, dh and ``image``, a list of
    rows of RGBA uint32 pixels, bottom row first."""
    got = browser.execute_script("""
        const d = Bokeh.documents[0].get_model_by_name('cloud-image').data;
        const img = d.image[0];
        return {x: d.x[0], y: d.y[0], dw: d.dw[0], dh: d.dh[0], shape: Array.from(img.shape),
                pixels: Array.from(img)};""")
    height, width = got["shape"]
    got["image"] = [got["pixels"][r * width:(r + 1) * width] for r in range(height)]
    del got["pixels"]
    return got


def ranking_ids(browser: Any) -> list[str]:
    return browser.execute_script("return Array.from(Bokeh.documents[0].get_model_by_name('ranking')"
                                  ".source.data.point_id);")


# `live(name)`: the one model of that name in the page's tree.  Bokeh's page forgets a model the server removed
# only some 30 s later (BokehJS recomputes its models on a timer after a partial update), so for a while
# get_model_by_name finds a redrawn figure twice; this looks only at what the roots reference.
LIVE_JS = """
const live = (name) => {
  const hits = [];
  // bokeh 3.4's document has roots(), later ones all_roots
  const doc = Bokeh.documents[0];
  for (const root of doc.all_roots ?? doc.roots()) for (const m of root.references()) if (m.name === name) hits.push(m);
  if (hits.length !== 1) throw new Error(`${hits.length} models named ${name} in the page`);
  return hits[0];
};
"""

# the viewport position of the save button of a figure's toolbar (by the figure's name)
SAVE_BUTTON_ON_SCREEN = LIVE_JS + """
const fig = live(arguments[0]);
const toolbar = Bokeh.index.find_one(fig.toolbar);
for (const button of toolbar._tool_button_views.values()) {
  if (button.model.tool.type === 'SaveTool') {
    button.el.scrollIntoView({block: 'center'});
    const rect = button.el.getBoundingClientRect();
    return rect.width > 0 ? [rect.left + rect.width / 2, rect.top + rect.height / 2] : 'hidden';
  }
}
return null;
"""


def save_figure(browser: Any, name: str, downloads: Any, timeout: float = 60.0) -> Any:
    """Click the save button of figure ``name`` and return the Path of the file it wrote into ``downloads`` (the
    folder given to chromium with ``Browser.setDownloadBehavior``; the figure's save tool names the file).

    Raises RuntimeError when the figure has no save button or no new file is complete within ``timeout``."""
    from pathlib import Path

    folder = Path(downloads)
    before = set(folder.iterdir())
    where = browser.execute_script(SAVE_BUTTON_ON_SCREEN, name)
    if where is None or where == "hidden":
        raise RuntimeError(f"the figure '{name}' has no save button" if where is None else
                           f"the save button of figure '{name}' is hidden (in its toolbar's overflow menu)")
    click_at(browser, *where)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        new = [p for p in set(folder.iterdir()) - before if not p.name.endswith(".crdownload")]
        if new and new[0].stat().st_size > 0:
            return new[0]
        time.sleep(0.05)
    raise RuntimeError(f"saving '{name}' wrote no file into {folder} within {timeout:.0f} s")
