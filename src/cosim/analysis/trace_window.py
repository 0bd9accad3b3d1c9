"""The Tk explorer's window of one re-run: a Toplevel that holds what it shows.

Imported by :meth:`cosim.analysis.explorer.ExplorerWindow.show_traces` only (it imports tkinter, which a
headless ``cosim report`` never needs).
"""

from __future__ import annotations

import tkinter as tk
from typing import Any

from matplotlib.backends.backend_tkagg import FigureCanvasTkAgg
from matplotlib.figure import Figure


class TraceWindow(tk.Toplevel):
    """A window over the explorer's root with the run's traces: ``figure`` drawn by ``canvas``; ``animation``
    and its ``arm_figure`` when the traces' viewer animates them (None otherwise).

    They are attributes of the window so that they live as long as it does: a matplotlib animation nobody
    refers to stops.
    """

    figure: Figure
    canvas: FigureCanvasTkAgg
    animation: Any = None  # the viewer's animation (cosim.analysis.traces.animation: a matplotlib Animation)
    arm_figure: Figure | None = None
