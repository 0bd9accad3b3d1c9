"""The decision room's Surrogate tab in real chromium: the predicted map against the stored surrogate's own
prediction, the simulated designs on top, Q² on screen, another held design, and "simulate here" adding a real
simulation of the clicked design to the study as a row (TwoBowls: f1 = x^2 + y^2, f2 = (x - 2)^2 + y^2)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cosim.analysis.room import browser as B
from cosim.analysis.surrogate import read
from cosim.analysis.table import load_results
from cosim.cli.main import main
from tests.helpers.tools import python_unit

# no error in chromium's console at the end of a test that drives it (the fixture is in tests/conftest.py)
pytestmark = pytest.mark.usefixtures("no_console_errors")


def bowls_sweep_spec() -> dict:
    return {"name": "bowls", "units": {"b": {"python": python_unit("TwoBowls")}},
            "experiment": {"stop": 1.0, "step": 1.0},
            "objectives": {"f1": {"signal": "b.f1", "reduce": "final", "sense": "minimize"},
                           "f2": {"signal": "b.f2", "reduce": "final", "sense": "minimize"}},
            "design": {"method": "lhs", "samples": 30, "seed": 4,
                       "parameters": {"b.x": {"min": -1.0, "max": 3.0}, "b.y": {"min": -2.0, "max": 2.0}}}}


@pytest.fixture(scope="module")
def folder(tmp_path_factory, local_cluster) -> Path:
    import cosim

    root = tmp_path_factory.mktemp("room_surrogate")
    spec = root / "spec.json"
    spec.write_text(json.dumps(bowls_sweep_spec()))
    out = root / "out"
    cosim.sweep(spec, out=out, scheduler=local_cluster, quiet=True)
    assert main(["surrogate", str(out), "--method", "gp"]) == 0
    return out


def page(driver, js: str):
    return driver.execute_script("const doc = Bokeh.documents[0]; " + js)


def test_surrogate_tab_maps_predictions_and_simulates_a_picked_design(browser, folder):  # noqa: F811
    from cosim.analysis.room.data import Study
    from cosim.analysis.room.server import RoomServer
    from cosim.analysis.room.surrogate_view import GRID

    table = load_results(folder)
    n = len(table.df)
    surrogates = read(folder / "surrogate")
    server = RoomServer(Study(table))
    try:
        B.load(browser, server.link)
        titles = page(browser, "return doc.get_model_by_name('tabs').tabs.map((t) => t.title);")
        assert titles[-1] == "Surrogate"
        B.show_tab(browser, len(titles) - 1)
        B.wait_for(browser, "return doc.get_model_by_name('surrogate-map') ? true : null;")
        # Q² on screen: the stored one, and the parameters' own
        quality = page(browser, "return doc.get_model_by_name('surrogate-quality').text;")
        f1 = surrogates.objectives["f1"]
        assert f"Q² {f1.fitted.q2:.4f}" in quality and "Q² of b.x" in quality
        # the map is the stored surrogate's prediction over the fitted box, the other parameters held (none here)
        image = np.array(page(browser, "return Array.from(doc.get_model_by_name('surrogate-image').data.image[0]);"))
        model = f1.fitted.model
        xs = np.linspace(model.scaling.low[0], model.scaling.low[0] + model.scaling.span[0], GRID)
        ys = np.linspace(model.scaling.low[1], model.scaling.low[1] + model.scaling.span[1], GRID)
        gx, gy = np.meshgrid(xs, ys)
        want = model.predict(np.c_[gx.ravel(), gy.ravel()])[0]
        np.testing.assert_allclose(image.ravel(), want, rtol=1e-12, atol=1e-12)
        # ... and close to the true f1 inside the box (Q² says how close; 30 designs of a quadratic)
        assert np.max(np.abs(want - (gx.ravel() ** 2 + gy.ravel() ** 2))) < 0.5
        # the simulated designs on top
        shown = page(browser, "const d = doc.get_model_by_name('surrogate-designs').data; "
                              "return [Array.from(d.x), Array.from(d.y)];")
        ok = table.ok_mask()
        np.testing.assert_allclose(shown[0], table.values("b.x")[ok])
        np.testing.assert_allclose(shown[1], table.values("b.y")[ok])
        # the standard deviation instead: small at the simulated designs' cells
        sigma = model.predict(np.c_[gx.ravel(), gy.ravel()])[1]
        page(browser, "doc.get_model_by_name('surrogate-what').value = 'std'; return null;")
        std = np.array(B.wait_for(browser, "const d = doc.get_model_by_name('surrogate-image').data.image[0]; "
                                           f"return doc.is_idle && Math.abs(d[0] - {float(sigma[0])!r}) < 1e-12 ? "
                                           "Array.from(d) : null;"))
        np.testing.assert_allclose(std, sigma, rtol=1e-12, atol=1e-12)
        assert sigma.max() > 10 * sigma.min()  # sure near the designs, unsure between them

        # a click on the map picks a design: its prediction is listed; simulate here adds the simulated row
        B.click_point(browser, 1.0, 0.0, figure="surrogate-map")
        picked = B.wait_for(browser, "const t = doc.get_model_by_name('surrogate-pick-text').text; "
                                     "return t.includes('Picked design') ? t : null;")
        assert "f1:" in picked and "f2:" in picked
        pick = page(browser, "const d = doc.get_model_by_name('surrogate-pick').data; return [d.x[0], d.y[0]];")
        assert abs(pick[0] - 1.0) < 0.05 and abs(pick[1]) < 0.05
        B.click_widget(browser, "simulate-here")
        status = B.wait_for(browser, "const t = doc.get_model_by_name('simulate-status').text; "
                                     "return t.includes('added design') || t.includes('failed') ? t : null;")
        assert "failed" not in status, status
        count = B.wait_for(browser, f"const t = doc.get_model_by_name('count').text; "
                                    f"return t.includes('of {n + 1} designs') ? t : null;")
        assert count
        after = load_results(folder)
        assert len(after.df) == n + 1
        new = after.df.iloc[-1]
        assert abs(new["b.x"] - pick[0]) < 1e-9 and abs(new["b.y"] - pick[1]) < 1e-9
        assert new["status"] == "ok" and new["worker"] == "room: simulate here"
        assert new["f1"] == pytest.approx(pick[0] ** 2 + pick[1] ** 2, rel=1e-12)
        assert new["f2"] == pytest.approx((pick[0] - 2) ** 2 + pick[1] ** 2, rel=1e-12)
        # the new design is drawn among the simulated ones
        xs_shown = page(browser, "return Array.from(doc.get_model_by_name('surrogate-designs').data.x);")
        assert len(xs_shown) == int(after.ok_mask().sum())
    finally:
        server.stop()
