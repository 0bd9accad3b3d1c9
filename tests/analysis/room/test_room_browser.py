"""The decision room (`cosim explore`) in a real browser: Debian's chromium driven by selenium (chromium-driver).

Three small folders are made here by real studies of the test units (a sweep with failing points, an
optimisation, a Sobol sensitivity analysis), each served by the room; in each the test checks that the page
loads, that a range filter narrows the points, that a click on the cloud selects the design under the
pointer, that a re-run draws the design's traces, and that the ranking reorders when a weight changes: each
against values computed here from the table (and, for traces, from the closed-form solution).  Under CI=true
a missing chromium, chromium-driver or selenium fails the tests instead of skipping them.

Screenshots of each view go to ``$COSIM_SCREENSHOTS`` when it is set.
"""

from __future__ import annotations

import json
import os
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cosim.analysis.room import browser as B
from cosim.analysis.room.server import cookie_name
from cosim.analysis.table import load_results
from tests.helpers.tools import python_unit

# the browser (fixture `browser`) and the check of its console (`no_console_errors`) are in tests/conftest.py,
# the room servers (`room`) in tests/analysis/room/conftest.py
pytestmark = pytest.mark.usefixtures("no_console_errors")


def screenshot(driver, name: str) -> None:
    folder = os.environ.get("COSIM_SCREENSHOTS")
    if folder:
        Path(folder).mkdir(parents=True, exist_ok=True)
        driver.save_screenshot(str(Path(folder) / f"room-{name}.png"))


# -- the studies --------------------------------------------------------------------------------------------------


def write(folder: Path, spec: dict) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "spec.json"
    path.write_text(json.dumps(spec, indent=2))
    return path


def decay_spec() -> dict:
    """dy/dt = a y, y(0) = x0 over 1 s, with a unit that fails at 0.5 s when f.fail_at is 0.5: half the grid fails.
    y_end = x0 e^a (minimised) against y_int = x0 (e^a - 1) / a (maximised): a front along a and x0."""
    return {"name": "decay", "units": {"ode": {"python": python_unit("LinearOde")},
                                       "f": {"python": python_unit("Failing")}},
            "experiment": {"start": 0.0, "stop": 1.0, "step": 0.01}, "record": ["ode.y"],
            "objectives": {"y_end": {"signal": "ode.y", "reduce": "final", "sense": "minimize", "unit": "m"},
                           "y_int": {"signal": "ode.y", "reduce": "integral", "sense": "maximize", "unit": "m.s"}},
            "design": {"parameters": {"ode.a": {"values": [-2.0, -1.5, -1.0, -0.5]},
                                      "ode.x0": {"values": [1.0, 2.0, 3.0]},
                                      "f.fail_at": {"values": [5.0, 0.5], "unit": "s"}}}}


def bowls_spec() -> dict:
    return {"name": "bowls", "units": {"b": {"python": python_unit("TwoBowls")}},
            "experiment": {"stop": 1.0, "step": 1.0},
            "objectives": {"f1": {"signal": "b.f1", "reduce": "final", "sense": "minimize"},
                           "f2": {"signal": "b.f2", "reduce": "final", "sense": "minimize"}},
            "design": {"parameters": {"b.x": {"min": -1.0, "max": 3.0}, "b.y": {"min": -2.0, "max": 2.0}}},
            "optimize": {"budget": 40, "batch": 8, "seed": 3}}


def ishigami_spec() -> dict:
    box = {"min": -np.pi, "max": np.pi}
    return {"name": "ishigami", "units": {"b": {"python": python_unit("Ishigami"), "parameters": {"a": 7.0, "b": 0.1}}},
            "experiment": {"stop": 1.0, "step": 1.0},
            "objectives": {"y": {"signal": "b.y", "reduce": "final", "sense": "maximize"},
                           "lin": {"signal": "b.lin", "reduce": "final", "sense": "minimize"}},
            "design": {"method": "lhs", "samples": 10, "parameters": {"b.x1": box, "b.x2": box, "b.x3": box}}}


@pytest.fixture(scope="module")
def studies(tmp_path_factory, local_cluster):
    """Three real results folders: a sweep, an optimisation and a Sobol sensitivity analysis."""
    import cosim
    from cosim.studies.sensitivity import SensitivityStudy

    root = tmp_path_factory.mktemp("room")
    cosim.sweep(write(root / "sweep", decay_spec()), out=root / "sweep" / "out", scheduler=local_cluster,
                quiet=True)
    cosim.optimize(write(root / "optimize", bowls_spec()), root / "optimize" / "out", scheduler=local_cluster,
                   quiet=True)
    SensitivityStudy(write(root / "sensitivity", ishigami_spec()), root / "sensitivity" / "out", method="sobol",
                     n=16, seed=2, objectives=["y"], scheduler=local_cluster, quiet=True).run()
    return {kind: root / kind / "out" for kind in ("sweep", "optimize", "sensitivity")}


# -- the tests ----------------------------------------------------------------------------------------------------


