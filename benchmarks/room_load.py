"""Load and filter times of the decision room (`cosim explore`) in Debian's headless chromium.

    python benchmarks/room_load.py [--repeat 3] [--rows 17061,1000000] [--json out.jsonl]

For each table: the room is served in this process (cosim.analysis.room.server.RoomServer), a fresh
chromium page opens it (a new session each time: the server builds the tab's document, sends it, the
browser draws it), then a range filter on the first design parameter is narrowed to its upper half (the server
recomputes the filters, the Pareto front, the ranking and the histogram and the page redraws) and a weight is
set to 0 (the ranking is recomputed and redrawn; the study is ranked by e_total and duration, its spec giving
e_total alone a sense).  Times are from the browser's request (or the property set
in the page) until the page has the server's answer and has drawn two frames after it; ``load_cpu_s`` is the CPU
time a load took in this process (the server) and in chromium's processes, what it costs on a machine however
loaded.

Tables: 17061 is the committed pick-and-place study (examples/pick_and_place/study); any other number is a
synthetic table of that many rows (two parameters, two objectives, 2 % failed rows with a message, seed 0),
written to a temporary parquet file with a metadata.json giving the objectives' senses.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
STUDY = REPO / "examples" / "pick_and_place" / "study"


def synthetic(rows: int, folder: Path) -> Path:
    rng = np.random.default_rng(0)
    a, b = rng.uniform(0, 100, rows), rng.uniform(-1, 1, rows)
    df = pd.DataFrame({"point_id": [f"{i:08x}" for i in range(rows)], "p.a": a, "p.b": b,
                       "energy": 50 + 0.5 * a + 10 * b ** 2 + rng.normal(0, 5, rows),
                       "duration": 3 - 0.02 * a + rng.normal(0, 0.2, rows), "status": "ok", "message": ""})
    failed = rng.random(rows) < 0.02
    df.loc[failed, ["energy", "duration"]] = np.nan
    df.loc[failed, "status"], df.loc[failed, "message"] = "failed", "synthetic failure"
    folder.mkdir(parents=True, exist_ok=True)
    df.to_parquet(folder / "results.parquet", index=False)
    spec = {"name": f"synthetic_{rows}", "objectives": {"energy": {"sense": "minimize"},
                                                       "duration": {"sense": "minimize"}},
            "design": {"parameters": {"p.a": {"min": 0, "max": 100}, "p.b": {"min": -1, "max": 1}}}}
    (folder / "metadata.json").write_text(json.dumps({"spec": spec}))
    return folder


def cpu_seconds(browser) -> float:
    """CPU seconds used so far by this process (the server and selenium) and by chromium's processes: what a
    load costs whatever else the machine runs."""
    import psutil

    def used(proc: psutil.Process) -> float:
        try:
            t = proc.cpu_times()
            return t.user + t.system + t.children_user + t.children_system
        except psutil.NoSuchProcess:
            return 0.0

    driver = psutil.Process(browser.service.process.pid)
    return used(psutil.Process()) + sum(used(p) for p in [driver, *driver.children(recursive=True)])


def measure(folder: Path, repeat: int) -> dict:
    from cosim.analysis.room import browser as B
    from cosim.analysis.room.data import Study
    from cosim.analysis.room.server import RoomServer
    from cosim.analysis.table import load_results

    start = time.perf_counter()
    table = load_results(folder)
    read_s = time.perf_counter() - start
    server = RoomServer(Study(table))
    column = table.parameter_columns()[0]
    values = table.values(column)
    lo, hi = float(np.nanmin(values)), float(np.nanmax(values))
    out: dict = {"rows": len(table.df), "table_read_s": round(read_s, 3), "load_s": [], "filter_s": [],
                 "decide_tab_s": [], "reweight_s": [], "load_cpu_s": []}
    browser = B.chromium()
    try:
        for _ in range(repeat):
            cpu = cpu_seconds(browser)
            _, seconds = B.load(browser, server.link)
            out["load_s"].append(round(seconds, 3))
            out["load_cpu_s"].append(round(cpu_seconds(browser) - cpu, 3))
            _, seconds = B.set_filter(browser, column, (lo + hi) / 2, hi)
            out["filter_s"].append(round(seconds, 3))
            start = time.perf_counter()
            B.show_tab(browser, 1)  # the Decide tab is built when first shown
            out["decide_tab_s"].append(round(time.perf_counter() - start, 3))
            weights = browser.execute_script("return Bokeh.documents[0].get_model_by_name('weights')"
                                             ".children.map((s) => s.name);")
            if len(weights) < 2:  # the study's spec gives e_total alone a sense: rank by time too, as the docs do
                B.set_and_wait(browser, "minimise", "value", ["e_total", "duration"], B.RANKING_SCORES)
            first = browser.execute_script("return Bokeh.documents[0].get_model_by_name('weights')"
                                           ".children[0].name;")
            _, seconds = B.set_and_wait(browser, first, "value", 0.0, B.RANKING_SCORES)
            out["reweight_s"].append(round(seconds, 3))
    finally:
        browser.quit()
        server.stop()
    for key in ("load_s", "load_cpu_s", "filter_s", "decide_tab_s", "reweight_s"):
        out[key.replace("_s", "_median_s")] = round(statistics.median(out[key]), 3)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", default="17061,1000000", help="tables: 17061 (the study) or synthetic sizes")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--json", help="append each result as a JSON line to this file")
    args = parser.parse_args()
    print(f"# {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
          f"load {os.getloadavg()[0]:.2f} at {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}", flush=True)
    with tempfile.TemporaryDirectory() as scratch:
        for rows in (int(r) for r in args.rows.split(",")):
            folder = STUDY if rows == 17061 else synthetic(rows, Path(scratch) / str(rows))
            result = measure(folder, args.repeat)
            result["load_average_after"] = round(os.getloadavg()[0], 2)
            print(json.dumps(result), flush=True)
            if args.json:
                with open(args.json, "a") as f:
                    f.write(json.dumps(result) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
