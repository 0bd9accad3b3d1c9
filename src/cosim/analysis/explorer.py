"""``cosim explore``: the interactive point cloud of thesis fig. 6-7, in Tk.

:class:`ExplorerState` holds everything the window shows and decides — the
axes and colour columns, the range of every column, which rows are greyed,
the selected row — as a plain class testable without a window.
:class:`ExplorerWindow` is the thin Tk view: it turns widget events into
state calls and redraws.

The window: on top, choosers for x, y, optional z and colour, "Re-run
selected" and "Save figure" buttons, the plot with matplotlib's toolbar; below,
one row per numeric column with two sliders (lower and upper end of its
range; points outside are greyed), the range and, in red, the selected
row's value.  Clicking a point selects the nearest drawn point (within 12
pixels).  A re-run opens a window with the run's traces, shown by the trace
viewer that recognises them (:mod:`cosim.analysis.viewers`; e.g. the Panda
arm's panels and stick-figure animation), else one panel per port.  It runs in the window's
own thread (a design run takes a fraction of a second to seconds; the window
is busy meanwhile): Tk objects must never be touched, nor garbage-collected,
in another thread.
"""

from __future__ import annotations

import functools
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any, Iterator

import numpy as np

from cosim.analysis.filters import Range, RangeFilters
from cosim.analysis.table import AnalysisError, ResultsTable

if TYPE_CHECKING:  # tkinter and matplotlib are imported when a window opens
    from matplotlib.axes import Axes

    from cosim.analysis.trace_window import TraceWindow

SLIDER_STEPS = 1000  # sliders move over 0..1000; 0 and 1000 are exactly the column's min and max


class ExplorerState:
    """What the explorer shows, without any window.

    ``bounds`` are each numeric column's finite min and max; ``ranges`` the
    user's narrowed ranges.  A row is *active* (coloured) when every column
    whose range is narrowed has a value inside it (a missing value is outside);
    it is *drawable* when its x, y (and z) values exist.
    """

    def __init__(self, table: ResultsTable):
        self.table = table
        self.filters = RangeFilters(table)  # shared with the decision room (cosim.analysis.decision)
        self.columns = self.filters.columns
        if len(self.columns) < 2:
            raise AnalysisError(f"{table.path}: the explorer needs at least two numeric columns")
        self.bounds: dict[str, Range] = self.filters.bounds
        params = [c for c in table.parameter_columns() if c in self.bounds]
        objectives = [c for c in table.objective_columns() if c in self.bounds]
        axes = (params + objectives + self.columns)
        self.x = axes[0]
        self.y = next(c for c in axes if c != self.x)
        self.z: str | None = None
        self.color: str | None = objectives[0] if objectives and objectives[0] not in (self.x, self.y) else None
        self.selected: int | None = None

    # -- choices ----------------------------------------------------------------
    def set_axis(self, which: str, column: str | None) -> None:
        """Set 'x', 'y', 'z' or 'color' to a numeric column ('' or None clears z and colour)."""
        if which not in ("x", "y", "z", "color"):
            raise ValueError(f"unknown axis '{which}'")
        if not column:
            if which in ("x", "y"):
                raise AnalysisError(f"the {which} axis needs a column")
            column = None
        else:
            self.table.check_column(column)
        setattr(self, which, column)

    @property
    def ranges(self) -> dict[str, Range]:
        return self.filters.ranges

    def set_range(self, column: str, lo: float, hi: float) -> None:
        """Narrow (or widen) ``column`` to [lo, hi], clipped to its bounds; lo > hi swaps them."""
        self.filters.set_range(column, lo, hi)

    def set_range_steps(self, column: str, lo_step: int, hi_step: int) -> None:
        """Set a range from slider positions 0..SLIDER_STEPS (the ends are exactly min and max)."""
        self.set_range(column, self.step_value(column, lo_step), self.step_value(column, hi_step))

    def step_value(self, column: str, step: int) -> float:
        b = self.bounds[column]
        step = int(np.clip(step, 0, SLIDER_STEPS))
        if step == SLIDER_STEPS:
            return b.hi
        return b.lo + (b.hi - b.lo) * step / SLIDER_STEPS

    def reset_ranges(self) -> None:
        self.filters.reset()

    def narrowed(self) -> list[str]:
        """Columns whose range is narrower than their bounds."""
        return self.filters.narrowed()

    # -- derived sets -------------------------------------------------------------
    def active(self) -> np.ndarray:
        """Rows inside every narrowed range."""
        return self.filters.active()

    def drawable(self) -> np.ndarray:
        cols = [c for c in (self.x, self.y, self.z) if c]
        return np.all([np.isfinite(self.filters.values(c)) for c in cols], axis=0)

    def greyed(self) -> np.ndarray:
        """Positions of drawn rows shown grey."""
        return np.flatnonzero(self.drawable() & ~self.active())

    def coloured(self) -> np.ndarray:
        """Positions of drawn rows shown in colour."""
        return np.flatnonzero(self.drawable() & self.active())

    # -- selection ----------------------------------------------------------------
    def pick(self, screen: np.ndarray, rows: np.ndarray, click: tuple[float, float], radius: float = 12.0) -> int | None:
        """Select the row nearest to ``click`` among ``rows`` drawn at ``screen`` (n x 2 pixels).

        Returns the selected row, or None (selection unchanged) when no point
        lies within ``radius`` pixels.
        """
        if len(rows) == 0:
            return None
        d = np.hypot(screen[:, 0] - click[0], screen[:, 1] - click[1])
        k = int(np.argmin(d))
        if d[k] > radius:
            return None
        self.selected = int(rows[k])
        return self.selected

    def select(self, row: int | None) -> None:
        if row is not None and not 0 <= row < len(self.table.df):
            raise IndexError(f"row {row} outside 0..{len(self.table.df) - 1}")
        self.selected = row

    def selected_values(self) -> dict[str, Any]:
        """Every value of the selected row ({} when nothing is selected)."""
        return {} if self.selected is None else self.table.row(self.selected)


