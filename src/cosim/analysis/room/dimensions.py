"""The decision room's Dimensions tab: views of several columns at once, over the same filters and selection.

- **scatter matrix** (``matrix:<i>:<j>``, the lower triangle: column i against column j): designs the
  filters keep in blue, the others in grey; a box or lasso in any panel selects designs (as a click in the
  cloud does) and the panels share one source, so a selection shows in all of them;
- **parallel coordinates** (``parallel``): an axis per column, scaled over its bounds; kept designs blue,
  dropped grey, the selection red.  *Brushing*: a box drawn over part of an axis narrows that column's range
  filter to the box's span, so the lines that leave it turn grey here and everywhere else on the page;
- **3-D scatter** (``scatter3d``) of the first three columns, coloured by the cloud's colour column: an
  orthographic projection (:mod:`.projection`) turned with the ``azimuth`` and ``elevation`` sliders or by
  dragging in the plot; the browser re-projects, the server is not asked.  Bokeh has no 3-D glyphs; a
  projection keeps the room on the one plotting library the Dask dashboard uses (no plotly, no WebGL
  toolkit), at the price of no depth cue but the rotation.

Tables of more than :data:`.projection.SAMPLE` rows are drawn from a random sample of that many designs (the
tab says so); the filters, front and ranking still use every row.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from bokeh.core.property.validation import without_property_validation
from bokeh.events import Pan, SelectionGeometry
from bokeh.layouts import column, gridplot, row
from bokeh.models import (
    BooleanFilter,
    BoxSelectTool,
    CDSView,
    ColumnDataSource,
    CustomJS,
    FixedTicker,
    LinearColorMapper,
)
from bokeh.models.widgets import Div, MultiChoice, Slider
from bokeh.palettes import Viridis256
from bokeh.plotting import figure

from cosim.analysis.decision import Decision
from cosim.analysis.room import data as D
from cosim.analysis.room import projection as P
from cosim.analysis.room import views as V
from cosim.analysis.room.views import GREY, PLAIN, SELECTED

MAX_COLUMNS = 6
PANEL = 190  # px of one panel of the scatter matrix
AZIMUTH, ELEVATION = 0.6, 0.4  # radians: the 3-D view's first angle


class Dimensions:
    """The tab's views over ``columns`` (module docstring); ``on_select(rows)`` when the user selects in the
    matrix, ``on_brush(column, lo, hi)`` when a box is drawn over an axis of the parallel coordinates."""

    def __init__(self, study: D.Study, decision: Decision, columns: list[str], colour: str | None,
                 on_select: Callable[[list[int]], None], on_brush: Callable[[str, float, float], None]):
        self.study, self.decision = study, decision
        self.on_select, self.on_brush = on_select, on_brush
        self.rows = P.sample(len(study.ids))
        self.colour = colour
        self.kept = np.ones(len(self.rows), dtype=bool)
        self.selection: list[int] = []
        self.chooser = MultiChoice(title=f"columns (2 to {MAX_COLUMNS}; the first three are the 3-D view's axes)",
                                   value=columns[:MAX_COLUMNS], options=V.choices(decision.filters.columns),
                                   name="dimensions", width=760)
        self.note = Div(text=self._note(), name="dimensions-note", width=760)
        self.layout = column(self.chooser, self.note, name="dimensions-tab")
        self.chooser.on_change("value", lambda attr, old, new: self._build())
        self._build()

    def _note(self) -> str:
        drawn, n = len(self.rows), len(self.study.ids)
        note = f"{drawn} designs drawn" if drawn == n else \
            f"a random sample of {drawn} of the {n} designs drawn (the filters use every design)"
        return (f"<i>{note}; a box over part of an axis of the parallel coordinates narrows its column's range "
                "filter</i>")

    def reload(self, study: D.Study, decision: Decision) -> None:
        """The same folder with more rows (a running study): the sources anew, the views kept (angles too)."""
        self.study, self.decision = study, decision
        self.rows = P.sample(len(study.ids))
        self.kept = np.ones(len(self.rows), dtype=bool)
        self.selection = []
        self.chooser.options = V.choices(decision.filters.columns)
        self.note.text = self._note()
        if len(self.columns) >= 2:
            self.matrix_source.selected.indices = []
            self.matrix_source.data = {f"c{k}": self._values(c) for k, c in enumerate(self.columns)}
        if len(self.columns) >= 3:
            self.source3d.data = self._columns3d(self.azimuth.value, self.elevation.value)

    def _columns3d(self, azimuth: float, elevation: float) -> dict[str, np.ndarray]:
        u, v, w = (P.scaled(self._values(c), *self._bounds(c), to=(-1.0, 1.0)) for c in self.columns[:3])
        px, py = P.project(u, v, w, azimuth, elevation)
        colour = self._values(self.colour) if self.colour else np.full(len(self.rows), np.nan)
        return {"u": u, "v": v, "w": w, "px": px, "py": py, "c": colour}

    # -- building --------------------------------------------------------------------------------------------
    def _values(self, name: str) -> np.ndarray:
        return self.decision.filters.values(name)[self.rows]

    def _bounds(self, name: str) -> tuple[float, float]:
        b = self.decision.filters.bounds[name]
        return b.lo, b.hi

    def _build(self) -> None:
        # the views are put in the layout, which is in the page when the columns change, only with bokeh's
        # property validation back on (see cosim.analysis.room.app.Room.__init__: a field with a transform would
        # be sent as a constant)
        self.layout.children = self._views()

    @without_property_validation
    def _views(self) -> list:
        self.columns = list(self.chooser.value)[:MAX_COLUMNS]
        self.filters = {layer: BooleanFilter(booleans=self.kept if layer == "kept" else ~self.kept,
                                             name=f"dimensions-{layer}") for layer in ("kept", "greyed")}
        parts: list = [self.chooser, self.note]
        if len(self.columns) >= 2:
            parts += [Div(text="<b>scatter matrix</b>"), self._matrix(), Div(text="<b>parallel coordinates</b>"),
                      self._parallel()]
        if len(self.columns) >= 3:
            parts += [Div(text="<b>3-D scatter</b> (drag in the plot, or the sliders, to turn it)"),
                      self._scatter3d()]
        return parts

    def _matrix(self) -> Any:
        self.matrix_source = ColumnDataSource({f"c{k}": self._values(c) for k, c in enumerate(self.columns)},
                                              name="matrix-source")
        self.matrix_source.selected.on_change("indices", self._on_matrix_selection)
        label = self.study.table.label
        grid: list[list[Any]] = []
        for i in range(1, len(self.columns)):
            line: list[Any] = []
            for j in range(len(self.columns) - 1):
                if j >= i:
                    line.append(None)
                    continue
                fig = figure(name=f"matrix:{i}:{j}", width=PANEL, height=PANEL, tools="box_select,lasso_select,reset",
                             x_axis_label=label(self.columns[j]) if i == len(self.columns) - 1 else None,
                             y_axis_label=label(self.columns[i]) if j == 0 else None, min_border=4)
                for layer, colour in (("greyed", GREY), ("kept", PLAIN)):
                    fig.scatter(f"c{j}", f"c{i}", source=self.matrix_source, size=3, color=colour, alpha=0.6,
                                view=CDSView(filter=self.filters[layer]), nonselection_alpha=0.6,
                                selection_color=SELECTED)
                fig.axis.major_label_text_font_size = "7pt"
                line.append(fig)
            grid.append(line)
        return gridplot(grid, toolbar_location="right", merge_tools=True)

    def _parallel(self) -> Any:
        k = len(self.columns)
        self.parallel = {layer: ColumnDataSource({"x": [], "y": []}, name=f"parallel-{layer}")
                         for layer in ("greyed", "kept", "selected")}
        fig = figure(name="parallel", width=760, height=320, x_range=(-0.3, k - 0.7), y_range=(-0.05, 1.05),
                     tools="reset,save", y_axis_label="scaled over each column's range")
        for layer, colour, width, alpha in (("greyed", GREY, 1, 0.3), ("kept", PLAIN, 1, 0.25),
                                            ("selected", SELECTED, 2.5, 1.0)):
            fig.line("x", "y", source=self.parallel[layer], color=colour, line_width=width, alpha=alpha,
                     name=f"parallel-{layer}-lines")
        ends = ColumnDataSource({"x": [*range(k), *range(k)], "y": [0.0] * k + [1.0] * k})
        axes = fig.scatter("x", "y", source=ends, size=1, alpha=0.0)  # what the brush selects in; unseen
        fig.segment(x0=list(range(k)), y0=[0.0] * k, x1=list(range(k)), y1=[1.0] * k, color="#444444",
                    line_width=1.5)
        fig.xaxis.ticker = FixedTicker(ticks=list(range(k)))
        fig.xaxis.major_label_overrides = {i: self.study.table.label(c) for i, c in enumerate(self.columns)}
        fig.xgrid.visible = False
        brush = BoxSelectTool(renderers=[axes], name="parallel-brush")
        fig.add_tools(brush)
        fig.toolbar.active_drag = brush
        fig.on_event(SelectionGeometry, self._on_brush)
        self._draw_parallel()
        return fig

    def _scatter3d(self) -> Any:
        self.source3d = ColumnDataSource(self._columns3d(AZIMUTH, ELEVATION), name="scatter3d-source")
        colour = self.source3d.data["c"]
        ends = P.axes_ends()
        apx, apy = P.project(*(np.array(ends[k]) for k in ("u", "v", "w")), AZIMUTH, ELEVATION)
        label = self.study.table.label
        axes = ColumnDataSource({**ends, "px": apx, "py": apy,
                                 "label": ["", label(self.columns[0]), "", label(self.columns[1]), "",
                                           label(self.columns[2])]}, name="scatter3d-axes")
        fig = figure(name="scatter3d", width=560, height=560, x_range=(-1.9, 1.9), y_range=(-1.9, 1.9),
                     tools="save", match_aspect=True)
        fig.axis.visible = False
        fig.grid.visible = False
        finite = colour[np.isfinite(colour)]
        mapper = LinearColorMapper(palette=Viridis256, nan_color=PLAIN,
                                   low=float(finite.min()) if finite.size else 0.0,
                                   high=float(finite.max()) if finite.size else 1.0)
        fig.scatter("px", "py", source=self.source3d, size=4, color=GREY, alpha=0.4,
                    view=CDSView(filter=self.filters["greyed"]), name="scatter3d-greyed")
        fig.scatter("px", "py", source=self.source3d, size=5, line_color=None, alpha=0.8,
                    fill_color={"field": "c", "transform": mapper}, view=CDSView(filter=self.filters["kept"]),
                    name="scatter3d-kept")
        lines = ColumnDataSource(self._axis_lines(apx, apy), name="scatter3d-lines")  # axis k: ends 2k, 2k + 1
        fig.multi_line(xs="xs", ys="ys", source=lines, color="#444444", line_width=1.5)
        fig.text("px", "py", text="label", source=axes, text_font_size="9pt", text_align="center")
        self.azimuth = azimuth = Slider(title="azimuth [rad]", start=-np.pi, end=np.pi, step=0.01, value=AZIMUTH,
                                        name="azimuth", width=270)
        self.elevation = elevation = Slider(title="elevation [rad]", start=-np.pi / 2, end=np.pi / 2, step=0.01,
                                            value=ELEVATION, name="elevation", width=270)
        project = CustomJS(args={"sources": [self.source3d, axes], "axes": axes, "azimuth": azimuth,
                                 "elevation": elevation, "lines": lines},
                           code=P.PROJECT_JS + """
