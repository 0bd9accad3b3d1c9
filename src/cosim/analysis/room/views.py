"""The decision room's bokeh views: figures, tables and widgets, each built from plain columns (:mod:`.data`).

Every model a test or a user script may look for carries a ``name`` (``Bokeh.documents[0].get_model_by_name``
in the page): ``cloud``, ``count``, ``filter-column`` and ``filter`` (the range filter of the column chosen,
``tags[0]``), ``narrowed``, ``histogram``, ``ranking``, ``weight:<objective>``,
``radar``, ``rerun``, ``trace:<port>``, ``export``, ``hypervolume``, ``sensitivity:<objective>``; the
shortlist's (:mod:`.shortlist`: ``pin``, ``shortlist``, ``shortlist-trace:<port>``), the view's link
(``view-link``, :mod:`.link`) and an optimisation's Study views (:mod:`.trials`: ``history``,
``importances``, ``slice:<parameter>``, ``contour``).
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from typing import Any, Literal, cast

import numpy as np
from bokeh.models import (
    BooleanFilter,
    CategoricalColorMapper,
    CDSView,
    ColumnDataSource,
    CustomJSHover,
    HoverTool,
    LinearColorMapper,
    Range1d,
    SaveTool,
)
from bokeh.models.annotations import ColorBar, Legend, LegendItem, Whisker
from bokeh.models.renderers import DataRenderer
from bokeh.models.widgets import Button, DataTable, Div, NumberFormatter, RangeSlider, Select, Slider, TableColumn
from bokeh.palettes import Category10_10, Viridis256
from bokeh.plotting import figure

from cosim.analysis.room.data import PLAIN_SIZE

GREY = "#c8c8c8"
PLAIN = "#1f77b4"  # ok points when no column gives the colour
FRONT = "#000000"
SELECTED = "#e31a1c"
NONE = "(none)"
Backend = Literal["canvas", "svg", "webgl"]  # how bokeh draws a plot (its output_backend)
ButtonKind = Literal["default", "primary", "success", "warning", "danger", "light"]  # bokeh's button_type
WIDTH = 760


def cloud(data: dict[str, Any], ids: str, not_ok: dict[str, Any], statuses: tuple[list[str], list[str]],
          x_label: str, y_label: str, colour_label: str | None, webgl: bool) -> dict[str, Any]:
    """The point cloud: greyed (filtered out), ok rows by the colour map, the designs not ok as crosses in
    their status's colour (a source of their own, ``cloud-not-ok-source``: :func:`.data.not_ok_points`), the
    Pareto front ringed, the selection ringed in red; the hover names a point's design from ``ids`` (one per
    line, :func:`.data.ids_text`; ``cloud-ids``).  Returns the figure and the models the app updates."""
    source = ColumnDataSource(data, name="cloud-source")
    crosses = ColumnDataSource(not_ok, name="cloud-not-ok-source")
    design = hover_ids(ids)
    n = len(data["x"])
    filters = {layer: BooleanFilter(booleans=booleans(np.zeros(len(not_ok["x"]) if layer == "not_ok" else n,
                                                                dtype=bool)),
                                    name=f"show-{layer}") for layer in ("greyed", "ok", "not_ok", "front", "selected")}
    fig = figure(name="cloud", width=WIDTH, height=520, x_axis_label=x_label, y_axis_label=y_label,
                 tools="pan,wheel_zoom,box_zoom,tap,box_select,lasso_select,reset,save",
                 output_backend="webgl" if webgl else "canvas", active_scroll="wheel_zoom")
    mapper = LinearColorMapper(palette=Viridis256, nan_color=PLAIN)
    same = 1.0  # selection_alpha and nonselection_alpha: the selection has its own red ring
    fig.scatter("x", "y", source=source, view=CDSView(filter=filters["greyed"]), size="s", color=GREY,
                line_color=None, legend_label="filtered out", name="cloud-greyed",
                selection_alpha=same, nonselection_alpha=same)
    ok = fig.scatter("x", "y", source=source, view=CDSView(filter=filters["ok"]), size="s", line_color=None,
                     fill_color={"field": "c", "transform": mapper}, name="cloud-ok",
                     selection_alpha=same, nonselection_alpha=same)
    factors, colours = statuses
    by_status = CategoricalColorMapper(factors=factors or ["failed"], palette=colours or [GREY])
    fig.scatter("x", "y", source=crosses, view=CDSView(filter=filters["not_ok"]), size="s", marker="x",
                line_color={"field": "status", "transform": by_status}, line_width=2, legend_field="status",
                name="cloud-not-ok", selection_alpha=same, nonselection_alpha=same)
    fig.scatter("x", "y", source=source, view=CDSView(filter=filters["front"]), size=PLAIN_SIZE + 6,
                fill_color=None, line_color=FRONT, line_width=1.5, legend_label="Pareto front", name="cloud-front",
                selection_alpha=same, nonselection_alpha=same)
    fig.scatter("x", "y", source=source, view=CDSView(filter=filters["selected"]), size=PLAIN_SIZE + 12,
                fill_color=None, line_color=SELECTED, line_width=3, legend_label="selected", name="cloud-selected",
                selection_alpha=same, nonselection_alpha=same)
    fig.legend.location = "top_right"
    fig.legend.click_policy = "hide"
    fig.add_tools(HoverTool(renderers=[ok], tooltips=[("design", "$index{id}"), ("x", "@x"), ("y", "@y"),
                                                        ("colour", "@c")], formatters={"$index": design}))
    crossed = [r for r in fig.renderers if isinstance(r, DataRenderer) and r.name == "cloud-not-ok"]
    fig.add_tools(HoverTool(renderers=crossed,
                            tooltips=[("design", "@point_id"), ("status", "@status")]))
    bar = ColorBar(color_mapper=mapper, title=colour_label or "", width=10)
    fig.add_layout(bar, "right")
    return {"figure": fig, "source": source, "not_ok_source": crosses, "filters": filters, "mapper": mapper,
            "colour_bar": bar, "status_mapper": by_status, "ids": design}


def booleans(mask: np.ndarray) -> Sequence[bool]:
    """``mask`` as a BooleanFilter's ``booleans``: bokeh takes (and sends) a NumPy bool array as it is, its stub
    says Sequence[bool] only; the cast keeps the array, which a list of 10^5 Python bools would not be."""
    return cast(Sequence[bool], mask)


def hover_ids(ids: str) -> CustomJSHover:
    """A hover formatter of a row (``$index{id}``, the row in the source) giving its design's id from ``ids``."""
    return CustomJSHover(name="cloud-ids", args={"ids": ids}, code="return ids.split('\\n')[value] ?? '';")


