"""One browser tab of the decision room: the views of :mod:`.views` wired to the tab's own Decision.

Tabs of the page:

- **Points**: x, y, colour and size choosers; the cloud (WebGL); a range filter per numeric column; a
  histogram of any column, all rows against the rows kept; the failed, timed-out and crashed designs with
  their messages.  A click (tap, box or lasso) on the cloud selects designs.
- **Decide**: objectives to minimise and to maximise, the ranking method (weighted sum, TOPSIS), a weight
  per objective, the best designs (a click on a row selects it), the radar of the selected designs.
- **Selection**: the selected designs, their re-run with the spec's recorded signals (traces overlaid per
  port), the selection as CSV and as ``cosim run --point`` commands.
- **Study**: counts by status; an optimisation's hypervolume against evaluations; a sensitivity analysis's
  indices with their confidence intervals.

Every change goes through the Decision, and :meth:`Room.refresh` recomputes what depends on it.  A re-run
runs in a thread of its own so the server keeps answering; its traces are drawn from the document's next
tick (bokeh's rule: a document is changed only while its lock is held).
"""

from __future__ import annotations

import html
import threading
from functools import partial
from typing import Any

import numpy as np
from bokeh.core.property.validation import without_property_validation
from bokeh.layouts import column, row
from bokeh.models import MultiChoice, Select, TabPanel, Tabs

from cosim.analysis.decision import Decision
from cosim.analysis.ranking import METHODS
from cosim.analysis.rerun import port_groups, rerun_rows
from cosim.analysis.room import data as D
from cosim.analysis.room import views as V

TOP = 20  # designs in the ranking table
MAX_RERUN = 8  # designs re-run at once (one colour each)


