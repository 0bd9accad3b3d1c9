"""One browser tab of the decision room: the views of :mod:`.views` wired to the tab's own Decision.

Tabs of the page:

- **Points**: x, y, colour and size choosers; the cloud; one range filter for the column chosen beside it
  (any numeric column; the narrowed ones listed under it); a histogram of any column, all rows against the
  rows kept; the failed, timed-out and crashed designs with their messages.  A click (tap, box or lasso) on
  the cloud selects designs.
- **Decide**: objectives to minimise and to maximise (by default every objective with a sense), the ranking
  method (weighted sum, TOPSIS), a weight per objective, the best designs with their parameters and objectives
  (a click on a row selects it), the radar of the selected designs, and the shortlist (:mod:`.shortlist`):
  designs pinned and compared side by side, their traces overlaid.
- **Selection**: the selected designs, their re-run with the spec's recorded signals (traces overlaid per
  port) and, when a trace viewer supplies link frames (:mod:`.animation`; e.g. the Panda arm's), the designs
  as 3-D stick figures over time; a switch that draws these figures as SVG (their save buttons then write
  SVG, not PNG); the selection as CSV and as ``cosim run --point`` commands.
- **Study**: counts by status; an optimisation's hypervolume against evaluations, its history, parameter
  importances, slice and contour plots (:mod:`.trials`); a sensitivity analysis's indices with their
  confidence intervals.
- **Surrogate** (when ``cosim surrogate DIR`` stored surrogates): predicted surfaces over any two parameters with
  the simulated designs on top, Q² on screen, and "simulate here" (:mod:`.surrogate_view`).

Only the Points tab is built with the page; the others are built on the server the first time they are
shown (what makes a page of a wide table slow is the number of bokeh models, not its rows: the 17061-point
study had ~350 models and 70 range sliders, see benchmarks/room_load.md).

The view (axes, colour, filters, objectives, weights, ranking method, shortlist, tab) lives in the page's
address (:mod:`.link`): a page opened with that link starts in the same state.

Every change goes through the Decision, and :meth:`Room.refresh` recomputes what depends on it.  A re-run
runs in a child process (:mod:`cosim.analysis.rerun_job`: a timeout and a Cancel button end it), waited for
by a thread of its own so the server keeps answering; its traces are drawn from the document's next tick
(bokeh's rule: a document is changed only while its lock is held).
"""

from __future__ import annotations

import html
import threading
from functools import partial
from typing import Any

from bokeh.core.property.validation import without_property_validation
from bokeh.layouts import column, row
from bokeh.models import CustomJS, TabPanel, Tabs
from bokeh.models.widgets import MultiChoice, Select, Toggle

from cosim.analysis.decision import Decision
from cosim.analysis.ranking import METHODS
from cosim.analysis.rerun import port_groups
from cosim.analysis.rerun_job import RerunJob, RerunStopped, rerun_timeout
from cosim.analysis.room import animation as A
from cosim.analysis.room import data as D
from cosim.analysis.room import link as L
from cosim.analysis.room import surrogate_view as S
from cosim.analysis.room import views as V
from cosim.analysis.room.clouds import BinnedCloud, PointCloud
from cosim.analysis.room.dimensions import Dimensions
from cosim.analysis.room.live import LiveStudy
from cosim.analysis.room.shortlist import Shortlist
from cosim.analysis.room.trials import TrialViews, is_optimisation
from cosim.analysis.table import AnalysisError

TOP = 20  # designs in the ranking table
TAB_NAMES = ("points", "decide", "selection", "study", "dimensions")
MAX_RERUN = 8  # designs re-run at once (one colour each)
MAX_FAILURES_LISTED = 500  # rows of the table of designs not ok (the count says how many there are)
WEBGL_ABOVE = 50_000  # rows from which the cloud is drawn through WebGL rather than canvas
AGGREGATE_ABOVE = 200_000  # rows from which the cloud is an image of bins made on the server (clouds.BinnedCloud)