def cloud_image(x_range: tuple[float, float], y_range: tuple[float, float], x_label: str, y_label: str,
                colour_label: str | None) -> dict[str, Any]:
    """The cloud of a large table (:mod:`.aggregate`): an image of bins (``cloud-image``), re-binned by the app
    when the ranges change (``cloud-x``, ``cloud-y``), with the Pareto front (``cloud-front-points``) and the
    selection (``cloud-selected-points``) drawn as points over it.  A tap selects the design nearest to it (the
    app's Tap handler)."""
    image = ColumnDataSource({"image": [], "x": [], "y": [], "dw": [], "dh": []}, name="cloud-image")
    front = ColumnDataSource({"x": [], "y": [], "point_id": []}, name="cloud-front-points")
    selected = ColumnDataSource({"x": [], "y": [], "point_id": []}, name="cloud-selected-points")
    fig = figure(name="cloud", width=WIDTH, height=520, x_axis_label=x_label, y_axis_label=y_label,
                 x_range=Range1d(start=x_range[0], end=x_range[1], name="cloud-x"),
                 y_range=Range1d(start=y_range[0], end=y_range[1], name="cloud-y"),
                 tools="pan,wheel_zoom,box_zoom,tap,reset,save", active_scroll="wheel_zoom")
    fig.image_rgba(image="image", x="x", y="y", dw="dw", dh="dh", source=image, name="cloud-bins")
    fig.scatter("x", "y", source=front, size=PLAIN_SIZE + 6, fill_color=None, line_color=FRONT, line_width=1.5,
                legend_label="Pareto front", name="cloud-front")
    fig.scatter("x", "y", source=selected, size=PLAIN_SIZE + 12, fill_color=None, line_color=SELECTED,
                line_width=3, legend_label="selected", name="cloud-selected")
    fig.legend.location = "top_right"
    fig.legend.click_policy = "hide"
    ringed = [r for r in fig.renderers if isinstance(r, DataRenderer) and r.name == "cloud-front"]
    fig.add_tools(HoverTool(renderers=ringed,
                            tooltips=[("design", "@point_id"), ("x", "@x"), ("y", "@y")]))
    mapper = LinearColorMapper(palette=Viridis256, nan_color=PLAIN)
    bar = ColorBar(color_mapper=mapper, title=colour_label or "", width=10)
    fig.add_layout(bar, "right")
    return {"figure": fig, "image": image, "front": front, "selected": selected, "mapper": mapper,
            "colour_bar": bar}