def exercise(driver, link: str, folder: Path, filter_column: str, name: str) -> dict:
    """The five checks of the module docstring on one folder; returns what the sweep test checks further."""
    table = load_results(folder)
    df = table.df
    n = len(df)
    text, _ = B.load(driver, link)
    assert f"of {n} designs" in text
    ok = (df["status"] == "ok").to_numpy()
    assert B.count_true(driver, "show-ok") == int(ok.sum())
    screenshot(driver, f"{name}-points")

    # a range filter narrows the points: the upper half of one parameter's range
    values = table.values(filter_column)
    lo, hi = float(np.nanmin(values)), float(np.nanmax(values))
    middle = (lo + hi) / 2
    B.set_filter(driver, filter_column, middle, hi)
    kept = values >= middle
    assert 0 < kept.sum() < n
    assert B.count_true(driver, "show-ok") == int((kept & ok).sum())
    assert B.count_true(driver, "show-greyed") == int((~kept).sum())
    assert driver.execute_script("return Bokeh.documents[0].get_model_by_name('count').text;").startswith(
        f"<b>{int(kept.sum())}</b> of {n}")

    # a click on the cloud selects the design under the pointer: the best-ranked design, drawn on the axes
    B.show_tab(driver, 1)  # the ranking is built with its tab
    first = B.ranking_ids(driver)[0]
    B.show_tab(driver, 0)
    row = int(np.flatnonzero(df["point_id"].astype(str).to_numpy() == first)[0])
    x_name, y_name = driver.execute_script(
        "const d = Bokeh.documents[0]; return [d.get_model_by_name('choose-x').value, "
        "d.get_model_by_name('choose-y').value];")
    B.click_point(driver, table.values(x_name)[row], table.values(y_name)[row])
    selected = B.wait_for(  # the click's indices, once the server has ringed them (show-selected)
        driver, "const s = doc.get_model_by_name('cloud-source').selected.indices; "
                  "const ringed = Array.from(doc.get_model_by_name('show-selected').booleans).filter(Boolean).length; "
                  "return s.length && ringed === s.length ? Array.from(s) : null;")
    assert row in selected
    # the hover names the design of the row it is over (the ids go to the page as one text)
    assert driver.execute_script("return Bokeh.documents[0].get_model_by_name('cloud-ids')"
                                  ".format(arguments[0], 'id', {index: arguments[0]});", row) == first

    # the ranking reorders when a weight changes: the first objective's weight to 0 ranks by the others only
    objectives = driver.execute_script(
        "return Bokeh.documents[0].get_model_by_name('weights').children.map((s) => s.name.slice(7));")
    before = B.ranking_ids(driver)
    B.set_and_wait(driver, f"weight:{objectives[0]}", "value", 0.0, B.RANKING_IDS)
    after = B.ranking_ids(driver)
    assert after != before
    senses = table.objective_senses()
    candidates = kept & ok & table.feasible_mask() & np.all(
        np.isfinite(np.column_stack([table.values(o) for o in objectives])), axis=1)
    rest = objectives[1:]
    utility = np.zeros(n)
    for o in rest:  # the weighted sum by hand: each objective scaled to [0, 1] over the candidates, 1 best
        v = table.values(o)
        lo_o, hi_o = v[candidates].min(), v[candidates].max()
        u = (v - lo_o) / (hi_o - lo_o) if hi_o > lo_o else np.ones(n)
        utility += (u if senses[o] == "max" else 1 - u) / len(rest)
    order = np.flatnonzero(candidates)[np.argsort(-utility[candidates], kind="stable")]
    assert after[:5] == list(df["point_id"].astype(str).to_numpy()[order[:5]])
    B.show_tab(driver, 1)
    screenshot(driver, f"{name}-decide")

    # a re-run draws the selected design's traces
    B.show_tab(driver, 2)
    assert str(df["point_id"].iloc[row]) in driver.execute_script(
        "return Bokeh.documents[0].get_model_by_name('selected').text;")
    B.click_widget(driver, "rerun")
    traces = B.wait_for(
        driver, "const c = doc.get_model_by_name('traces'); "
                  "if (doc.get_model_by_name('rerun-status').text.includes('failed')) return 'failed'; "
                  "return c && c.children.length ? "
                  "c.children.map((f) => [f.name, f.renderers.map((r) => [r.name, Array.from(r.data_source.data.x),"
                  " Array.from(r.data_source.data.y)])]) : null;")
    assert traces != "failed", driver.execute_script(
        "return Bokeh.documents[0].get_model_by_name('rerun-status').text;")
    screenshot(driver, f"{name}-selection")
    if (folder / "sensitivity.csv").exists() or table.metadata.get("kind") == "optimization":
        B.show_tab(driver, 3)
        screenshot(driver, f"{name}-study")
    return {"table": table, "row": row, "selected": selected, "traces": traces}