class Room:
    """The models and callbacks of one document (module docstring)."""

    @without_property_validation  # see refresh
    def __init__(self, doc: Any, study: D.Study, webgl: bool = True):
        self.doc, self.study = doc, study
        self.decision = Decision(study.table)
        table = study.table
        self.x, self.y, self.colour = study.default_axes(self.decision)
        self.size: str | None = None
        self.runs: list = []
        self._pending = False
        self._weight_sliders: dict[str, Any] = {}
        columns = self.decision.filters.columns

        # -- Points
        self.choosers = V.axis_choosers(columns, self.x, self.y, self.colour)
        self.cloud = V.cloud(D.points(study, self.decision, self.x, self.y, self.colour, None),
                             D.status_palette(study.status),
                             table.label(self.x), table.label(self.y),
                             table.label(self.colour) if self.colour else None, webgl)
        self.count = V.text("", "count")
        self.sliders = V.range_sliders(self.decision.filters.bounds, {c: table.label(c) for c in columns})
        self.reset = V.button("Reset filters", "reset-filters")
        self.histogram_column = Select(title="histogram of", value=self.colour or self.x, options=list(columns),
                                       name="choose-histogram", width=220)
        self.histogram = V.histogram(D.histogram(self.decision.filters.values(self.histogram_column.value),
                                                 self.decision.active()), table.label(self.histogram_column.value))
        not_ok = np.flatnonzero(study.status != "ok")
        self.failures = V.failures_table({"point_id": list(study.ids[not_ok]), "status": list(study.status[not_ok]),
                                          "message": list(study.messages[not_ok])})

        # -- Decide
        senses = dict(self.decision.objectives)
        self.minimise = MultiChoice(title="minimise", options=list(columns), name="minimise", width=360,
                                    value=[c for c, s in senses.items() if s == "min"])
        self.maximise = MultiChoice(title="maximise", options=list(columns), name="maximise", width=360,
                                    value=[c for c, s in senses.items() if s == "max"])
        self.method = Select(title="ranking", value="weighted_sum", options=list(METHODS.items()), name="method",
                             width=200)
        self.weights = column(name="weights")
        self.ranking = V.ranking_table(self.decision.objectives, D.ranking_rows(study, self.decision, TOP))
        self.ranking.source.selected.on_change("indices", self._on_ranking_selection)
        self.radar = V.radar(D.radar(self.decision, []), [])

        # -- Selection
        self.selected = V.text("<p>No design selected: click points of the cloud or rows of the ranking.</p>",
                               "selected")
        self.rerun_button = V.button("Re-run selected", "rerun", "primary")
        self.rerun_status = V.text("", "rerun-status")
        self.traces = column(name="traces")
        self.export = V.text("", "export")

        # -- Study
        self.summary = V.text(self._summary(), "summary")
        study_views: list = [self.summary]
        history = study.hypervolume()
        if history is not None:
            study_views.append(V.hypervolume(*history))
        indices = study.sensitivity()
        if indices is not None:
            study_views.extend(V.sensitivity(indices))

        self._wire()
        self._rebuild_weights()
        self.refresh()
        self.doc.title = f"cosim: {study.name}"
        points = row(column(row(*self.choosers.values()), self.cloud["figure"], self.count,
                            row(self.histogram_column), self.histogram["figure"],
                            V.text("<b>not ok</b> (failed, timed out, crashed)", "failures-title"), self.failures),
                     column(self.reset, V.scrolling(list(self.sliders.values()), 900, "filters")))
        decide = row(column(row(self.minimise, self.maximise), self.method, self.weights),
                     column(self.ranking, self.radar["figure"]))
        selection = column(self.selected, row(self.rerun_button, self.rerun_status), self.traces, self.export)
        self.tabs = Tabs(tabs=[TabPanel(child=points, title="Points"), TabPanel(child=decide, title="Decide"),
                               TabPanel(child=selection, title="Selection"),
                               TabPanel(child=column(*study_views), title="Study")], name="tabs")
        doc.add_root(self.tabs)

    # -- wiring -------------------------------------------------------------------------------------------------
    def _wire(self) -> None:
        for which, select in self.choosers.items():
            select.on_change("value", partial(self._on_axis, which))
        for name, slider in self.sliders.items():
            slider.on_change("value", partial(self._on_filter, name))
        self.reset.on_click(self._on_reset)
        self.histogram_column.on_change("value", lambda attr, old, new: self._refresh_histogram())
        self.cloud["source"].selected.on_change("indices", self._on_cloud_selection)
        self.minimise.on_change("value", self._on_objectives)
        self.maximise.on_change("value", self._on_objectives)
        self.method.on_change("value", self._on_method)
        self.rerun_button.on_click(self._on_rerun)

    @without_property_validation
    def _on_axis(self, which: str, attr: str, old: Any, new: Any) -> None:
        value = None if new == V.NONE else new
        setattr(self, which, value)
        self.cloud["source"].data.update(self._point_columns(which))
        if which in ("x", "y"):
            axis = self.cloud["figure"].xaxis if which == "x" else self.cloud["figure"].yaxis
            axis.axis_label = self.study.table.label(value)
        if which == "colour":
            V.colour_by(self.cloud["mapper"], self.cloud["colour_bar"], self.cloud["source"].data["c"],
                        self.study.table.label(value) if value else None)

    def _point_columns(self, which: str) -> dict[str, Any]:
        columns = D.points(self.study, self.decision, self.x, self.y, self.colour, self.size)
        keys = {"x": ["x"], "y": ["y"], "colour": ["c"], "size": ["s"]}[which]
        return {k: columns[k] for k in keys}

    def _on_filter(self, name: str, attr: str, old: Any, new: Any) -> None:
        before = self.decision.filters.ranges[name]
        self.decision.filters.set_range(name, *new)
        if self.decision.filters.ranges[name] != before:  # a slider's first report of its own value changes nothing
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
        for name, slider in self.sliders.items():
            b = self.decision.filters.bounds[name]
            slider.value = (b.lo, slider.end)  # each fires _on_filter; the last refresh counts
        self.refresh()

    def _on_cloud_selection(self, attr: str, old: Any, new: Any) -> None:
        self.decision.select(list(new))
        self._refresh_selection()

    def _on_ranking_selection(self, attr: str, old: Any, new: Any) -> None:
        rows = self.ranking.source.data["row"]
        chosen = [int(rows[i]) for i in new]
        if chosen:
            self.cloud["source"].selected.indices = chosen  # fires _on_cloud_selection

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
    @without_property_validation  # bokeh would check each of the 5 masks' n booleans one by one (seconds at 10^5)
    def refresh(self) -> None:
        """Everything that depends on the filters and the objectives."""
        masks = D.masks(self.study, self.decision)
        for layer, mask in masks.items():
            self.cloud["filters"][layer].booleans = mask
        active = int((~masks["greyed"]).sum())
        front = int(masks["front"].sum())
        self._refresh_histogram()
        self._refresh_ranking()
        self._refresh_selection()
        self.count.text = (f"<b>{active}</b> of {len(self.study.ids)} designs kept by the filters; "
                           f"{front} on the Pareto front of "
                           + (", ".join(f"{s} {c}" for c, s in self.decision.objectives) or "no objective"))

    def _refresh_histogram(self) -> None:
        name = self.histogram_column.value
        self.histogram["source"].data = D.histogram(self.decision.filters.values(name), self.decision.active())
        self.histogram["figure"].xaxis.axis_label = self.study.table.label(name)

    def _refresh_ranking(self) -> None:
        data = D.ranking_rows(self.study, self.decision, TOP)
        columns = [c.field for c in self.ranking.columns]
        if columns != ["rank", "point_id", "score", *[f"o{k}" for k in range(len(self.decision.objectives))]] \
                or [c.title for c in self.ranking.columns[3:]] != [f"{n} ({s})" for n, s in self.decision.objectives]:
            self.ranking.columns = V.ranking_table(self.decision.objectives, data).columns  # objectives changed
        # emptied first: bokeh 3.9 does not redraw a DataTable whose source's data is replaced by as many rows
        # as before (bokeh/bokeh#15328); a new source would make bokeh walk the whole document again
        self.ranking.source.data = {k: [] for k in data}
        self.ranking.source.data = data
        self._refresh_radar()

    def _refresh_radar(self) -> None:
        data = D.radar(self.decision, self.decision.selection[:MAX_RERUN])
        self.radar["spokes"].data = {"x": data["spoke_x"], "y": data["spoke_y"], "label": data["labels"]}
        self.radar["designs"].data = V.radar_columns(data, [self.study.ids[r] for r in data["rows"]])

    @without_property_validation
    def _refresh_selection(self) -> None:
        rows = self.decision.selection
        mask = np.zeros(len(self.study.ids), dtype=bool)
        mask[rows] = True
        self.cloud["filters"]["selected"].booleans = mask
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
        self.rerun_status.text = f"re-running {len(rows)} design(s) …"
        threading.Thread(target=self._rerun, args=(rows,), daemon=True, name="cosim-room-rerun").start()

    def _rerun(self, rows: list[int]) -> None:
        try:
            runs = rerun_rows(self.study.table, rows, self.study.spec_path)
            outcome: Any = runs
        except Exception as exc:  # a bad spec or value is shown in the page, never a dead server
            outcome = exc
        self.doc.add_next_tick_callback(partial(self._show_runs, outcome))

    def _show_runs(self, outcome: Any) -> None:
        self.rerun_button.disabled = False
        if isinstance(outcome, Exception):
            first = str(outcome).splitlines()[0] if str(outcome) else repr(outcome)
            self.rerun_status.text = f"<span style='color:#a40000'>re-run failed: {html.escape(first)}</span>"
            return
        self.runs = outcome
        recorded = []
        for run in outcome:
            if run.result.traces is not None:
                recorded += [c for c in D.trace_columns(run.result.traces) if c not in recorded]
        self.traces.children = V.trace_figures(port_groups(recorded), outcome)
        self.rerun_status.text = "; ".join(
            f"{html.escape(run.point_id)}: {html.escape(run.result.status)} in {run.result.elapsed:.2f} s"
            + (f" ({html.escape(run.result.message)})" if run.result.message else "") for run in outcome)


def make_document(doc: Any, study: D.Study, webgl: bool = True) -> Room:
    """Fill ``doc`` (a new browser tab) with the room of ``study``."""
    return Room(doc, study, webgl)