# ---------------------------------------------------------------------------------------------------------------
# The Tk view


class ExplorerWindow:
    """The Tk window over an :class:`ExplorerState` (see the module docstring)."""

    def __init__(self, root, state: ExplorerState, spec_path: str | None = None):
        import tkinter as tk
        from tkinter import ttk

        from matplotlib.backends.backend_tkagg import FigureCanvasTkAgg, NavigationToolbar2Tk
        from matplotlib.figure import Figure

        self.root, self.state, self.spec_path = root, state, spec_path
        self.tk = tk
        self.ax: Axes | None = None  # the cloud's axes, once drawn (redraw, at the end of __init__)
        self._drawn_rows = np.zeros(0, dtype=int)
        self._pending: Any = None
        self.trace_windows: list[TraceWindow] = []
        root.title(f"cosim explore: {state.table.path}")
        top = ttk.Frame(root)
        top.pack(side="top", fill="both", expand=True)
        bar = ttk.Frame(top)
        bar.pack(side="top", fill="x")
        self.choosers: dict[str, Any] = {}
        for which in ("x", "y", "z", "color"):
            ttk.Label(bar, text=f"{which}:").pack(side="left", padx=(8, 2))
            options = state.columns if which in ("x", "y") else [""] + state.columns
            box = ttk.Combobox(bar, values=options, state="readonly", width=18)
            box.set(getattr(state, which) or "")
            box.bind("<<ComboboxSelected>>", functools.partial(self._on_chooser, which))
            box.pack(side="left")
            self.choosers[which] = box
        ttk.Button(bar, text="Save figure…", command=self.on_save).pack(side="right", padx=4)
        self.reset_button = ttk.Button(bar, text="Reset ranges", command=self.on_reset)
        self.reset_button.pack(side="right", padx=4)
        self.rerun_button = ttk.Button(bar, text="Re-run selected", command=self.on_rerun)
        self.rerun_button.pack(side="right", padx=4)
        self.status = ttk.Label(top, text="")
        self.status.pack(side="bottom", fill="x")

        self.figure = Figure(figsize=(8, 5), dpi=100)
        self.canvas = FigureCanvasTkAgg(self.figure, master=top)
        self.toolbar = NavigationToolbar2Tk(self.canvas, top, pack_toolbar=False)
        self.toolbar.pack(side="bottom", fill="x")
        self.canvas.get_tk_widget().pack(side="top", fill="both", expand=True)
        self.canvas.mpl_connect("button_press_event", self.on_click)

        self.sliders: dict[str, tuple[Any, Any, Any, Any]] = {}
        self._build_sliders(root)
        self.redraw()

    def _build_sliders(self, root) -> None:
        tk = self.tk
        from tkinter import ttk

        outer = ttk.Frame(root)
        outer.pack(side="bottom", fill="x")
        canvas = tk.Canvas(outer, height=min(34 * len(self.state.columns), 240), highlightthickness=0)
        scroll = ttk.Scrollbar(outer, orient="vertical", command=canvas.yview)
        inner = ttk.Frame(canvas)
        inner.bind("<Configure>", lambda e: canvas.configure(scrollregion=canvas.bbox("all")))
        canvas.create_window((0, 0), window=inner, anchor="nw")
        canvas.configure(yscrollcommand=scroll.set)
        canvas.pack(side="left", fill="both", expand=True)
        scroll.pack(side="right", fill="y")
        for sequence, units in (("<Button-4>", -1), ("<Button-5>", 1)):  # the mouse wheel on X11
            canvas.bind_all(sequence, lambda e, u=units: canvas.yview_scroll(u, "units")
                            if str(e.widget).startswith(str(outer)) else None)
        for i, c in enumerate(self.state.columns):
            ttk.Label(inner, text=self.state.table.label(c), width=28, anchor="w").grid(row=i, column=0, sticky="w")
            lo = tk.Scale(inner, from_=0, to=SLIDER_STEPS, orient="horizontal", showvalue=0, length=160,
                          command=lambda v, col=c: self.on_slider(col))
            hi = tk.Scale(inner, from_=0, to=SLIDER_STEPS, orient="horizontal", showvalue=0, length=160,
                          command=lambda v, col=c: self.on_slider(col))
            hi.set(SLIDER_STEPS)
            lo.grid(row=i, column=1)
            hi.grid(row=i, column=2)
            shown = ttk.Label(inner, width=24, anchor="w")
            shown.grid(row=i, column=3, sticky="w")
            value = tk.Label(inner, fg="red", width=14, anchor="w")
            value.grid(row=i, column=4, sticky="w")
            self.sliders[c] = (lo, hi, shown, value)
            self._show_range(c)

    # -- handlers (what the widgets call) ---------------------------------------------
    def _on_chooser(self, which: str, event: object) -> None:
        self.on_axis(which, self.choosers[which].get())

    def on_axis(self, which: str, column: str) -> None:
        try:
            self.state.set_axis(which, column)
        except AnalysisError as exc:
            self.status.configure(text=str(exc))
            return
        self.redraw()

    def on_slider(self, column: str) -> None:
        lo, hi, _, _ = self.sliders[column]
        self.state.set_range_steps(column, int(lo.get()), int(hi.get()))
        self._show_range(column)
        if self._pending is None:  # redraw once after a burst of slider moves
            self._pending = self.root.after_idle(self._redraw_pending)

    def on_reset(self) -> None:
        """Every slider back to its column's full range."""
        self.state.reset_ranges()
        for c, (lo, hi, _, _) in self.sliders.items():
            lo.set(0)
            hi.set(SLIDER_STEPS)
            self._show_range(c)
        self.redraw()

    def _redraw_pending(self) -> None:
        self._pending = None
        self.redraw()

    def on_click(self, event) -> None:
        if event.inaxes is None or event.inaxes is not self.ax or self.toolbar.mode:
            return
        rows = self._drawn_rows
        screen = self._screen_positions(rows)
        if self.state.pick(screen, rows, (event.x, event.y)) is not None:
            self.redraw()

    def on_rerun(self) -> None:
        """Run the selected design again, in this thread (see the module docstring), and show its traces."""
        from cosim.analysis.rerun import rerun

        row = self.state.selected
        if row is None:
            self.status.configure(text="select a point first (click it)")
            return
        self.status.configure(text=f"re-running row {row} …")
        self.root.configure(cursor="watch")
        self.root.update_idletasks()
        try:
            result, _ = rerun(self.state.table, row, self.spec_path)
        except Exception as exc:  # a bad spec or value is shown in the window, never a crash of the GUI
            self.status.configure(text=f"re-run failed: {str(exc).splitlines()[0] if str(exc) else exc!r}")
            return
        finally:
            self.root.configure(cursor="")
        self.status.configure(text=f"row {row}: {result.status} in {result.elapsed:.2f} s {result.message}")
        self.show_traces(row, result)

    def on_save(self) -> None:
        from tkinter import filedialog

        path = filedialog.asksaveasfilename(defaultextension=".png",
                                            filetypes=[("PNG", "*.png"), ("SVG", "*.svg"), ("PDF", "*.pdf")])
        if path:
            self.save_figure(path)

    # -- drawing -------------------------------------------------------------------
    def save_figure(self, path: str) -> None:
        self.figure.savefig(path, bbox_inches="tight")
        self.status.configure(text=f"saved {path}")

    def redraw(self) -> None:
        from cosim.analysis.plots import scatter_cloud

        s = self.state
        self.ax, counts = scatter_cloud(self.figure, s.table, s.x, s.y, s.z, s.color, active=s.active(),
                                        selected=s.selected)
        self._drawn_rows = np.flatnonzero(s.drawable())
        self.canvas.draw_idle()
        self._show_selection()
        self.status.configure(text=f"{counts.coloured} coloured, {counts.greyed} greyed"
                                   + (f", {counts.missing} without a value" if counts.missing else ""))

    def _screen_positions(self, rows: np.ndarray) -> np.ndarray:
        from mpl_toolkits.mplot3d import Axes3D, proj3d

        s, ax = self.state, self.ax
        if ax is None:
            raise RuntimeError("the cloud is not drawn yet")  # __init__ draws it before any event
        xs, ys = s.table.values(s.x)[rows], s.table.values(s.y)[rows]
        if s.z and isinstance(ax, Axes3D):  # a cloud with z is drawn in 3-D (plots.scatter_cloud)
            zs = s.table.values(s.z)[rows]
            px, py, _ = proj3d.proj_transform(xs, ys, zs, ax.get_proj())
            return ax.transData.transform(np.column_stack([px, py]))
        return ax.transData.transform(np.column_stack([xs, ys]))

    def screen_position(self, row: int) -> tuple[float, float]:
        """Where row ``row`` is drawn, in matplotlib display pixels (origin bottom left)."""
        self.canvas.draw()
        x, y = self._screen_positions(np.array([row]))[0]
        return float(x), float(y)

    def _show_range(self, column: str) -> None:
        r = self.state.ranges[column]
        self.sliders[column][2].configure(text=f"{r.lo:.6g} … {r.hi:.6g}")

    def _show_selection(self) -> None:
        values = self.state.selected_values()
        for c, (_, _, _, label) in self.sliders.items():
            v = values.get(c)
            label.configure(text="" if v is None else f"{v:.6g}" if isinstance(v, (float, np.floating)) else str(v))

    def show_traces(self, row: int, result: Any) -> TraceWindow:
        """A window with the run's traces and, when their viewer has one, its animation; returns the Toplevel."""
        from matplotlib.backends.backend_tkagg import FigureCanvasTkAgg
        from matplotlib.figure import Figure

        from cosim.analysis.trace_window import TraceWindow
        from cosim.analysis.traces import animation, traces_figure

        win = TraceWindow(self.root)
        pid = self.state.table.df["point_id"].iloc[row] if "point_id" in self.state.table.df.columns else row
        win.title(f"run of {pid}: {result.status}")
        fig = Figure(figsize=(7, 6), dpi=100)
        if result.traces is not None and len(result.traces):
            traces_figure(fig, result.traces, title=f"{pid}")
        canvas = FigureCanvasTkAgg(fig, master=win)
        canvas.get_tk_widget().pack(side="left", fill="both", expand=True)
        win.figure, win.canvas, win.animation = fig, canvas, None
        if result.traces is not None:
            try:
                arm_fig = Figure(figsize=(5, 5), dpi=100)
                arm_canvas = FigureCanvasTkAgg(arm_fig, master=win)
                anim = animation(arm_fig, result.traces)  # e.g. the Panda viewer's arm (cosim.models.panda_viewer)
                if anim is not None:
                    arm_canvas.get_tk_widget().pack(side="right", fill="both", expand=True)
                    win.arm_figure, win.animation = arm_fig, anim  # keep the animation alive
                    arm_canvas.draw_idle()  # its first draw starts the animation's timer
            except Exception as exc:  # e.g. no pinocchio model: traces alone are still useful
                self.status.configure(text=f"no animation: {exc}")
        canvas.draw_idle()
        self.trace_windows.append(win)
        return win