def test_sweep_folder_filter_click_rerun_and_ranking(browser, studies, room):
    folder = studies["sweep"]
    link, _ = room(folder)
    seen = exercise(browser, link, folder, "ode.a", "sweep")
    table, row = seen["table"], seen["row"]
    df = table.df
    # failed designs: drawn in their status colour, listed with their message
    failed = (df["status"] == "failed").to_numpy()
    assert failed.sum() == 12
    B.show_tab(browser, 0)
    messages = browser.execute_script("return Array.from(Bokeh.documents[0].get_model_by_name('failures')"
                                      ".source.data.message);")
    assert len(messages) == 12 and all("boom" in m for m in messages)
    # ... and drawn as crosses from a source of their own (the cloud's has no string column), the kept ones shown
    crosses = browser.execute_script("const d = Bokeh.documents[0].get_model_by_name('cloud-not-ok-source').data;"
                                     "return [Array.from(d.point_id), Array.from(d.status)];")
    assert crosses == [list(df.loc[failed, "point_id"].astype(str)), ["failed"] * 12]
    y, _ = B.set_and_wait(browser, "choose-y", "value", "ode.x0",  # a column the failed designs have
                          "return Array.from(doc.get_model_by_name('cloud-not-ok-source').data.y).join();")
    assert np.allclose([float(v) for v in y.split(",")], table.values("ode.x0")[failed])
    a = table.values("ode.a")
    assert B.count_true(browser, "show-not_ok") == int((failed & (a >= (a.min() + a.max()) / 2)).sum())
    # a second column chosen in the range filter narrows that column and leaves the first one's range as it was
    a, x0 = table.values("ode.a"), table.values("ode.x0")
    B.set_filter(browser, "ode.x0", 2.0, 3.0)
    kept = (a >= (a.min() + a.max()) / 2) & (x0 >= 2.0)
    assert browser.execute_script("return Bokeh.documents[0].get_model_by_name('count').text;").startswith(
        f"<b>{int(kept.sum())}</b> of {len(df)}")
    narrowed = browser.execute_script("return Bokeh.documents[0].get_model_by_name('narrowed').text;")
    assert narrowed.count("<li>") == 2 and "ode.a: -1.25 … -0.5" in narrowed and "ode.x0: 2 … 3" in narrowed
    # the traces are the spec's recorded signal, y = x0 e^(a t), one line per selected design
    assert [name for name, _ in seen["traces"]] == ["trace:ode.y"]
    lines = {name.split(":")[-1]: (np.array(t), np.array(y)) for name, t, y in seen["traces"][0][1]}
    a, x0 = float(df["ode.a"].iloc[row]), float(df["ode.x0"].iloc[row])
    t, y = lines[str(df["point_id"].iloc[row])]
    assert t[-1] == pytest.approx(1.0) and y == pytest.approx(x0 * np.exp(a * t), rel=1e-9)
    # the selection's export: CSV rows and cosim run commands naming the design
    export = browser.execute_script("return Bokeh.documents[0].get_model_by_name('export').text;")
    assert f"--point {df['point_id'].iloc[row]}" in export and "data:text/csv;base64," in export