class Room:
    """The models and callbacks of one document (module docstring)."""

    def __init__(self, doc: Any, study: D.Study, webgl: bool | None = None, aggregate_above: int | None = None,
                 live: LiveStudy | None = None):
        self.doc, self.study, self.live = doc, study, live
        self._options = (webgl, aggregate_above)
        self.rebuilt_note = ""  # why this room replaced another on the page (a watched table's columns changed)
        self._build(webgl, aggregate_above)
        # attached to the document only now, with bokeh's property validation back on: a document bound to a page
        # (a live page turning from waiting into the room) sends new models at once, and bokeh 3.9 encodes a
        # field with a transform (the colour map's) as a constant while validation is off ("color is not
        # iterable" in the page, and no cloud)
        doc.add_root(self.tabs)
        self._looking = None
        if live is not None:  # a folder watched while its study runs: new rows are drawn as they arrive
            self._looking = doc.add_periodic_callback(self._look, int(live.every * 1000))

    @without_property_validation  # the cloud's masks: bokeh would check their n booleans one by one
    def _build(self, webgl: bool | None, aggregate_above: int | None) -> None:
        """The page's models, not yet in the document (see __init__)."""
        study, doc = self.study, self.doc
        self.decision = Decision(study.table)
        table = study.table
        self._has_surrogate = S.models_of(study) is not None  # a Surrogate tab after TAB_NAMES' (surrogate_view)
        view, notes = L.decode(self._arguments(doc), self.decision.filters.columns, list(METHODS), study.ids,
                               len(TAB_NAMES) + self._has_surrogate)
        self._apply(view)
        self.x, self.y, self.colour = study.default_axes(self.decision)
        self.size: str | None = None
        for which in ("x", "y", "colour", "size"):
            if getattr(view, which) is not None:
                setattr(self, which, None if getattr(view, which) == L.NONE else getattr(view, which))
        self.runs: list = []
        self.motions: list[A.Motion] = []  # the re-run designs' link frames, when a viewer supplies them
        self.motion_note = ""
        self.link_view: A.LinkView | None = None
        self._pending = False
        self._weight_sliders: dict[str, Any] = {}
        self.ranking = self.radar = None  # the Decide tab's, built when it is first shown
        self._highlighting = False  # the server sets the ranking's highlighted rows (_show_ranking_selection)
        self.dimensions: Dimensions | None = None  # the Dimensions tab's
        self.surrogate: Any = None  # the Surrogate tab's (surrogate_view.SurrogateView), when the folder has one
        columns = self.decision.filters.columns
        if aggregate_above is None:
            aggregate_above = AGGREGATE_ABOVE
        if webgl is None:  # canvas draws a few ten thousand points faster than software WebGL (benchmarks)
            webgl = len(study.ids) > WEBGL_ABOVE

        # -- Points
        self.choosers = V.axis_choosers(columns, self.x, self.y, self.colour)
        self.choosers["size"].value = self.size or V.NONE
        axes = (self.x, self.y, self.colour)
        self.cloud: PointCloud | BinnedCloud = \
            BinnedCloud(study, self.decision, axes, self._on_cloud_selection, doc) \
            if len(study.ids) > aggregate_above else PointCloud(study, self.decision, axes, self._on_cloud_selection,
                                                                webgl)
        if isinstance(self.cloud, BinnedCloud):
            self.choosers["size"].disabled = True  # a bin has no size
        elif self.size:  # sized by the link
            self.cloud.set_axes(self.x, self.y, self.colour, self.size)
        self.count = V.text("", "count")
        first = (self.decision.filters.narrowed() + table.parameter_columns() + columns)[0]
        self.filter_column = Select(title="filter by", value=first, options=list(columns), name="filter-column",
                                    width=300)
        self.filter = V.range_filter(self._filter_state(first))
        self.narrowed = V.text("", "narrowed", width=300)
        self.reset = V.button("Reset filters", "reset-filters")
        self.histogram_column = Select(title="histogram of", value=self.colour or self.x, options=list(columns),
                                       name="choose-histogram", width=220)
        self.histogram = V.histogram(D.histogram(self.decision.filters.values(self.histogram_column.value),
                                                 self.decision.active()), table.label(self.histogram_column.value))
        self.failures = column(*self._failures(), name="failures-box")

        # -- Decide: the choosers are cheap; the table and the radar are built with the tab
        senses = dict(self.decision.objectives)
        self.minimise = MultiChoice(title="minimise", options=V.choices(columns), name="minimise", width=360,
                                    value=[c for c, s in senses.items() if s == "min"])
        self.maximise = MultiChoice(title="maximise", options=V.choices(columns), name="maximise", width=360,
                                    value=[c for c, s in senses.items() if s == "max"])
        self.method = Select(title="ranking", value=self.decision.method, options=list(METHODS.items()), name="method",
                             width=200)
        self.weights = column(name="weights")
        self.shortlist = Shortlist(study, self.decision, doc, self._publish, view.pinned or ())

        # -- the view's link: the address bar follows the state (link.REPLACE_JS, the page's own CustomJS)
        self.view_link = V.text("<i>the address bar holds this view (axes, filters, ranking, weights, shortlist):"
                                " bookmark it or send it</i>" + "".join(
                                    f"<br><span class='link-note'>left out of the link: {html.escape(n)}</span>"
                                    for n in notes), "view-link", width=300)
        replace = CustomJS(args={"state": self.view_link}, code=L.REPLACE_JS)
        self.view_link.js_on_change("tags", replace)
        doc.js_on_event("document_ready", replace)

        # -- Selection
        self.selected = V.text("<p>No design selected: click points of the cloud or rows of the ranking.</p>",
                               "selected")
        self.rerun_button = V.button("Re-run selected", "rerun", "primary")
        self.cancel_button = V.button("Cancel the re-run", "rerun-cancel", "warning")
        self.cancel_button.disabled = True
        self.rerun_job: RerunJob | None = None  # the re-run going on (in a child process), None when none
        self.rerun_status = V.text("", "rerun-status")
        self.traces = column(name="traces")
        self.viewer = column(name="viewer")  # the 3-D view of the re-run designs (animation.LinkView)
        self.svg = Toggle(label="figures as SVG", active=False, name="svg-figures", width=180)
        self.export = V.text("", "export")

        self._wire()
        self._rebuild_weights()
        self.refresh()
        self.doc.title = f"cosim: {study.name}"
        points = row(column(row(*self.choosers.values()), self.cloud.figure, self.count,
                            row(self.histogram_column), self.histogram["figure"],
                            self.failures),
                     column(self.filter_column, self.filter, self.reset, self.narrowed, self.view_link))
        self._builders = {1: self._build_decide, 2: self._build_selection, 3: self._build_study,
                          4: self._build_dimensions}
        names = list(TAB_NAMES[1:])
        if self._has_surrogate:
            self._builders[len(names) + 1] = self._build_surrogate
            names.append("surrogate")
        self.tabs = Tabs(tabs=[TabPanel(child=points, title="Points")] +
                         [TabPanel(child=column(name=f"tab:{name}"), title=name.capitalize())
                          for name in names], name="tabs")
        self.tabs.on_change("active", self._on_tab)
        if view.tab:
            self.tabs.active = view.tab
            self._on_tab("active", 0, view.tab)
        self._publish()

    # -- the view's link --------------------------------------------------------------------------------------
    @staticmethod
    def _arguments(doc: Any) -> dict[str, list[bytes]]:
        """The query arguments of the page that opened this document ({} outside a server's session)."""
        context = getattr(doc, "session_context", None)
        request = getattr(context, "request", None) if context is not None else None
        return dict(getattr(request, "arguments", None) or {})

    def _apply(self, view: L.ViewState) -> None:
        """The link's objectives, method, weights and filters into the tab's Decision (checked by L.decode)."""
        if view.minimise is not None or view.maximise is not None:
            self.decision.set_objectives([(c, "min") for c in view.minimise or []] +
                                         [(c, "max") for c in view.maximise or []])
        if view.method:
            self.decision.set_method(view.method)
        for name, weight in view.weights.items():
            if name in self.decision.weights:
                self.decision.set_weight(name, min(weight, 1.0))  # a weight slider ends at 1
        for name, (lo, hi) in view.filters.items():
            self.decision.filters.set_range(name, lo, hi)

    def view_state(self) -> L.ViewState:
        """The tab's view as its link carries it."""
        f, objectives = self.decision.filters, self.decision.objectives
        return L.ViewState(x=self.x, y=self.y, colour=self.colour or L.NONE, size=self.size or L.NONE,
                           minimise=[c for c, s in objectives if s == "min"],
                           maximise=[c for c, s in objectives if s == "max"], method=self.decision.method,
                           weights=dict(self.decision.weights),
                           filters={c: (f.ranges[c].lo, f.ranges[c].hi) for c in f.narrowed()},
                           pinned=list(self.shortlist.ids), tab=self.tabs.active if hasattr(self, "tabs") else 0)

    def _publish(self) -> None:
        """The view's query into ``view-link`` (the page's CustomJS puts it into the address bar)."""
        if not hasattr(self, "shortlist"):  # the first refresh, before the models exist
            return
        query = L.encode(self.view_state())
        if self.view_link.tags != [query]:
            self.view_link.tags = [query]

    # -- a running study's new rows -------------------------------------------------------------------------------
    def _look(self) -> None:
        assert self.live is not None  # the callback exists only then
        study = self.live.current()
        if study is None or study is self.study:
            if self.live.problem:  # the table cannot be read now: the note says so (see _live_note)
                self.refresh()
            return
        if list(study.table.df.columns) != list(self.study.table.df.columns):
            self._rebuild(study)  # another study's table: filters and objectives of the old one mean nothing
            return
        try:
            self.reload(study)
        except AnalysisError:  # a column the tab's state needs is gone after all: start afresh from the table
            self._rebuild(study)

    def _rebuild(self, study: D.Study) -> None:
        """Replace this room on its page by a new one of ``study`` (a watched table whose columns changed: before,
        every refresh raised, the server printed a traceback per look and a new page got HTTP 500)."""
        old = list(self.study.table.df.columns)
        new = list(study.table.df.columns)
        gone, added = [c for c in old if c not in new], [c for c in new if c not in old]
        if self._looking is not None:
            self.doc.remove_periodic_callback(self._looking)
            self._looking = None
        self.doc.remove_root(self.tabs)
        room = Room(self.doc, study, *self._options, live=self.live)
        room.rebuilt_note = ("the table's columns changed (" + "; ".join(
            part for part in (f"gone: {', '.join(gone[:8])}" if gone else "",
                              f"new: {', '.join(added[:8])}" if added else "") if part)
            + "): the room shows the new table, filters, objectives and selection reset")
        room.refresh()

    @without_property_validation
    def reload(self, study: D.Study) -> None:
        """Show ``study`` (the same folder with more rows) keeping this tab's filters, objectives, weights,
        ranking method and selection (by design id)."""
        old, ids = self.decision, self.study.ids
        self.study = study
        self.decision = decision = Decision(study.table)
        try:
            decision.set_objectives(old.objectives)
        except AnalysisError:  # an objective column not in the new table: the table's own objectives stay
            pass
        for name, weight in old.weights.items():
            if name in decision.weights:
                decision.set_weight(name, weight)
        decision.set_method(old.method)
        for name in old.filters.narrowed():
            if name in decision.filters.bounds:
                decision.filters.set_range(name, old.filters.ranges[name].lo, old.filters.ranges[name].hi)
        where = {i: r for r, i in enumerate(study.ids)}
        selected = [where[i] for i in (ids[r] for r in old.selection) if i in where]
        columns = list(decision.filters.columns)
        for which, select in self.choosers.items():
            select.options = columns if which in ("x", "y") else [V.NONE, *columns]
        self.filter_column.options = self.histogram_column.options = columns
        self.cloud.reload(study, decision)
        if self.dimensions is not None:
            self.dimensions.reload(study, decision)
        decision.select(selected)  # after the views let go of the old rows' selection
        self.shortlist.reload(study, decision)
        self.filter.update(**self._filter_state(self.filter.tags[0]))
        self.failures.children = self._failures()
        if self.surrogate is not None:
            self.surrogate.reload(study, self._held_row())
        self.refresh()

    # -- the tabs built when first shown --------------------------------------------------------------------------
    def _on_tab(self, attr: str, old: Any, new: Any) -> None:
        build = self._builders.pop(new, None)
        if build is not None:
            self.tabs.tabs[new].child.children = build()
        self._publish()

    @without_property_validation
    def _build_decide(self) -> list:
        self.ranking = V.ranking_table(D.ranking_columns(self.study, self.decision),
                                       D.ranking_rows(self.study, self.decision, TOP))
        self._show_ranking_selection()
        self.ranking.source.selected.on_change("indices", self._on_ranking_selection)
        self.radar = V.radar(D.radar(self.decision, []), [])
        self.radar_note = V.text("", "radar-note", width=460)
        self._refresh_radar()
        return [row(column(row(self.minimise, self.maximise), self.method, self.weights),
                    column(self.ranking, self.radar_note, self.radar["figure"])), self.shortlist.layout]

    def _build_selection(self) -> list:
        return [self.selected, row(self.rerun_button, self.cancel_button, self.svg, self.rerun_status),
                row(self.traces, self.viewer),
                self.export]

    def _build_surrogate(self) -> list:
        self.surrogate = S.SurrogateView(self.doc, self.study, self._held_row(), self.reload)
        return [self.surrogate.layout]

    def _held_row(self) -> int | None:
        """The design the Surrogate tab holds the other parameters at: the first selected one."""
        return self.decision.selection[0] if self.decision.selection else None

    def _build_dimensions(self) -> list:
        table = self.study.table
        columns = self.decision.filters.columns
        chosen = list(dict.fromkeys(c for c in [*table.parameter_columns(), *[c for c, _ in self.decision.objectives],
                                                *table.objective_columns(), *columns] if c in columns))[:4]
        self.dimensions = Dimensions(self.study, self.decision, chosen, self.colour, self._on_cloud_selection,
                                     self._on_brush)
        self.dimensions.show(D.masks(self.study, self.decision))
        self.dimensions.show_selection(self.decision.selection)
        return [self.dimensions.layout]

    def _on_brush(self, name: str, lo: float, hi: float) -> None:
        """A box over an axis of the parallel coordinates: that column's range filter narrowed to it."""
        self.decision.filters.set_range(name, lo, hi)
        if self.filter.tags[0] == name:
            self.filter.update(**self._filter_state(name))
        self._refresh_soon()

    def _build_study(self) -> list:
        views: list = [V.text(self._summary(), "summary")]
        history = self.study.hypervolume()
        if history is not None:
            views.append(V.hypervolume(*history))
        if is_optimisation(self.study.table):  # what optuna-dashboard shows, from the table
            views.append(TrialViews(self.study.table, self.decision.filters.columns).layout)
        indices = self.study.sensitivity()
        if indices is not None:
            views.extend(V.sensitivity(indices))
        return views

    # -- wiring -------------------------------------------------------------------------------------------------
    def _wire(self) -> None:
        for which, select in self.choosers.items():
            select.on_change("value", partial(self._on_axis, which))
        self.filter.on_change("value", self._on_filter)
        self.filter_column.on_change("value", self._on_filter_column)
        self.reset.on_click(self._on_reset)
        self.histogram_column.on_change("value", lambda attr, old, new: self._refresh_histogram())
        self.minimise.on_change("value", self._on_objectives)
        self.maximise.on_change("value", self._on_objectives)
        self.method.on_change("value", self._on_method)
        self.rerun_button.on_click(self._on_rerun)
        self.cancel_button.on_click(self._on_cancel)
        self.svg.on_change("active", lambda attr, old, new: self._draw_runs())

    def _on_axis(self, which: str, attr: str, old: Any, new: Any) -> None:
        setattr(self, which, None if new == V.NONE else new)
        self.cloud.set_axes(self.x, self.y, self.colour, self.size)
        self._publish()

    def _filter_state(self, name: str) -> dict[str, Any]:
        """The range filter's properties showing column ``name``: its bounds and its current range."""
        b, r = self.decision.filters.bounds[name], self.decision.filters.ranges[name]
        end = b.hi if b.hi > b.lo else b.lo + 1.0  # a constant column: a slider it cannot narrow
        return {"title": self.study.table.label(name), "start": b.lo, "end": end, "step": (end - b.lo) / 1000,
                "value": (r.lo, r.hi if b.hi > b.lo else end), "tags": [name]}

    def _on_filter_column(self, attr: str, old: Any, new: Any) -> None:
        # the column first: setting the value below calls _on_filter here at once, which narrows tags[0]
        self.filter.tags = [new]
        self.filter.update(**self._filter_state(new))  # its value's echo from the page changes nothing

    def _on_filter(self, attr: str, old: Any, new: Any) -> None:
        name = self.filter.tags[0]
        before = self.decision.filters.ranges[name]
        self.decision.filters.set_range(name, *new)
        if self.decision.filters.ranges[name] != before:  # the slider's report of a value set here changes nothing
            self._refresh_soon()

    def _refresh_soon(self) -> None:
        """One refresh after a burst of changes (a dragged slider reports every step)."""
        if not self._pending:
            self._pending = True
            self.doc.add_next_tick_callback(self._refresh_pending)

    def _refresh_pending(self) -> None:
        self._pending = False
        self.refresh()

    def _on_reset(self) -> None:
        self.decision.filters.reset()
        self.filter.update(**self._filter_state(self.filter.tags[0]))
        self.refresh()

    def _on_cloud_selection(self, rows: list[int]) -> None:
        self.decision.select(rows)
        self._refresh_selection()

    def _on_ranking_selection(self, attr: str, old: Any, new: Any) -> None:
        assert self.ranking is not None  # its own callback
        if self._highlighting:  # the highlight set by the server, not a click
            return
        rows = self.ranking.source.data["row"]
        chosen = [int(rows[i]) for i in new if 0 <= i < len(rows)]
        if chosen:
            self.cloud.select(chosen)

    def _show_ranking_selection(self) -> None:
        """The ranking's highlighted rows: the selected designs it lists (a selected design ranked below its
        TOP is not in it)."""
        if self.ranking is None:
            return
        selected = set(self.decision.selection)
        self._highlight([k for k, r in enumerate(self.ranking.source.data["row"]) if int(r) in selected])

    def _highlight(self, positions: list[int]) -> None:
        assert self.ranking is not None  # called only once it exists
        if list(self.ranking.source.selected.indices) == positions:
            return
        self._highlighting = True
        try:
            self.ranking.source.selected.indices = positions
        finally:
            self._highlighting = False

    def _on_objectives(self, attr: str, old: Any, new: Any) -> None:
        objectives = [(c, "min") for c in self.minimise.value] + \
            [(c, "max") for c in self.maximise.value if c not in self.minimise.value]
        self.decision.set_objectives(objectives)
        self._rebuild_weights()
        self.refresh()

    def _on_method(self, attr: str, old: Any, new: Any) -> None:
        self.decision.set_method(new)
        self._refresh_ranking()

    def _on_weight(self, name: str, attr: str, old: Any, new: Any) -> None:
        self.decision.set_weight(name, float(new))
        self._refresh_ranking()

    def _rebuild_weights(self) -> None:
        # one slider per objective name for the tab's life: the page keeps a removed model for a while, and two
        # models of one name would make it ambiguous
        for slider in V.weight_sliders(self.decision.weights):
            name = slider.name.split(":", 1)[1]
            if name not in self._weight_sliders:
                slider.on_change("value", partial(self._on_weight, name))
                self._weight_sliders[name] = slider
            else:
                self.decision.set_weight(name, self._weight_sliders[name].value)
        self.weights.children = [self._weight_sliders[name] for name in self.decision.weights]

    # -- refreshing ------------------------------------------------------------------------------------------
    def refresh(self) -> None:
        """Everything that depends on the filters and the objectives."""
        masks = D.masks(self.study, self.decision)
        self.cloud.show(masks)
        if self.dimensions is not None:
            self.dimensions.show(masks)
        active = int((~masks["greyed"]).sum())
        front = int(masks["front"].sum())
        self._refresh_narrowed()
        self._refresh_histogram()
        self._refresh_ranking()
        self._refresh_selection()
        self.count.text = (f"<b>{active}</b> of {len(self.study.ids)} designs kept by the filters; "
                           f"{front} on the Pareto front of "
                           + (", ".join(f"{s} {html.escape(c)}" for c, s in self.decision.objectives) or "no objective")
                           + self._live_note())
        self._publish()

    def _live_note(self) -> str:
        """For a watched folder: its rows so far by status, and whether its study still runs."""
        if self.live is None:
            return ""
        counts = ", ".join(f"{v} {html.escape(k)}" for k, v in self.decision.status_counts().items())
        state = "running (or interrupted): new rows appear as they are written" if self.live.running else "complete"
        note = f"live: {len(self.study.ids)} rows ({counts}); the study is {state}"
        if self.live.problem and not self.live.running:  # a garbled or deleted table is not a complete study
            note = (f"live: the table cannot be read now ({html.escape(self.live.problem)}); shown: the "
                    f"{len(self.study.ids)} rows ({counts}) read before")
        if self.rebuilt_note:
            note += f"; {html.escape(self.rebuilt_note)}"
        return f"<br><span class='live'>{note}</span>"

    def _refresh_narrowed(self) -> None:
        f, label = self.decision.filters, self.study.table.label
        lines = [f"<li>{html.escape(label(c))}: {f.ranges[c].lo:.6g} … {f.ranges[c].hi:.6g}</li>"
                 for c in f.narrowed()]
        self.narrowed.text = ("<b>narrowed</b><ul>" + "".join(lines) + "</ul>") if lines else \
            "<i>no column narrowed: choose one above and drag its range</i>"

    def _refresh_histogram(self) -> None:
        name = self.histogram_column.value
        self.histogram["source"].data = D.histogram(self.decision.filters.values(name), self.decision.active())
        self.histogram["figure"].xaxis.axis_label = self.study.table.label(name)

    def _refresh_ranking(self) -> None:
        if self.ranking is None:  # the Decide tab was not shown yet
            return
        data = D.ranking_rows(self.study, self.decision, TOP)
        wanted = [(field, html.escape(title)) for field, title in D.ranking_columns(self.study, self.decision)]
        if [(c.field, c.title) for c in self.ranking.columns[3:]] != wanted:  # objectives changed
            self.ranking.columns = V.ranking_columns(D.ranking_columns(self.study, self.decision))
        # the table's selected rows are positions in its old rows: let go of before the rows change, then set to
        # where the selected designs are now.  bokeh 3.4's DataTable throws "Out of bounds: 0 <= 0 < 0" in the
        # page for a selected position past the end of its new rows (the emptied table below has none:
        # bokeh/bokeh#13931); bokeh 3.9 does not throw (its BitSet.get answers false there, bokeh/bokeh#14566)
        # but kept the old positions, which then highlighted other designs
        self._highlight([])
        # emptied first: bokeh 3.9 does not redraw a DataTable whose source's data is replaced by as many rows
        # as before (bokeh/bokeh#15328); a new source would make bokeh walk the whole document again
        self.ranking.source.data = {k: [] for k in data}
        self.ranking.source.data = data
        self._show_ranking_selection()
        self._refresh_radar()
        self._publish()

    def _refresh_radar(self) -> None:
        if self.radar is None:
            return
        data = D.radar(self.decision, self.decision.selection[:MAX_RERUN])
        self.radar["spokes"].data = {"x": data["spoke_x"], "y": data["spoke_y"], "label": data["labels"]}
        self.radar["designs"].data = V.radar_columns(data, [self.study.ids[r] for r in data["rows"]])
        k = len(self.decision.objectives)
        self.radar_note.text = "" if k >= 2 else (
            "<i>the radar compares designs over two objectives or more: "
            + ("this study states one objective with a sense; " if k == 1 else "")
            + "choose more under minimise or maximise</i>")

    def _refresh_selection(self) -> None:
        rows = self.decision.selection
        self.cloud.show_selection(rows)
        self._show_ranking_selection()
        if self.surrogate is not None:
            self.surrogate.hold(self._held_row())
        if self.dimensions is not None:
            self.dimensions.show_selection(rows)
        self._refresh_radar()
        if not rows:
            self.selected.text = "<p>No design selected: click points of the cloud or rows of the ranking.</p>"
            self.export.text = ""
            return
        frame = self.decision.selected_frame()
        shown = [c for c in ["point_id", *self.study.table.parameter_columns(),
                             *[c for c, _ in self.decision.objectives], "status", "message"] if c in frame.columns]
        self.selected.text = f"<p><b>{len(rows)} design(s) selected</b></p>" + \
            frame[list(dict.fromkeys(shown))].head(50).to_html(index=False, float_format=lambda v: f"{v:.6g}")
        try:
            commands = self.decision.run_commands()
        except Exception as exc:  # a table without point_id: no commands, the CSV still
            commands = [f"# {exc}"]
        script = "\n".join(commands) + "\n"
        self.export.text = (
            f"<p><a download='selection.csv' href='{D.data_url(self.decision.selection_csv(), 'text/csv')}'>"
            f"selection as CSV</a> · <a download='selection.sh' href='{D.data_url(script, 'text/x-shellscript')}'>"
            f"as cosim run commands</a></p><pre>{html.escape(script)}</pre>")

    def _failures(self) -> list:
        """The title and table of the designs not ok; none when every design is ok."""
        n = int((self.study.status != "ok").sum())
        if not n:
            return []
        more = f", the first {MAX_FAILURES_LISTED} listed" if n > MAX_FAILURES_LISTED else ""
        return [V.text(f"<b>not ok</b> (failed, timed out, crashed): {n}{more}", "failures-title"),
                V.failures_table(D.failures(self.study, MAX_FAILURES_LISTED))]

    def _summary(self) -> str:
        counts = self.decision.status_counts()
        parts = ", ".join(f"{v} {k}" for k, v in counts.items())
        return (f"<h3>{html.escape(self.study.name)}: a {html.escape(self.study.kind)}</h3>"
                f"<p>{len(self.study.ids)} designs: {html.escape(parts)}. Table: "
                f"<code>{html.escape(str(self.study.table.path))}</code></p>")

    # -- re-runs ------------------------------------------------------------------------------------------------
    def _on_rerun(self) -> None:
        rows = self.decision.selection[:MAX_RERUN]
        if not rows:
            self.rerun_status.text = "select designs first"
            return
        self.rerun_button.disabled = True
        self.cancel_button.disabled = False
        timeout = rerun_timeout(self.study.table, rows)
        self.rerun_status.text = f"re-running {len(rows)} design(s) … (stopped after {timeout:.0f} s)"
        threading.Thread(target=self._rerun, args=(rows, timeout), daemon=True, name="cosim-room-rerun").start()

    def _rerun(self, rows: list[int], timeout: float) -> None:
        try:  # in a child process: a timeout and the Cancel button end it, a hung FMU too (rerun_job)
            self.rerun_job = job = RerunJob(self.study.table, rows, self.study.spec_path, timeout)
            runs = job.wait()
            outcome: Any = (runs, *A.motions(runs))  # the link frames here: not in the server's loop
        except Exception as exc:  # a bad spec or value, a timeout, a cancel: shown in the page, never a dead server
            outcome = exc
        self.doc.add_next_tick_callback(partial(self._show_runs, outcome))

    def _on_cancel(self) -> None:
        if self.rerun_job is not None:
            self.rerun_status.text = "cancelling the re-run …"
            self.rerun_job.cancel()  # its wait() ends, and _show_runs says so

    def _show_runs(self, outcome: Any) -> None:
        self.rerun_button.disabled = False
        self.cancel_button.disabled = True
        self.rerun_job = None
        if isinstance(outcome, RerunStopped):
            self.rerun_status.text = f"<span style='color:#a40000'>re-run {html.escape(str(outcome))}</span>"
            return
        if isinstance(outcome, Exception):
            first = str(outcome).splitlines()[0] if str(outcome) else repr(outcome)
            self.rerun_status.text = f"<span style='color:#a40000'>re-run failed: {html.escape(first)}</span>"
            return
        self.runs, self.motions, self.motion_note = outcome
        self._draw_runs()
        self.rerun_status.text = "; ".join(
            f"{html.escape(run.point_id)}: {html.escape(run.result.status)} in {run.result.elapsed:.2f} s"
            + (f" ({html.escape(run.result.message)})" if run.result.message else "") for run in self.runs)

    def _draw_runs(self) -> None:
        """The re-run designs' trace plots and 3-D view, drawn as SVG when the switch says so (bokeh picks a
        plot's backend when its view is made, so they are made anew); their save buttons name the file
        (``cosim-trace_robot_q.png`` or ``.svg`` for ``trace:robot.q``)."""
        backend = "svg" if self.svg.active else "canvas"
        recorded: list[str] = []
        for run in self.runs:
            if run.result.traces is not None:
                recorded += [c for c in D.trace_columns(run.result.traces) if c not in recorded]
        figures = V.trace_figures(port_groups(recorded), self.runs, backend)
        same = self.link_view is not None and list(map(id, self.link_view.motions)) == list(map(id, self.motions))
        shown = self.link_view.state() if same else {}  # the same designs drawn anew (as SVG): same time, angles
        if self.link_view is not None:  # its play timer in the page stops with it
            self.link_view.play.active = False
        self.link_view = view = A.LinkView(self.motions, backend, **shown) if self.motions else None
        for fig in figures:  # a 200 px plot's toolbar has room for four tools: save went into its "…" menu
            fig.height = 240
        V.name_save_tools(figures + ([view.figure] if view else []))
        self.traces.children = figures
        self.viewer.children = [view.layout] if view else [A.note(self.motion_note)] if self.motion_note else []


def make_document(doc: Any, study: D.Study | LiveStudy, webgl: bool | None = None,
                  aggregate_above: int | None = None) -> None:
    """Fill ``doc`` (a new browser tab) with the room of ``study``; of a watched folder (LiveStudy), a page that
    waits for its first rows when it has none yet."""
    if isinstance(study, D.Study):
        Room(doc, study, webgl, aggregate_above)
        return
    live = study
    first = live.current()
    if first is not None:
        Room(doc, first, webgl, aggregate_above, live)
        return
    doc.title = f"cosim: {live.folder.name}"
    note = V.text(f"<p>Waiting for the first rows of <code>{html.escape(str(live.folder))}</code> …</p>",
                  "waiting")  # not 'count': the page keeps a removed model's name for a while
    doc.add_root(note)

    def look() -> None:
        ready = live.current()
        if ready is not None:
            doc.remove_periodic_callback(waiting)
            Room(doc, ready, webgl, aggregate_above, live)
            doc.remove_root(note)

    waiting = doc.add_periodic_callback(look, int(live.every * 1000))