const ends = axes.data;
lines.data = {xs: [0, 2, 4].map((k) => [ends.px[k], ends.px[k + 1]]),
              ys: [0, 2, 4].map((k) => [ends.py[k], ends.py[k + 1]])};
""")
        azimuth.js_on_change("value", project)
        elevation.js_on_change("value", project)
        fig.js_on_event(Pan, CustomJS(args={"azimuth": azimuth, "elevation": elevation}, code=P.TURN_JS))
        return row(fig, column(azimuth, elevation))

    @staticmethod
    def _axis_lines(px: np.ndarray, py: np.ndarray) -> dict[str, list]:
        return {"xs": [[float(px[k]), float(px[k + 1])] for k in (0, 2, 4)],
                "ys": [[float(py[k]), float(py[k + 1])] for k in (0, 2, 4)]}

    # -- following the page's state ------------------------------------------------------------------------------
    @without_property_validation
    def show(self, masks: dict[str, np.ndarray]) -> None:
        """The filters' masks (:func:`.data.masks`)."""
        self.kept = ~masks["greyed"][self.rows]
        self.filters["kept"].booleans = self.kept
        self.filters["greyed"].booleans = ~self.kept
        if len(self.columns) >= 2:
            self._draw_parallel()

    def show_selection(self, rows: list[int]) -> None:
        self.selection = list(rows)
        if len(self.columns) >= 2:
            self._draw_parallel()

    def _draw_parallel(self) -> None:
        values = [self.decision.filters.values(c) for c in self.columns]
        bounds = [self._bounds(c) for c in self.columns]
        for layer, rows in (("greyed", self.rows[~self.kept]), ("kept", self.rows[self.kept]),
                            ("selected", np.array(self.selection, dtype=np.int64))):
            x, y = P.parallel_lines(values, bounds, rows)
            self.parallel[layer].data = {"x": x, "y": y}

    # -- the user's gestures -------------------------------------------------------------------------------------
    def _on_matrix_selection(self, attr: str, old: Any, new: Any) -> None:
        self.on_select([int(self.rows[i]) for i in new])

    def _on_brush(self, event: Any) -> None:
        geometry = event.geometry
        if not event.final or geometry.get("type") != "rect":
            return
        x0, x1 = sorted((geometry["x0"], geometry["x1"]))
        axes = [k for k in range(len(self.columns)) if x0 <= k <= x1] or \
            [int(np.clip(round((x0 + x1) / 2), 0, len(self.columns) - 1))]
        y0, y1 = sorted((geometry["y0"], geometry["y1"]))
        y0, y1 = max(y0, 0.0), min(y1, 1.0)
        for k in axes:
            lo, hi = self._bounds(self.columns[k])
            self.on_brush(self.columns[k], lo + y0 * (hi - lo), lo + y1 * (hi - lo))