def test_decide_tab_explains_designs_pins_a_shortlist_and_keeps_the_view_in_its_link(browser, studies, room):
    """Issue 39.2 on the sweep: the ranking shows each design's parameters and objectives with their units, on
    both objectives with a sense; two ranked designs pinned are compared side by side and re-run, their traces
    overlaid (y = x0 e^(a t)); the view (axes, colour, a filter, the method, a weight, the shortlist, the tab)
    goes into the page's address, and that address opened in a fresh chromium (no cookie) shows the same
    widgets' values, ranking and shortlist."""
    folder = studies["sweep"]
    link, _ = room(folder)
    table = load_results(folder)
    df = table.df
    ids = df["point_id"].astype(str).to_numpy()
    B.load(browser, link)
    B.show_tab(browser, 1)
    doc = "Bokeh.documents[0]"
    assert browser.execute_script(f"return [{doc}.get_model_by_name('minimise').value, "
                                  f"{doc}.get_model_by_name('maximise').value];") == [["y_end"], ["y_int"]]
    titles = browser.execute_script(f"return {doc}.get_model_by_name('ranking').columns.map((c) => c.title);")
    assert titles == ["#", "design", "score", "ode.a", "ode.x0", "f.fail_at [s]", "y_end [m] (min)",
                      "y_int [m.s] (max)"]
    data = browser.execute_script(f"const d = {doc}.get_model_by_name('ranking').source.data; "
                                  "return Object.fromEntries(Object.entries(d).map(([k, v]) => [k, Array.from(v)]));")
    rows = [int(np.flatnonzero(ids == i)[0]) for i in data["point_id"]]
    assert len(rows) == 12  # the ok designs
    for field, name in (("p0", "ode.a"), ("p1", "ode.x0"), ("p2", "f.fail_at"), ("o0", "y_end"), ("o1", "y_int")):
        assert data[field] == pytest.approx(table.values(name)[rows], rel=1e-12)
    # the radar has a spoke per objective
    assert browser.execute_script(f"return {doc}.get_model_by_name('radar-spokes').data.label.length;") == 2

    # the first two ranked designs: a click on their rows selects them; pinned, they are compared side by side
    browser.execute_script(f"{doc}.get_model_by_name('ranking').source.selected.indices = [0, 1];")
    B.wait_for(browser, "return doc.is_idle && Array.from(doc.get_model_by_name('show-selected').booleans)"
                        ".filter(Boolean).length === 2;")
    B.click_widget(browser, "pin")
    shortlist = B.wait_for(browser, "const t = doc.get_model_by_name('shortlist'); return doc.is_idle && "
                                    "t.columns.length === 4 && 'd1' in t.source.data ? [t.columns.map((c) => c.title), "
                                    "Object.fromEntries(Object.entries(t.source.data).map(([k, v]) => [k, Array.from(v)]))]"
                                    " : null;")
    pinned = data["point_id"][:2]
    assert shortlist[0] == ["", "", *pinned]
    # a row clicked in the comparison, then both unpinned and pinned again: the click's highlight goes before
    # the rows are replaced (bokeh 3.4 threw "Out of bounds" in the page here)
    browser.execute_script(f"{doc}.get_model_by_name('shortlist').source.selected.indices = [4];")
    B.click_widget(browser, "unpin")
    B.wait_for(browser, "return doc.is_idle && doc.get_model_by_name('shortlist').columns.length === 2;")
    assert browser.execute_script(f"return Array.from({doc}.get_model_by_name('shortlist').source.selected.indices);"
                                  ) == []
    B.click_widget(browser, "pin")
    B.wait_for(browser, "const t = doc.get_model_by_name('shortlist'); return doc.is_idle && t.columns.length === 4 "
                        "&& t.source.data.quantity.length === 5;")
    assert shortlist[1]["quantity"] == ["ode.a", "ode.x0", "f.fail_at [s]", "y_end [m]", "y_int [m.s]"]
    for k, r in enumerate(rows[:2]):
        assert shortlist[1][f"d{k}"] == pytest.approx([table.values(c)[r] for c in
                                                       ("ode.a", "ode.x0", "f.fail_at", "y_end", "y_int")])
    B.click_widget(browser, "rerun-shortlist")
    lines = B.wait_for(browser, "const f = doc.get_model_by_name('shortlist-trace:ode.y'); "
                                "if (doc.get_model_by_name('shortlist-status').text.includes('failed')) return 'failed';"
                                "return f && doc.is_idle ? f.renderers.map((r) => [r.name, Array.from(r.data_source.data.x),"
                                " Array.from(r.data_source.data.y)]) : null;")
    assert lines != "failed"
    assert sorted(name.split(":")[-1] for name, _, _ in lines) == sorted(pinned)
    for name, t, y in lines:
        r = rows[pinned.index(name.split(":")[-1])]
        a, x0 = table.values("ode.a")[r], table.values("ode.x0")[r]
        assert np.array(y) == pytest.approx(x0 * np.exp(a * np.array(t)), rel=1e-9)
    screenshot(browser, "sweep-shortlist")

    # the view changed on every count the link carries; the address bar follows
    B.set_and_wait(browser, "choose-x", "value", "ode.x0", "return location.search.includes('x=ode.x0') || null;")
    B.set_and_wait(browser, "choose-colour", "value", "y_int", "return location.search.includes('colour=y_int') || null;")
    B.set_filter(browser, "ode.a", -1.5, -0.5, watch="return location.search.includes('f=ode.a') ? location.search : null;")
    B.set_and_wait(browser, "method", "value", "topsis", "return location.search.includes('rank=topsis') || null;")
    B.set_and_wait(browser, "weight:y_end", "value", 0.25, "return location.search.includes('y_end~0.25') || null;")
    # the ranking, re-ordered and narrowed three times since, highlights the rows of the two selected designs
    # wherever they are now (not the first two rows it had: bokeh 3.4 threw "Out of bounds" in the page when
    # they outlived the table's old rows)
    ranked, highlighted = browser.execute_script(f"const s = {doc}.get_model_by_name('ranking').source; "
                                                 "return [Array.from(s.data.point_id), Array.from(s.selected.indices)];")
    assert sorted(highlighted) == [k for k, i in enumerate(ranked) if i in pinned]
    address = browser.current_url
    assert address.startswith(link) and "pin=" in address and "tab=1" in address
    expected = browser.execute_script(f"return Array.from({doc}.get_model_by_name('ranking').source.data.point_id);")
    colleague = B.chromium()
    try:
        count, _ = B.load(colleague, address)
        assert count.startswith(f"<b>{int((table.values('ode.a') >= -1.5).sum())}</b> of {len(df)}")
        B.wait_for(colleague, "return doc.is_idle && doc.get_model_by_name('ranking') !== null;")
        got = colleague.execute_script(
            f"const d = {doc}; const v = (n, a) => d.get_model_by_name(n)[a]; "
            "return [v('tabs', 'active'), v('choose-x', 'value'), v('choose-y', 'value'), v('choose-colour', 'value'),"
            " v('method', 'value'), v('weight:y_end', 'value'), v('weight:y_int', 'value'), v('filter', 'tags')[0],"
            " Array.from(v('filter', 'value')), v('minimise', 'value'), v('maximise', 'value'),"
            " v('shortlist', 'columns').map((c) => c.title), Array.from(v('ranking', 'source').data.point_id)];")
        y_axis = browser.execute_script(f"return {doc}.get_model_by_name('choose-y').value;")
        assert got == [1, "ode.x0", y_axis, "y_int", "topsis", 0.25, 1.0, "ode.a", [-1.5, -0.5], ["y_end"], ["y_int"],
                       ["", "", *pinned], expected]
        assert "ode.a: -1.5 … -0.5" in colleague.execute_script(f"return {doc}.get_model_by_name('narrowed').text;")
        assert colleague.current_url == address  # the page opened with it writes the same view back
        assert B.console_errors(colleague) == []
    finally:
        colleague.quit()