def colour_by(mapper: LinearColorMapper, bar: ColorBar, values: np.ndarray, label: str | None) -> None:
    """Map ``values`` (the source's ``c``) over their finite range; without a column one plain colour."""
    finite = values[np.isfinite(values)]
    if label is None or not finite.size:
        mapper.update(palette=[PLAIN], low=0.0, high=1.0)
        bar.visible = False
        return
    lo, hi = float(finite.min()), float(finite.max())
    mapper.update(palette=Viridis256, low=lo, high=hi if hi > lo else lo + 1.0)
    bar.update(title=label, visible=True)


def axis_choosers(columns: Sequence[str], x: str, y: str, colour: str | None) -> dict[str, Select]:
    """Selects of x, y, colour and size (the last two may be '(none)')."""
    options: list[str | tuple[Any, str]] = list(columns)  # bokeh's type of a Select's options
    return {"x": Select(title="x", value=x, options=options, name="choose-x", width=180),
            "y": Select(title="y", value=y, options=options, name="choose-y", width=180),
            "colour": Select(title="colour", value=colour or NONE, options=[NONE, *options], name="choose-colour",
                             width=180),
            "size": Select(title="size", value=NONE, options=[NONE, *options], name="choose-size", width=180)}


def choices(columns: Sequence[str]) -> list[tuple[str, str]]:
    """The options of a MultiChoice: (column, its name escaped).  Its list (Choices.js) shows an option's label
    as HTML, unlike a Select's, so a column named ``<img onerror=...>`` would run in the page."""
    return [(c, html.escape(c)) for c in columns]


def range_filter(state: dict[str, Any]) -> RangeSlider:
    """The one range filter (``filter``): the app sets its column (``tags[0]``), bounds and range."""
    return RangeSlider(name="filter", width=300, format="0[.]0000", **state)


def histogram(data: dict[str, np.ndarray], label: str) -> dict[str, Any]:
    """Bars of every row (grey) and of the rows the filters keep (blue), over one column."""
    source = ColumnDataSource(data, name="histogram-source")
    fig = figure(name="histogram", width=WIDTH, height=220, x_axis_label=label, y_axis_label="designs",
                 tools="xpan,xwheel_zoom,reset,save")
    fig.quad(left="left", right="right", bottom=0, top="all", source=source, color=GREY, legend_label="all")
    fig.quad(left="left", right="right", bottom=0, top="active", source=source, color=PLAIN, alpha=0.8,
             legend_label="kept by the filters")
    fig.legend.location = "top_right"
    return {"figure": fig, "source": source}


def ranking_table(columns: Sequence[tuple[str, str]], data: dict[str, list]) -> DataTable:
    """The best designs: rank, design, score, and each (field, title) of ``columns`` (:func:`.data.ranking_columns`:
    the parameters and objectives with their units); wider than the page, it scrolls sideways."""
    return DataTable(source=ColumnDataSource(data), columns=ranking_columns(columns), name="ranking", width=WIDTH,
                     height=330, index_position=None, selectable=True, autosize_mode="none")


def ranking_columns(columns: Sequence[tuple[str, str]]) -> list[TableColumn]:
    """The ranking's TableColumns.  A DataTable shows its titles as HTML (its cells as text), so the titles
    (column names and units from a results file) are escaped here."""
    number = NumberFormatter(format="0.[0000]")
    head = [TableColumn(field="rank", title="#", width=36), TableColumn(field="point_id", title="design", width=140),
            TableColumn(field="score", title="score", formatter=NumberFormatter(format="0.0000"), width=60)]
    return head + [TableColumn(field=field, title=html.escape(title), formatter=number,
                               width=min(max(80, 7 * len(title)), 220)) for field, title in columns]


def weight_sliders(weights: dict[str, float]) -> list[Slider]:
    return [Slider(title=f"weight of {name}", start=0.0, end=1.0, step=0.05, value=min(float(w), 1.0),
                   name=f"weight:{name}", width=300) for name, w in weights.items()]


