"""The screenshots of docs/decision-room.md: the walk through the pick-and-place study, in headless chromium.

    python docs/decision_room_screenshots.py [--out docs/figures]

Serves examples/pick_and_place/study (with examples/pick_and_place/spec.json for the re-runs) as
``cosim explore`` does, and does in the page what the walk through says: narrows duration to the faster
designs, ranks by e_total, duration and the shoulder's torque peak with TOPSIS, selects the three best designs,
pins them to the shortlist and re-runs them there, re-runs them in the Selection tab; one screenshot per tab,
one of the shortlist (room-shortlist.png) and one of the re-run designs' 3-D arm view (room-arm.png).  Then the
Study tab of the optimisation examples/pick_and_place_free_pose/results_optimize (room-study-optimisation.png).
Needs Debian's chromium and chromium-driver and selenium.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
STUDY = REPO / "examples" / "pick_and_place" / "study"
SPEC = REPO / "examples" / "pick_and_place" / "spec.json"
OPTIMISATION = REPO / "examples" / "pick_and_place_free_pose" / "results_optimize"


def main() -> None:
    from cosim.analysis.room import browser as B
    from cosim.analysis.room.data import Study
    from cosim.analysis.room.server import RoomServer
    from cosim.analysis.table import load_results

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(REPO / "docs" / "figures"))
    out = Path(parser.parse_args().out)
    out.mkdir(parents=True, exist_ok=True)
    server = RoomServer(Study(load_results(STUDY, SPEC), spec_path=str(SPEC)))
    browser = B.chromium(1500, 1050)
    try:
        text, seconds = B.load(browser, server.link)
        print(f"loaded in {seconds:.1f} s: {text}", flush=True)
        B.set_filter(browser, "duration", 1.589, 1.75)
        B.set_and_wait(browser, "choose-colour", "value", "duration",
                       "return doc.get_model_by_name('choose-colour').value;")
        B.show_tab(browser, 1)  # the Decide tab is built when first shown
        B.set_and_wait(browser, "minimise", "value", ["e_total", "duration", "peak_tau_ratio[2]"], B.RANKING_SCORES)
        B.set_and_wait(browser, "method", "value", "topsis", B.RANKING_SCORES)
        B.set_and_wait(browser, "weight:duration", "value", 0.5, B.RANKING_SCORES)
        print("best:", browser.execute_script("const d = Bokeh.documents[0].get_model_by_name('ranking').source.data;"
                                              "return [Array.from(d.point_id).slice(0, 3), Array.from(d.score)"
                                              ".slice(0, 3), Array.from(d.o0).slice(0, 3), Array.from(d.o1)"
                                              ".slice(0, 3), Array.from(d.o2).slice(0, 3)];"))
        rows = browser.execute_script("return Array.from(Bokeh.documents[0].get_model_by_name('ranking')"
                                      ".source.data.row).slice(0, 3);")
        B.show_tab(browser, 0)
        browser.execute_script(f"Bokeh.documents[0].get_model_by_name('cloud-source').selected.indices = {rows};")
        B.wait_for(browser, "return Array.from(doc.get_model_by_name('show-selected').booleans).filter(Boolean)"
                            ".length === 3;")
        time.sleep(1.0)
        browser.save_screenshot(str(out / "room-points.png"))
        B.show_tab(browser, 1)
        time.sleep(1.0)
        browser.save_screenshot(str(out / "room-decide.png"))
        # the three pinned to the shortlist, compared side by side and re-run there (their traces overlaid)
        B.click_widget(browser, "pin")
        B.wait_for(browser, "return doc.is_idle && doc.get_model_by_name('shortlist').columns.length === 5;")
        B.click_widget(browser, "rerun-shortlist")
        status = B.wait_for(browser, "const t = doc.get_model_by_name('shortlist-status').text; "
                                     "return doc.get_model_by_name('shortlist-traces').children.length || "
                                     "t.includes('failed') ? t : null;")
        print(f"shortlist re-run: {status}")
        print(f"the view's link: {browser.current_url.split('&', 1)[1]}")
        time.sleep(1.5)
        browser.execute_script("Bokeh.index.find_one(Bokeh.documents[0].get_model_by_name('shortlist-box')).el"
                               ".scrollIntoView({block: 'start'});")
        time.sleep(1.0)
        browser.save_screenshot(str(out / "room-shortlist.png"))
        B.show_tab(browser, 2)
        B.click_widget(browser, "rerun")
        status = B.wait_for(browser, "const t = doc.get_model_by_name('rerun-status').text; "
                                     "return doc.get_model_by_name('traces').children.length || t.includes('failed')"
                                     " ? t : null;")
        print(f"re-run: {status}")
        time.sleep(1.5)
        browser.save_screenshot(str(out / "room-selection.png"))
        # the 3-D view of the arms (the Panda's trace viewer, cosim.models.panda_viewer) at 0.8 s, turned a little
        B.set_and_wait(browser, "arm-time", "value", 0.8,
                       "return doc.get_model_by_name('arm-time').value === 0.8 && doc.is_idle;")
        B.set_and_wait(browser, "arm-azimuth", "value", -0.9,
                       "return doc.get_model_by_name('arm-azimuth').value === -0.9 && doc.is_idle;")
        browser.execute_script("Bokeh.index.find_one(Bokeh.documents[0].get_model_by_name('arm-box')).el"
                               ".scrollIntoView({block: 'center'});")
        time.sleep(1.0)
        browser.save_screenshot(str(out / "room-arm.png"))
        B.show_tab(browser, 4)
        B.set_and_wait(browser, "azimuth", "value", 0.9,
                       "return Bokeh.documents[0].get_model_by_name('scatter3d-source').data.px[0];")
        time.sleep(1.5)
        browser.save_screenshot(str(out / "room-dimensions.png"))
    finally:
        browser.quit()
        server.stop()
    # the Study tab of an optimisation: examples/pick_and_place_free_pose/results_optimize (cosim optimize, TPE)
    server = RoomServer(Study(load_results(OPTIMISATION)))
    browser = B.chromium(1100, 2700)
    try:
        B.load(browser, server.link)
        B.show_tab(browser, 3)
        B.wait_for(browser, "return doc.is_idle && doc.get_model_by_name('contour') !== null;")
        time.sleep(1.5)
        browser.save_screenshot(str(out / "room-study-optimisation.png"))
    finally:
        browser.quit()
        server.stop()
    names = ("points", "decide", "shortlist", "selection", "arm", "dimensions", "study-optimisation")
    print(f"written: {', '.join(str(out / f'room-{n}.png') for n in names)}")


if __name__ == "__main__":
    main()