def test_optimisation_folder_with_its_hypervolume(browser, studies, room):
    from cosim.analysis.hypervolume import hypervolume, normalised_losses
    from cosim.analysis.pareto import pareto_mask

    folder = studies["optimize"]
    link, _ = room(folder)
    seen = exercise(browser, link, folder, "b.x", "optimize")
    df = seen["table"].df
    # every output of the bowls (the spec records nothing), f1 = x^2 + y^2 over the run
    names = dict(seen["traces"])
    f1 = {n.split(":")[-1]: y for n, _, y in names["trace:b.f1"]}
    x, y = df["b.x"].iloc[seen["row"]], df["b.y"].iloc[seen["row"]]
    assert f1[str(df["point_id"].iloc[seen["row"]])][-1] == pytest.approx(x ** 2 + y ** 2, rel=1e-12)
    # the hypervolume against evaluations ends at the hypervolume of the final front, in the scale of the first
    # batch's usable rows (fixed for the run, issue 28), reference 1.1
    history = browser.execute_script("const f = Bokeh.documents[0].get_model_by_name('hypervolume');"
                                     "return Array.from(f.renderers[0].data_source.data.y);")
    usable = ((df["status"] == "ok") & df["feasible"]).to_numpy()
    values = df.loc[usable, ["f1", "f2"]].to_numpy(float)
    batches = df.loc[usable, "batch"].to_numpy()
    first = values[batches == batches.min()]
    front = values[pareto_mask(values)]
    final = hypervolume(normalised_losses(front, ["min", "min"], first.min(axis=0), first.max(axis=0)))
    assert len(history) == len(df) and history[-1] == pytest.approx(final, rel=1e-9)
    assert all(b >= a - 1e-12 for a, b in zip(history, history[1:]))

    # what optuna-dashboard shows (issue 39.2), from the table: the history of f1 and its best so far...
    from cosim.analysis.room import trials as T

    table = seen["table"]

    def drawn(name, fields):
        return browser.execute_script(  # live: a view drawn anew leaves its old model in the page a while
            B.LIVE_JS + "const m = live(arguments[0]); "
            "const s = m.data_source ?? m; return arguments[1].map((f) => Array.from(s.data[f]));", name, fields)

    order = df.sort_values("trial", kind="stable")
    good = ((order["status"] == "ok") & order["feasible"]).to_numpy()
    trials, values = drawn("history-values", ["x", "y"])
    assert trials == list(order["trial"][good]) and values == pytest.approx(list(order["f1"][good]))
    best = drawn("history-best", ["y"])[0]
    assert best == pytest.approx(np.fmin.accumulate(np.where(good, order["f1"], np.nan)), nan_ok=True)
    # ... the importances of optuna's fANOVA on the table's trials, most important first ...
    names = T.parameters(table, table.numeric_columns())
    expected = T.importances(table, names, {"f1": "min", "f2": "min"})["f1"]
    parameter, importance = drawn("importances-source", ["parameter", "importance"])
    assert dict(zip(parameter, importance)) == pytest.approx(expected) and sum(importance) == pytest.approx(1.0)
    assert parameter[-1] == max(expected, key=expected.get)  # the top bar
    # ... a slice plot per parameter, and the contour of the two over their hull
    x, y = drawn("slice-source:b.x", ["x", "y"])
    assert x == pytest.approx(list(df["b.x"][usable])) and y == pytest.approx(list(df["f1"][usable]))
    grid = T.contour(df["b.x"][usable].to_numpy(float), df["b.y"][usable].to_numpy(float),
                     df["f1"][usable].to_numpy(float))
    image = browser.execute_script("const s = Bokeh.documents[0].get_model_by_name('contour-source'); "
                                   "const i = s.data.image[0]; return [Array.from(i.shape ?? []), Array.from(i.flat ?? i)];")
    assert np.allclose(np.array(image[1], dtype=float), grid["image"].ravel(), equal_nan=True)
    # another objective chosen: the history is f2's
    B.set_and_wait(browser, "study-objective", "value", "f2",
                   B.LIVE_JS.replace("throw new Error(`${hits.length} models named ${name} in the page`)", "return null")
                   + "const m = live('history'); return m && m.title.text.includes('f2') ? m.title.text : null;")
    values = drawn("history-values", ["y"])[0]
    assert values == pytest.approx(list(order["f2"][good]))
    screenshot(browser, "optimize-study-trials")


def test_sensitivity_folder_with_its_indices(browser, studies, room):
    folder = studies["sensitivity"]
    link, _ = room(folder)
    exercise(browser, link, folder, "b.x1", "sensitivity")
    bars = browser.execute_script(
        "const f = Bokeh.documents[0].get_model_by_name('sensitivity:y'); const d = f.renderers[0].data_source.data;"
        "return [Array.from(d.factor), Array.from(d.value), Array.from(d.upper)];")
    written = pd.read_csv(folder / "sensitivity.csv")
    shown = {tuple(f): (v, u) for f, v, u in zip(*bars)}
    assert len(shown) == len(written) == 6
    for r in written.itertuples():
        v, u = shown[(r.parameter, r.index)]
        assert v == pytest.approx(r.value) and u == pytest.approx(r.value + r.conf)


def test_a_room_wants_its_token_on_every_address(room, studies):
    link, server = room(studies["sweep"], host="0.0.0.0")
    assert "?token=" in link
    port = server.server.port
    token = link.split("?token=")[1]
    with pytest.raises(urllib.error.HTTPError) as refused:
        urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=60)
    assert refused.value.code == 403
    with pytest.raises(urllib.error.HTTPError):
        urllib.request.urlopen(f"http://127.0.0.1:{port}/?token=wrong", timeout=60)
    page = urllib.request.urlopen(f"http://127.0.0.1:{port}/?token={token}", timeout=60)
    assert page.status == 200 and b"cosim: decay" in page.read()
    assert f"{cookie_name(token)}={token}" in page.headers.get("Set-Cookie", "")
    loopback, _ = room(studies["sweep"])  # loopback too (a login node's other users): issue 38.3
    assert loopback.startswith("http://127.0.0.1:") and "?token=" in loopback
    open_room, _ = room(studies["sweep"], no_token=True)
    assert "token" not in open_room and urllib.request.urlopen(open_room, timeout=60).status == 200