def radar(data: dict[str, Any], ids: Sequence[str]) -> dict[str, Any]:
    """Spokes (one per objective, 1 = best at the rim), a ring per 0.25, one polygon per selected design."""
    fig = figure(name="radar", width=460, height=460, x_range=Range1d(start=-1.45, end=1.45),
                 y_range=Range1d(start=-1.3, end=1.3),
                 tools="save", match_aspect=True, title="score profile of the selected designs (rim: best)")
    fig.axis.visible = False
    fig.grid.visible = False
    angles = np.linspace(0, 2 * np.pi, 73)
    for r in (0.1, 0.325, 0.55, 0.775, 1.0):
        fig.line(r * np.cos(angles), r * np.sin(angles), color="#dddddd")
    spokes = ColumnDataSource({"x": data["spoke_x"], "y": data["spoke_y"], "label": data["labels"]},
                              name="radar-spokes")
    fig.segment(0, 0, "x", "y", source=spokes, color="#999999")
    fig.text("x", "y", text="label", source=spokes, text_font_size="9pt", text_align="center",
             text_baseline="middle", y_offset=0)
    designs = ColumnDataSource(radar_columns(data, ids), name="radar-designs")
    fig.patches("xs", "ys", source=designs, fill_color="colour", fill_alpha=0.12, line_color="colour",
                line_width=2, legend_field="design")
    return {"figure": fig, "spokes": spokes, "designs": designs}


def radar_columns(data: dict[str, Any], ids: Sequence[str]) -> dict[str, list]:
    return {"xs": data["xs"], "ys": data["ys"], "design": list(ids),
            "colour": [Category10_10[k % 10] for k in range(len(ids))]}


# an array port's elements within a design's colour: a dash each, and a lighter shade the later the element
ELEMENT_DASHES = ("solid", "dashed", "dotted", "dotdash", "dashdot", [8, 3, 2, 3], [2, 6])


def element_style(design: int, element: int, elements: int) -> dict[str, Any]:
    """Line colour and dash of element ``element`` (0-based) of ``elements`` in design ``design``'s colour
    family: the design's Category10 colour, mixed with white up to 55 % for the last element, and a dash of
    its own (issue 39: seven joints in one colour could not be told apart)."""
    base = Category10_10[design % 10]
    share = 0.55 * element / max(elements - 1, 1)
    rgb = [int(base[i:i + 2], 16) for i in (1, 3, 5)]
    mixed = "#" + "".join(f"{round(c + (255 - c) * share):02x}" for c in rgb)
    return {"color": mixed, "line_dash": ELEMENT_DASHES[element % len(ELEMENT_DASHES)]}


def trace_figures(groups: list[tuple[str, list[str]]], runs: Sequence[Any], backend: Backend = "canvas",
                  prefix: str = "trace") -> list:
    """One figure per port (``<prefix>:<port>``, ``trace:robot.q``), a line per design and element, x ranges
    linked; drawn through ``backend`` ("canvas", or "svg" for a save button that writes SVG).

    Each design has its own colour; the elements of an array port are drawn in that colour's family, each
    with its own shade and dash (:func:`element_style`).  The y axis names the port and its unit
    (``robot.tau [N.m]``, from the runs' ``units``).  The legend, beside the plot, has an entry per design (a
    click hides its lines) and, for an array port, one per element named as recorded (``robot.tau[3]``: a
    click hides that element in every design); the hover names the line."""
    units: dict[str, str] = {}
    for run in runs:
        units.update(getattr(run, "units", None) or {})
    figures: list = []
    for port, columns in groups:
        linked = {"x_range": figures[0].x_range} if figures else {}
        label = f"{port} [{units[port]}]" if units.get(port) else port
        fig = figure(name=f"{prefix}:{port}", width=WIDTH, height=200, x_axis_label="time [s]", y_axis_label=label,
                     tools="pan,wheel_zoom,box_zoom,reset,save", output_backend=backend, **linked)
        fig.add_tools(HoverTool(tooltips=[("line", "$name"), ("t [s]", "$x"), (label, "$y")],
                                line_policy="nearest"))
        by_design: dict[str, list] = {}
        by_element: dict[str, list] = {}
        for k, run in enumerate(runs):
            traces = run.result.traces
            if traces is None or not len(traces):
                continue
            t = traces["time"].to_numpy(dtype=float)
            drawn = [c for c in columns if c in traces.columns]
            for i, column in enumerate(drawn):
                style = element_style(k, i, len(drawn)) if len(drawn) > 1 else {"color": Category10_10[k % 10]}
                line = fig.line(t, traces[column].to_numpy(dtype=float), line_width=1.5,
                                name=f"trace:{column}:{run.point_id}", **style)
                by_design.setdefault(run.point_id, []).append(line)
                by_element.setdefault(column, []).append(line)
        if fig.renderers:
            # beside the plot, not over its curves: the designs, then (an array port) its elements by name
            items = [LegendItem(label=design, renderers=lines) for design, lines in by_design.items()]
            if len(by_element) > 1:
                items += [LegendItem(label=column, renderers=lines) for column, lines in by_element.items()]
            # compact rows: two designs and seven elements fit beside a 240 px plot without a cut
            legend = Legend(items=items, label_text_font_size="8pt", click_policy="hide", spacing=0,
                            padding=cast(Any, 4),  # bokeh's stub types padding as a Property, not the int it takes
                            label_height=12, glyph_height=12, label_standoff=4, margin=2)
            fig.add_layout(legend, "right")
            figures.append(fig)
    return figures


