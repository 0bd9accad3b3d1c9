"""The two ways the decision room draws its point cloud, behind one interface the app drives.

- :class:`PointCloud`: every row a point in the browser (tables up to ``AGGREGATE_ABOVE`` rows): one source
  shared by five renderers (filtered out, ok, not ok, front, selected), each a view through a BooleanFilter
  the server sets; colour and size by any column; tap, box and lasso select in the browser.
- :class:`BinnedCloud`: above that, an image of bins made on the server (:mod:`.aggregate`) and re-made
  when the user zooms or pans; the front and the selection drawn as points over it; a tap selects the
  design nearest to it (on the server: the browser has no rows).

Both: ``figure``; ``set_axes(x, y, colour, size)``; ``show(masks)`` with the layers of
:func:`cosim.analysis.room.data.masks`; ``show_selection(rows)``; ``select(rows)`` (as if the user picked them);
the app's ``on_select(rows)`` is called when the user picks designs in the cloud.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from bokeh.core.property.validation import without_property_validation
from bokeh.palettes import Viridis256

from cosim.analysis.decision import Decision
from cosim.analysis.room import aggregate as A
from cosim.analysis.room import data as D
from cosim.analysis.room import views as V

BINS = (340, 230)  # the image's bins: about two screen pixels each in the cloud's frame


class PointCloud:
    """Every row a point (module docstring)."""

    def __init__(self, study: D.Study, decision: Decision, axes: tuple[str, str, str | None],
                 on_select: Callable[[list[int]], None], webgl: bool):
        self.study, self.decision = study, decision
        self.x, self.y, self.colour = axes
        self.size: str | None = None
        label = study.table.label
        self.not_ok = D.not_ok_rows(study)
        points = D.points(study, decision, self.x, self.y, self.colour, None)
        self.parts = V.cloud(points, D.ids_text(study), D.not_ok_points(study, points, self.not_ok),
                             D.status_palette(study.status), label(self.x), label(self.y),
                             label(self.colour) if self.colour else None, webgl)
        self.figure = self.parts["figure"]
        self.on_select = on_select
        for source in (self.parts["source"], self.parts["not_ok_source"]):  # a box may take points of both
            source.selected.on_change("indices", lambda attr, old, new: self._on_pick())

    def _on_pick(self) -> None:
        crosses = [int(self.not_ok[i]) for i in self.parts["not_ok_source"].selected.indices]
        self.on_select(sorted(set(self.parts["source"].selected.indices) | set(crosses)))

    @without_property_validation
    def set_axes(self, x: str, y: str, colour: str | None, size: str | None) -> None:
        columns = D.points(self.study, self.decision, x, y, colour, size)
        changed = {k for k, new, old in (("x", x, self.x), ("y", y, self.y), ("c", colour, self.colour),
                                         ("s", size, self.size)) if new != old}
        self.x, self.y, self.colour, self.size = x, y, colour, size
        self.parts["source"].data.update({k: columns[k] for k in changed})
        crosses = D.not_ok_points(self.study, columns, self.not_ok)
        self.parts["not_ok_source"].data.update({k: crosses[k] for k in changed if k in crosses})
        self.figure.xaxis.axis_label = self.study.table.label(x)
        self.figure.yaxis.axis_label = self.study.table.label(y)
        if "c" in changed:
            V.colour_by(self.parts["mapper"], self.parts["colour_bar"], columns["c"],
                        self.study.table.label(colour) if colour else None)

    @without_property_validation  # bokeh would check each of the masks' n booleans one by one
    def show(self, masks: dict[str, np.ndarray]) -> None:
        for layer, mask in masks.items():
            self.parts["filters"][layer].booleans = mask[self.not_ok] if layer == "not_ok" else mask

    @without_property_validation
    def show_selection(self, rows: list[int]) -> None:
        mask = np.zeros(len(self.study.ids), dtype=bool)
        mask[rows] = True
        self.parts["filters"]["selected"].booleans = mask

    def select(self, rows: list[int]) -> None:
        self.parts["not_ok_source"].selected.indices = []
        self.parts["source"].selected.indices = rows  # fires on_select like a click

    @without_property_validation
    def reload(self, study: D.Study, decision: Decision) -> None:
        """The same folder with more rows (a running study): every column anew; the app then shows the masks."""
        self.study, self.decision = study, decision
        for source in (self.parts["not_ok_source"], self.parts["source"]):  # row positions of the old table;
            source.selected.indices = []  # the app re-selects by id
        self.not_ok = D.not_ok_rows(study)
        points = D.points(study, decision, self.x, self.y, self.colour, self.size)
        self.parts["not_ok_source"].data = D.not_ok_points(study, points, self.not_ok)
        self.parts["source"].data = points
        self.parts["ids"].args = {"ids": D.ids_text(study)}
        factors, colours = D.status_palette(study.status)
        self.parts["status_mapper"].update(factors=factors or ["failed"], palette=colours or [V.GREY])
        if self.colour:
            V.colour_by(self.parts["mapper"], self.parts["colour_bar"], self.parts["source"].data["c"],
                        study.table.label(self.colour))


class BinnedCloud:
    """An image of bins made on the server (module docstring)."""

    def __init__(self, study: D.Study, decision: Decision, axes: tuple[str, str, str | None],
                 on_select: Callable[[list[int]], None], doc: Any):
        from bokeh.events import Tap

        self.study, self.decision, self.doc = study, decision, doc
        self.x, self.y, self.colour = axes
        self.on_select = on_select
        self.factors, self.status_colours = D.status_palette(study.status)
        self.status_codes = D.status_codes(study.status, self.factors)
        self.masks: dict[str, np.ndarray] | None = None
        self.grid = self._grid_of_columns()
        label = study.table.label
        self.parts = V.cloud_image((self.grid.x0, self.grid.x1), (self.grid.y0, self.grid.y1), label(self.x),
                                   label(self.y), label(self.colour) if self.colour else None)
        self.figure = self.parts["figure"]
        self._colour_map()
        self._pending = False
        for r in (self.figure.x_range, self.figure.y_range):
            r.on_change("start", self._on_range)
            r.on_change("end", self._on_range)
        self.figure.on_event(Tap, self._on_tap)

    def _values(self, column: str) -> np.ndarray:
        return self.decision.filters.values(column)

    def _grid_of_columns(self) -> A.Grid:
        return A.grid_around(self._values(self.x), self._values(self.y), *BINS)

    def _colour_map(self) -> None:
        values = self._values(self.colour) if self.colour else np.full(1, np.nan)
        V.colour_by(self.parts["mapper"], self.parts["colour_bar"], values,
                    self.study.table.label(self.colour) if self.colour else None)

    def set_axes(self, x: str, y: str, colour: str | None, size: str | None) -> None:
        """x, y and colour; ``size`` is not drawn (a bin has no size)."""
        moved = (x, y) != (self.x, self.y)
        self.x, self.y, self.colour = x, y, colour
        self.figure.xaxis.axis_label = self.study.table.label(x)
        self.figure.yaxis.axis_label = self.study.table.label(y)
        self._colour_map()
        if moved:  # the new columns' whole range; the range callbacks re-bin once
            self.grid = self._grid_of_columns()
            self.figure.x_range.update(start=self.grid.x0, end=self.grid.x1)
            self.figure.y_range.update(start=self.grid.y0, end=self.grid.y1)
        self._draw()
        self.show_selection(self.decision.selection)

    def show(self, masks: dict[str, np.ndarray]) -> None:
        self.masks = masks
        self._draw()

    def _draw(self) -> None:
        if self.masks is None:
            return
        m, g = self.masks, self.grid
        x, y = self._values(self.x), self._values(self.y)
        cells = g.bin_of(x, y)
        colour = self._values(self.colour) if self.colour else None
        mapper = self.parts["mapper"]
        image, _ = A.image(g, cells, m["ok"], m["not_ok"], m["greyed"], colour, (mapper.low, mapper.high),
                           Viridis256, V.PLAIN, self.status_codes, self.status_colours, V.GREY)
        self.parts["image"].data = {"image": [image], "x": [g.x0], "y": [g.y0], "dw": [g.x1 - g.x0],
                                    "dh": [g.y1 - g.y0]}
        front = np.flatnonzero(m["front"])
        self.parts["front"].data = {"x": x[front], "y": y[front], "point_id": list(self.study.ids[front])}

    def show_selection(self, rows: list[int]) -> None:
        x, y = self._values(self.x), self._values(self.y)
        self.parts["selected"].data = {"x": x[rows], "y": y[rows], "point_id": list(self.study.ids[rows])}

    def select(self, rows: list[int]) -> None:
        self.on_select(rows)

    def reload(self, study: D.Study, decision: Decision) -> None:
        """The same folder with more rows (a running study); the app then shows the masks."""
        self.study, self.decision = study, decision
        self.factors, self.status_colours = D.status_palette(study.status)
        self.status_codes = D.status_codes(study.status, self.factors)
        self.masks = None
        self._colour_map()

    def _on_range(self, attr: str, old: Any, new: Any) -> None:
        if not self._pending:  # one re-binning after a burst of range changes (a drag reports every step)
            self._pending = True
            self.doc.add_next_tick_callback(self._rebin)

    def _rebin(self) -> None:
        self._pending = False
        xr, yr = self.figure.x_range, self.figure.y_range
        if None in (xr.start, xr.end, yr.start, yr.end) or xr.start == xr.end or yr.start == yr.end:
            return
        self.grid = A.Grid(float(min(xr.start, xr.end)), float(max(xr.start, xr.end)),
                           float(min(yr.start, yr.end)), float(max(yr.start, yr.end)), *BINS)
        self._draw()

    def _on_tap(self, event: Any) -> None:
        if self.masks is None or event.x is None or event.y is None:
            return
        shown = ~self.masks["greyed"]
        row = A.nearest(self._values(self.x), self._values(self.y), shown, float(event.x), float(event.y),
                        self.grid)
        self.on_select([] if row is None else [row])