def test_a_large_table_is_drawn_as_bins_made_on_the_server(browser, studies, room):
    """Above AGGREGATE_ABOVE rows the cloud is an image of bins made on the server (here the sweep folder with
    the threshold at 0 rows): the bins holding designs are coloured (kept ok ones by the mean of the colour
    column, failed ones red, filtered out ones grey) against bins counted here by np.histogram2d; a click selects
    the design under the pointer; a zoom re-bins the new rectangle."""
    from bokeh.palettes import Viridis256

    from cosim.analysis.room.aggregate import rgba
    from cosim.analysis.room.views import GREY

    folder = studies["sweep"]
    link, _ = room(folder, aggregate_above=0)
    table = load_results(folder)
    df = table.df
    text, _ = B.load(browser, link)
    assert f"of {len(df)} designs" in text
    for which, column in (("x", "ode.a"), ("y", "f.fail_at"), ("colour", "y_end")):
        B.set_and_wait(browser, f"choose-{which}", "value", column,
                       "const d = Bokeh.documents[0].get_model_by_name('cloud-image').data; "
                       f"return d.image.length ? [d.x[0], d.y[0], d.dw[0], d.dh[0], {which!r}].join() + "
                       "Array.from(d.image[0]).join() : null;")
    x, y, c = table.values("ode.a"), table.values("f.fail_at"), table.values("y_end")
    ok = (df["status"] == "ok").to_numpy()
    failed = (df["status"] == "failed").to_numpy()
    assert ok.sum() == failed.sum() == 12

    def expected(got, kept):
        image = np.array(got["image"], dtype=np.uint32)
        h, w = image.shape
        edges = (np.linspace(got["y"], got["y"] + got["dh"], h + 1), np.linspace(got["x"], got["x"] + got["dw"], w + 1))
        def count(rows, weights=None):
            return np.histogram2d(y[rows], x[rows], bins=edges, weights=weights)[0]

        kept_ok, kept_failed, dropped = count(kept & ok), count(kept & failed), count(~kept)
        mean = count(kept & ok, c[kept & ok]) / np.where(kept_ok > 0, kept_ok, 1)
        lo, hi = np.nanmin(c), np.nanmax(c)
        index = np.clip(((mean - lo) / (hi - lo) * 256).astype(int), 0, 255)
        want = np.zeros_like(image)
        want[dropped > 0] = rgba(GREY)
        want[kept_failed > 0] = rgba("#d62728")
        viridis = np.array([rgba(v) for v in Viridis256], dtype=np.uint32)
        want[kept_ok > 0] = viridis[index[kept_ok > 0]]
        return image, want

    image, want = expected(B.binned_image(browser), np.ones(len(df), dtype=bool))
    assert (image != 0).sum() == 8 and np.array_equal(image, want)  # 4 values of a x 2 of fail_at

    # a filter turns the dropped designs' bins grey
    B.set_filter(browser, "ode.a", -1.0, -0.5)
    kept = x >= -1.0
    image, want = expected(B.binned_image(browser), kept)
    assert (want == rgba(GREY)).sum() == 4 and np.array_equal(image, want)

    # a click selects the design under the pointer (the first of the three sharing its bin: x0 is not drawn)
    row = int(np.flatnonzero(ok & (x == -0.5))[0])
    B.click_point(browser, x[row], y[row])
    chosen = B.wait_for(browser, "const d = doc.get_model_by_name('cloud-selected-points').data; "
                                 "return d.point_id.length && doc.is_idle ? Array.from(d.point_id) : null;")
    assert chosen == [str(df["point_id"].iloc[row])]

    # a zoom re-bins the new rectangle: the x range -1.2 .. -0.3 holds the designs of a = -1 and -0.5 only
    B.set_and_wait(browser, "cloud-x", "start", -1.2, "return doc.get_model_by_name('cloud-image').data.x[0];")
    browser.execute_script("Bokeh.documents[0].get_model_by_name('cloud-x').end = -0.3;")
    got = B.wait_for(browser, "const d = doc.get_model_by_name('cloud-image').data; "
                              "return Math.abs(d.x[0] + d.dw[0] + 0.3) < 1e-9 && doc.is_idle;")
    assert got
    image, want = expected(B.binned_image(browser), kept)
    assert (image != 0).sum() == 4 and np.array_equal(image, want)


