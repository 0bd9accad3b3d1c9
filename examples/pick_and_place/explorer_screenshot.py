"""Screenshots of `cosim explore` on the full study, for the README.

Starts a private Xvfb screen, opens the explorer on study/ (the full study) with
x = q2[2], y = q2[4], colour = total energy, narrows the execution-time slider
to the faster half (the slower designs turn grey), selects the least-energy
design, re-runs it and lets the arm animation run; then saves the screen as
explorer.png in ``--out`` (default ``results/pick_and_place/`` at the repository's root, which git ignores;
``--out examples/pick_and_place/figures`` refreshes the README's picture).  Needs Debian's xvfb package.

    python examples/pick_and_place/explorer_screenshot.py
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import matplotlib.image
import numpy as np

HERE = Path(__file__).resolve().parent
OUT = HERE.parents[1] / "results" / HERE.name  # git-ignored: running the example leaves the tracked tree as it was


def start_xvfb(fbdir: Path) -> tuple[subprocess.Popen, str]:
    number = next(n for n in range(90, 200) if not Path(f"/tmp/.X11-unix/X{n}").exists()
                  and not Path(f"/tmp/.X{n}-lock").exists())
    proc = subprocess.Popen(["Xvfb", f":{number}", "-screen", "0", "2300x1000x24", "-nolisten", "tcp",
                             "-fbdir", str(fbdir)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    while not Path(f"/tmp/.X11-unix/X{number}").exists():
        time.sleep(0.05)
    return proc, f":{number}"


def pump(root, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        root.update()
        time.sleep(0.01)


def main() -> None:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=OUT, help=f"folder of explorer.png (default: {OUT})")
    folder = parser.parse_args().out
    folder.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as fbdir:
        xvfb, display = start_xvfb(Path(fbdir))
        os.environ["DISPLAY"] = display
        try:
            import tkinter as tk

            from cosim.analysis.explorer import ExplorerState, ExplorerWindow
            sys.path.insert(0, str(HERE.parent.parent))  # the repository: the frame-buffer decoder is a test tool
            from tests.helpers.xwd import xwd_to_rgb

            from cosim.analysis.table import load_results

            table = load_results(HERE / "study")
            root = tk.Tk()
            root.geometry("1000x980+0+0")
            window = ExplorerWindow(root, ExplorerState(table), spec_path=str(HERE / "spec.json"))
            for which, column in (("x", "traj.waypoints[9]"), ("y", "traj.waypoints[11]"), ("color", "e_total")):
                window.choosers[which].set(column)
                window.on_axis(which, column)
            lo, hi, _, _ = window.sliders["duration"]
            hi.set(int(hi.cget("to")) // 2)  # keep the faster half of the designs coloured
            window.on_slider("duration")
            energy = table.values("e_total")
            window.state.select(int(np.nanargmin(energy)))
            window.redraw()
            pump(root, 1.0)
            window.on_rerun()
            for trace_window in window.trace_windows:  # beside the explorer, not over it
                trace_window.geometry("+1010+0")
            pump(root, 6.0)  # the arm animation runs
            image = xwd_to_rgb(Path(fbdir) / "Xvfb_screen0")
            out = folder / "explorer.png"
            height, width = image.shape[:2]
            right = max(int(np.flatnonzero(image.reshape(height, width, 3).any(axis=2).any(axis=0))[-1]) + 1, 1000)
            matplotlib.image.imsave(out, image[:, :right])
            print(f"wrote {out}; status: {window.status.cget('text')}")
            root.destroy()
        finally:
            xvfb.terminate()
            xvfb.wait(timeout=10)


if __name__ == "__main__":
    main()