def run_explorer(table: ResultsTable) -> None:
    """Open the window and run the Tk main loop until it is closed or the process is told to stop.

    Raises AnalysisError without a display.  Ctrl-C, SIGTERM and SIGHUP close every window and raise
    KeyboardInterrupt (``cosim explore --tk`` then says ``cosim: interrupted`` and exits 130), also while an
    arm animation runs or a re-run is under way, and without a traceback: see :func:`_stop_on_signals`.
    """
    import tkinter as tk

    state = ExplorerState(table)
    try:
        root = tk.Tk()
    except tk.TclError as exc:
        raise AnalysisError(f"cannot open a window ({exc}); set DISPLAY, or use cosim plot/report") from None
    ExplorerWindow(root, state)
    with _stop_on_signals(root) as stopped:
        try:
            root.mainloop()
        except KeyboardInterrupt:  # the signal came while Tk itself was waiting, not inside a callback
            stopped.append("interrupted")
        if stopped:
            root.destroy()
    if stopped:
        raise KeyboardInterrupt


SIGNAL_CHECK_MS = 100  # how often the main loop wakes to let Python run its signal handlers


@contextmanager
def _stop_on_signals(root: Any) -> Iterator[list]:
    """While the block runs, SIGINT, SIGTERM and SIGHUP end ``root``'s main loop; yields the list of signals seen.

    Tk runs Python code (a timer of the arm animation, a re-run) inside callbacks, and tkinter prints a
    traceback for whatever a callback raises, KeyboardInterrupt included, and goes on: a Ctrl-C during the
    animation printed a traceback per press and the window stayed.  So the handler asks the loop to end
    (``root.quit``) before it raises, and a KeyboardInterrupt reaching Tk's report of callback errors is kept
    silent.  The raise leaves a long callback (a re-run) at once.  A threaded Tcl waits in C between events
    and would run the handler only at the next event: a timer wakes the loop every SIGNAL_CHECK_MS.  Only in
    the main thread (signal handlers can be set only there); the previous handlers come back afterwards.
    """
    import signal
    import threading

    stopped: list = []
    if threading.current_thread() is not threading.main_thread():
        yield stopped
        return

    def stop(signum: int, frame: Any) -> None:
        first = not stopped
        stopped.append(signum)
        root.quit()
        if first:
            raise KeyboardInterrupt

    report = root.report_callback_exception

    def report_unless_stopping(kind: type, value: BaseException, tb: Any) -> None:
        if not issubclass(kind, KeyboardInterrupt):
            report(kind, value, tb)

    def wake() -> None:
        root.after(SIGNAL_CHECK_MS, wake)

    names = ("SIGINT", "SIGTERM", "SIGHUP")
    previous = {n: signal.signal(n, stop) for n in (getattr(signal, name) for name in names if hasattr(signal, name))}
    root.report_callback_exception = report_unless_stopping
    root.after(SIGNAL_CHECK_MS, wake)
    try:
        yield stopped
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