def test_dimensions_matrix_parallel_coordinates_brushing_and_3d(browser, studies, room):
    """The Dimensions tab on the sweep: the scatter matrix's panels and source, the parallel coordinates' lines
    (each column scaled over its range, computed here), a real mouse box over the first axis narrowing its
    filter (brushing), a selection in the matrix shown in the lines, and the 3-D view turned by its sliders and
    by a drag, against the projection computed here."""
    folder = studies["sweep"]
    link, _ = room(folder)
    table = load_results(folder)
    df = table.df
    n = len(df)
    B.load(browser, link)
    B.show_tab(browser, 4)
    columns = ["ode.a", "ode.x0", "f.fail_at", "y_end"]  # the parameters, then the first objective
    assert browser.execute_script("return Bokeh.documents[0].get_model_by_name('dimensions').value;") == columns
    names = browser.execute_script(
        "const out = []; for (const m of Bokeh.documents[0]._all_models.values()) "
        "{ if (m.name && m.name.startsWith('matrix:')) out.push(m.name); } return out.sort();")
    assert names == sorted(["matrix:1:0", "matrix:2:0", "matrix:2:1", "matrix:3:0", "matrix:3:1",
                                               "matrix:3:2"])
    source = browser.execute_script("const d = Bokeh.documents[0].get_model_by_name('matrix-source').data;"
                                    "return [0, 1, 2, 3].map((k) => Array.from(d['c' + k]));")
    for k, c in enumerate(columns):
        assert np.allclose(np.array(source[k], dtype=float), table.values(c), equal_nan=True)

    def lines(layer):
        got = browser.execute_script(f"const d = Bokeh.documents[0].get_model_by_name('parallel-{layer}').data;"
                                     "return [Array.from(d.x), Array.from(d.y)];")
        return np.array(got[0], dtype=float), np.array(got[1], dtype=float)

    def expected_lines(rows):
        y = np.full((len(rows), 5), np.nan)
        for k, c in enumerate(columns):
            v = table.values(c)
            lo, hi = np.nanmin(v), np.nanmax(v)
            y[:, k] = (v[rows] - lo) / (hi - lo)
        return np.tile([0, 1, 2, 3, np.nan], len(rows)), y.reshape(-1)

    x, y = lines("kept")
    ex, ey = expected_lines(np.arange(n))
    assert np.allclose(x, ex, equal_nan=True) and np.allclose(y, ey, equal_nan=True)

    # brushing: a box from above the top of axis 0 down to its middle keeps a >= -1.25 (a in -2 .. -0.5)
    B.drag(browser, (-0.2, 1.04), (0.2, 0.5), "parallel")
    text = B.wait_for(browser, "const t = doc.get_model_by_name('count').text; "
                               "return t.startsWith('<b>24<') ? null : t;")
    a = table.values("ode.a")
    kept = a >= -1.25
    assert text.startswith(f"<b>{int(kept.sum())}</b> of {n}")
    narrowed = browser.execute_script("return Bokeh.documents[0].get_model_by_name('narrowed').text;")
    low = float(narrowed.split("ode.a: ")[1].split(" …")[0])
    assert low == pytest.approx(-1.25, abs=0.02)  # a pixel of the 320 px plot is 0.005 of the range
    x, y = lines("kept")
    ex, ey = expected_lines(np.flatnonzero(kept))
    assert np.allclose(y, ey, equal_nan=True)
    assert len(lines("greyed")[0]) == 5 * int((~kept).sum())

    # a selection in the matrix (as its box tool sets it) selects the design everywhere
    browser.execute_script("Bokeh.documents[0].get_model_by_name('matrix-source').selected.indices = [5];")
    sx, sy = B.wait_for(browser, "const d = doc.get_model_by_name('parallel-selected').data; "
                                 "return d.x.length ? [Array.from(d.x), Array.from(d.y)] : null;")
    assert np.allclose(np.array(sy, dtype=float), expected_lines(np.array([5]))[1], equal_nan=True)
    assert B.count_true(browser, "show-selected") == 1

    # the 3-D view: the first three columns scaled to [-1, 1], projected from the sliders' angles
    def projected():
        got = browser.execute_script("const d = Bokeh.documents[0].get_model_by_name('scatter3d-source').data;"
                                     "return [Array.from(d.px), Array.from(d.py)];")
        return np.array(got[0], dtype=float), np.array(got[1], dtype=float)

    u, v, w = (2 * (table.values(c) - np.nanmin(table.values(c))) / np.ptp(table.values(c)) - 1 for c in columns[:3])
    for azimuth, elevation in ((1.0, -0.3), (-2.5, 1.2)):
        browser.execute_script(f"const d = Bokeh.documents[0]; d.get_model_by_name('azimuth').value = {azimuth};"
                               f"d.get_model_by_name('elevation').value = {elevation};")
        px, py = projected()
        ca, sa, ce, se = np.cos(azimuth), np.sin(azimuth), np.cos(elevation), np.sin(elevation)
        assert np.allclose(px, u * ca - v * sa) and np.allclose(py, w * ce + (u * sa + v * ca) * se)
    before = browser.execute_script("return Bokeh.documents[0].get_model_by_name('azimuth').value;")
    B.drag(browser, (-1.0, 0.0), (0.5, 0.0), "scatter3d")
    after = browser.execute_script("return Bokeh.documents[0].get_model_by_name('azimuth').value;")
    assert after != before
    px, py = projected()
    ca, sa = np.cos(after), np.sin(after)
    assert np.allclose(px, u * ca - v * sa)

    # other columns: the views are built again in the page, the 3-D view still coloured by the colour column
    in_tab = ("const tab = doc.get_model_by_name('dimensions-tab');"
              "const find = (m) => m.name === 'scatter3d' ? m : (m.children || []).map(find).find((f) => f);"
              "const fig = tab.children.map(find).find((f) => f);")
    before = B.wait_for(browser, in_tab + "return fig.id;")
    browser.execute_script("Bokeh.documents[0].get_model_by_name('dimensions').value = arguments[0];",
                           ["ode.x0", "ode.a", "y_end"])
    fills = B.wait_for(browser, in_tab + f"if (fig.id === {json.dumps(before)}) return null;"
                       "const v = Bokeh.index.find_one(fig); if (!v || !v.has_finished()) return null;"
                       "return fig.renderers.map((r) => r.glyph.fill_color).filter((c) => c && c.field !== undefined)"
                       ".map((c) => [c.field, 'value' in c]);")
    assert fills == [["c", False]]