def name_save_tools(figures: Sequence[Any]) -> None:
    """No bokeh logo in the figures' toolbars, and their save buttons name the file after the figure
    (``cosim-trace_robot_q.png`` or ``.svg`` for ``trace:robot.q``)."""
    for fig in figures:
        fig.toolbar.logo = None
        for tool in fig.select(type=SaveTool):
            # no dot: the browser adds .png or .svg only to a name without an extension
            tool.filename = "cosim-" + "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in fig.name)


def hypervolume(evaluations: np.ndarray, values: np.ndarray) -> Any:
    fig = figure(name="hypervolume", width=WIDTH, height=300, x_axis_label="evaluations",
                 y_axis_label="hypervolume", title="hypervolume of the feasible front after each evaluation",
                 tools="pan,wheel_zoom,reset,save")
    fig.step(evaluations, values, mode="after", line_width=2)
    return fig


def sensitivity(indices: Any) -> list:
    """One figure per objective (at most 6): each parameter's indices as bars with their 95 % intervals."""
    figures = []
    for objective, part in list(indices.groupby("objective", sort=False))[:6]:
        names = list(dict.fromkeys(part["index"]))
        factors = [(str(p), str(i)) for p in dict.fromkeys(part["parameter"]) for i in names]
        by = {(str(r.parameter), str(r["index"])): r for _, r in part.iterrows()}
        value = [float(by[f]["value"]) if f in by else np.nan for f in factors]
        conf = [float(by[f]["conf"]) if f in by else 0.0 for f in factors]
        source = ColumnDataSource({"factor": factors, "value": value, "lower": np.subtract(value, conf),
                                   "upper": np.add(value, conf),
                                   "colour": [Category10_10[names.index(i) % 10] for _, i in factors]})
        fig = figure(name=f"sensitivity:{objective}", y_range=_factor_range(factors), width=WIDTH,
                     height=60 + 22 * len(factors), title=f"sensitivity of {objective} (± 95 % confidence)",
                     x_axis_label="index", tools="save")
        fig.hbar(y="factor", right="value", height=0.7, source=source, color="colour")
        fig.add_layout(Whisker(source=source, base="factor", lower="lower", upper="upper", dimension="width"))
        figures.append(fig)
    return figures


def _factor_range(factors):
    from bokeh.models import FactorRange

    return FactorRange(*factors)


def failures_table(rows: dict[str, list]) -> DataTable:
    return DataTable(source=ColumnDataSource(rows), name="failures", width=WIDTH, height=160, index_position=None,
                     columns=[TableColumn(field="point_id", title="design", width=140),
                              TableColumn(field="status", title="status", width=70),
                              TableColumn(field="message", title="message", width=550)])


def button(label: str, name: str, kind: ButtonKind = "default") -> Button:
    return Button(label=label, name=name, button_type=kind, width=180)


def text(html: str, name: str, width: int = WIDTH) -> Div:
    """A block of HTML.  Never typeset as TeX: a ``$$`` in a message or a column name stays as it is (the page
    is served without bokeh's MathJax, :func:`cosim.analysis.room.server.serve_without_mathjax`)."""
    return Div(text=html, name=name, width=width, disable_math=True)