def test_the_room_of_a_running_sweep_draws_points_as_they_arrive(browser, tmp_path, local_cluster):
    """``sweep(explore=True)`` serves the room of its folder while it runs, linked from the dashboard's Cosim
    page; the page (opened before the first rows) draws new points as rows are written, without a reload,
    with counts by status; every point it showed is a row of the finished table with its values."""
    import io
    import re
    import threading
    import time

    import cosim

    ROWS = 24  # enough for the page to show the table growing on a loaded machine (it draws each new table)
    spec = write(tmp_path / "live", {
        "name": "sleepy", "units": {"s": {"python": python_unit("Sleeper"), "parameters": {"delay": 0.15}}},
        "experiment": {"stop": 1.0, "step": 0.1},
        "objectives": {"y_end": {"signal": "s.y", "reduce": "final", "sense": "maximize"}},
        "design": {"parameters": {"s.gain": {"values": [float(g) for g in range(1, 1 + ROWS)]}}}})
    out = tmp_path / "live" / "out"
    said = io.StringIO()
    done: dict = {}
    thread = threading.Thread(target=lambda: done.update(df=cosim.sweep(
        spec, out=out, scheduler=local_cluster, explore=True, progress=said, batch_size=2)), daemon=True)
    thread.start()
    deadline = time.monotonic() + 120
    while not re.search(r"decision room: (http://\S+)", said.getvalue()) and time.monotonic() < deadline:
        time.sleep(0.05)
    link = re.search(r"decision room: (http://\S+)", said.getvalue()).group(1)
    points_page = re.search(r"points: (http://\S+)\)", said.getvalue()).group(1)
    assert f"href='{link}'" in urllib.request.urlopen(points_page, timeout=30).read().decode()
    browser.get(link)
    seen = []
    look = ("const d = Bokeh.documents[0], s = d.get_model_by_name('cloud-source');"
            f"return s ? [d.get_model_by_name('count').text, ({B.CLOUD_IDS})(d), Array.from(s.data.x),"
            " Array.from(s.data.y)] : null;")
    while thread.is_alive():
        try:  # a state the page shows for a while: the server's changes of one update arrive one by one
            first = browser.execute_script(look)
            time.sleep(0.1)
            if browser.execute_script(look) == first:
                seen.append(first)
        except Exception:  # between the waiting page and the room, or the room stopping with the sweep
            pass
        time.sleep(0.2)
    thread.join()
    final = load_results(out).df
    assert len(final) == ROWS and (final["status"] == "ok").all()
    by_id = final.set_index("point_id")
    shown = [s for s in seen if s is not None]
    sizes = [len(ids) for _, ids, _, _ in shown]
    assert any(0 < k < ROWS for k in sizes) and len(set(sizes)) >= 2, sizes  # it grew while the page was open
    assert sizes == sorted(sizes)
    for text, ids, x, y in shown:
        assert f"live: {len(ids)} rows ({len(ids)} ok)" in text
        assert "the study is running" in text or len(ids) == ROWS
        # the cloud's axes are the design parameter and the objective: y_end = gain (y = gain t at t = 1)
        assert np.allclose(x, by_id.loc[ids, "s.gain"].to_numpy(float))
        assert np.allclose(y, by_id.loc[ids, "y_end"].to_numpy(float)) and np.allclose(y, x)


def test_a_page_waiting_for_the_first_rows_becomes_the_room_without_console_errors(browser, studies, tmp_path):
    """A page opened on a watched folder before its first rows waits, then turns into the room when rows
    appear (here the sweep's table copied in): the cloud is drawn with its colour map, and chromium's console
    has no error.  Before the fix, the room's models went to the page while bokeh's property validation was
    off (a speed-up of the server), which made bokeh send the colour map's field as a constant: the page
    logged "color is not iterable" and never drew the cloud."""
    import shutil
    import time

    from cosim.analysis.room.live import LiveStudy
    from cosim.analysis.room.server import RoomServer

    folder = tmp_path / "watched"
    folder.mkdir()
    server = RoomServer(LiveStudy(folder, every=0.2))
    try:
        B.console_errors(browser)  # what the earlier tests left in the log
        browser.get(server.link)
        B.wait_for(browser, "return doc !== undefined && doc.get_model_by_name('waiting') !== null;")
        for name in ("metadata.json", "results.parquet"):
            shutil.copy(studies["sweep"] / name, folder / name)
        df = load_results(folder).df
        errors: list[str] = []
        drawn = None
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not errors and not drawn:
            time.sleep(0.1)
            errors += B.console_errors(browser)
            drawn = browser.execute_script(  # the count, once the cloud's view is built and drawn
                "const doc = Bokeh.documents[0], cloud = doc.get_model_by_name('cloud');"
                "const view = cloud && Bokeh.index.find_one(cloud);"
                "return view && view.has_finished() ? doc.get_model_by_name('count').text : null;")
        errors += B.console_errors(browser)
        assert not errors, errors
        assert drawn is not None and f"of {len(df)} designs" in drawn and f"live: {len(df)} rows" in drawn
        assert B.count_true(browser, "show-ok") == int((df["status"] == "ok").sum())
        fill = browser.execute_script("const c = Bokeh.documents[0].get_model_by_name('cloud-ok').glyph.fill_color;"
                                      "return [c.field === undefined ? null : c.field, 'value' in c];")
        assert fill == ["c", False]  # the colour column, not a constant
    finally:
        server.stop()


def test_an_optimisation_with_explore_serves_its_room_while_it_runs(tmp_path, local_cluster):
    """``optimize(explore=True)``: the start line gives the room's link, and the room answers while the
    optimisation runs (its page, titled by the spec's name, fetched from a thread)."""
    import io
    import re
    import threading
    import time

    import cosim

    spec = write(tmp_path / "opt", {**bowls_spec(), "optimize": {"budget": 16, "batch": 4, "seed": 3}})
    said = io.StringIO()
    pages: list = []

    def fetch() -> None:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not pages:
            found = re.search(r"decision room: (http://\S+)", said.getvalue())
            if found:
                pages.append(urllib.request.urlopen(found.group(1), timeout=60).read().decode())
            time.sleep(0.05)

    watcher = threading.Thread(target=fetch, daemon=True)
    watcher.start()
    cosim.optimize(spec, tmp_path / "opt" / "out", scheduler=local_cluster, explore=True, progress=said)
    watcher.join(10)
    assert re.search(r"; decision room: http://127\.0\.0\.1:\d+/", said.getvalue())
    assert pages and "<title>cosim: " in pages[0]
