"""The decision room's shortlist: designs the designer pins, compared side by side (issue 39).

- *Pin selected* (``pin``) adds the designs selected (by a click in the cloud, a row of the ranking, a box in
  the Dimensions tab) to the shortlist, in pick order; *Unpin selected* (``unpin``) takes them out again and
  *Clear shortlist* (``clear-shortlist``) empties it.
- ``shortlist``: a table with a row per design parameter and per objective (named with its unit) and a column
  per pinned design (its id as the title): the designs side by side.
- *Re-run shortlist* (``rerun-shortlist``) re-runs the pinned designs (at most :data:`MAX_RERUN`) in a child
  process of the server, stopped at its timeout (:mod:`cosim.analysis.rerun_job`), with the spec's recorded signals, and overlays their traces, one plot per port
  (``shortlist-trace:<port>``), a colour per design (its elements in that colour's family:
  :func:`.views.element_style`).

The shortlist holds design ids, not rows: they stay the same when a running study's table grows, and they are
what the room's link carries (:mod:`.link`).  Every id and name reaches the page escaped.
"""

from __future__ import annotations

import html
import threading
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

from bokeh.layouts import column, row
from bokeh.models import ColumnDataSource
from bokeh.models.widgets import DataTable, NumberFormatter, TableColumn

from cosim.analysis.decision import Decision
from cosim.analysis.rerun import port_groups
from cosim.analysis.rerun_job import RerunJob
from cosim.analysis.room import data as D
from cosim.analysis.room import views as V

MAX_PINNED = 12  # designs side by side (columns of the table)
MAX_RERUN = 8  # designs re-run at once (one colour each)


def compare_rows(study: D.Study, decision: Decision, ids: Sequence[str]) -> dict[str, list]:
    """The comparison's columns: ``quantity`` (a parameter's or objective's name with its unit, plain text),
    ``role`` ('parameter' or 'min'/'max' for an objective) and ``d0``, ``d1``, ... the value of each design of
    ``ids`` (NaN for an id the table does not hold)."""
    where = {str(i): r for r, i in enumerate(study.ids)}
    rows = [where.get(str(i)) for i in ids]
    names = [(c, "parameter") for c in D.ranking_parameters(study, decision)] + list(decision.objectives)
    label = study.table.label
    data: dict[str, list] = {"quantity": [label(c) for c, _ in names], "role": [role for _, role in names]}
    values = [decision.filters.values(c) for c, _ in names]
    for k, r in enumerate(rows):
        data[f"d{k}"] = [float(v[r]) if r is not None else float("nan") for v in values]
    return data


class Shortlist:
    """The shortlist of one browser tab (module docstring).  ``on_change()`` is called after every change of
    the pinned ids (the room's link follows them)."""

    def __init__(self, study: D.Study, decision: Decision, doc: Any, on_change: Callable[[], None],
                 ids: Sequence[str] = ()):
        self.study, self.decision, self.doc, self.on_change = study, decision, doc, on_change
        known = set(map(str, study.ids))
        self.ids: list[str] = list(dict.fromkeys(str(i) for i in ids if str(i) in known))[:MAX_PINNED]
        self.pin = V.button("Pin selected", "pin")
        self.unpin = V.button("Unpin selected", "unpin")
        self.clear = V.button("Clear shortlist", "clear-shortlist")
        self.rerun = V.button("Re-run shortlist", "rerun-shortlist", "primary")
        self.status = V.text("", "shortlist-status")
        self.note = V.text("", "shortlist-note")
        self.source = ColumnDataSource({"quantity": [], "role": []})  # the table's rows
        self.table = DataTable(source=self.source, columns=[], name="shortlist",
                               width=V.WIDTH, height=260, index_position=None, autosize_mode="none")
        self.traces = column(name="shortlist-traces")
        self.pin.on_click(self._on_pin)
        self.unpin.on_click(self._on_unpin)
        self.clear.on_click(self._on_clear)
        self.rerun.on_click(self._on_rerun)
        self.layout = column(V.text("<b>shortlist</b>: pin designs selected in the cloud or the ranking and "
                                    "compare them side by side", "shortlist-title"),
                             row(self.pin, self.unpin, self.clear, self.rerun), self.note, self.table, self.status,
                             self.traces, name="shortlist-box")
        self.show()

    def reload(self, study: D.Study, decision: Decision) -> None:
        """The same folder with more rows: the same ids, their values anew."""
        self.study, self.decision = study, decision
        self.show()

    # -- the pinned ids --------------------------------------------------------------------------------------
    def set_ids(self, ids: Sequence[str]) -> None:
        known = set(map(str, self.study.ids))
        self.ids = list(dict.fromkeys(str(i) for i in ids if str(i) in known))[:MAX_PINNED]
        self.show()
        self.on_change()

    def _on_pin(self) -> None:
        selected = [str(self.study.ids[r]) for r in self.decision.selection]
        if not selected:
            self.note.text = "<i>select designs first (a click in the cloud or on a row of the ranking)</i>"
            return
        self.set_ids(self.ids + selected)

    def _on_unpin(self) -> None:
        selected = {str(self.study.ids[r]) for r in self.decision.selection}
        self.set_ids([i for i in self.ids if i not in selected])

    def _on_clear(self) -> None:
        self.set_ids([])

    # -- the comparison --------------------------------------------------------------------------------------
    def show(self) -> None:
        """The table of the pinned designs, side by side."""
        data = compare_rows(self.study, self.decision, self.ids)
        number = NumberFormatter(format="0.[0000]")
        width = 140  # a 16-digit id whole
        columns = [TableColumn(field="quantity", title="", width=220), TableColumn(field="role", title="", width=70)]
        columns += [TableColumn(field=f"d{k}", title=html.escape(i), formatter=number, width=width)
                    for k, i in enumerate(self.ids)]
        if [(c.field, c.title) for c in self.table.columns] != [(c.field, c.title) for c in columns]:
            self.table.columns = columns
        # a row clicked in the table: let go of before its rows change (bokeh 3.4 throws in the page for a selected
        # row past the end of the emptied table, bokeh/bokeh#13931; see app.Room._refresh_ranking)
        self.source.selected.indices = []
        self.source.data = {k: [] for k in data}  # bokeh/bokeh#15328, see app.Room._refresh_ranking
        self.source.data = data
        self.table.height = min(30 + 26 * len(data["quantity"]), 420)
        full = f" (at most {MAX_PINNED})" if len(self.ids) >= MAX_PINNED else ""
        self.note.text = (f"<i>{len(self.ids)} design(s) pinned{full}</i>" if self.ids else
                          "<i>no design pinned: select designs, then <b>Pin selected</b></i>")

    # -- re-runs ---------------------------------------------------------------------------------------------
    def _on_rerun(self) -> None:
        where = {str(i): r for r, i in enumerate(self.study.ids)}
        rows = [where[i] for i in self.ids if i in where][:MAX_RERUN]
        if not rows:
            self.status.text = "pin designs first"
            return
        self.rerun.disabled = True
        self.status.text = f"re-running {len(rows)} pinned design(s) …"
        threading.Thread(target=self._rerun, args=(rows,), daemon=True, name="cosim-room-shortlist").start()

    def _rerun(self, rows: list[int]) -> None:
        try:
            # in a child process, stopped at its timeout (cosim.analysis.rerun_job): a hung design never keeps it
            outcome: Any = RerunJob(self.study.table, rows, self.study.spec_path).wait()
        except Exception as exc:  # a bad spec or value, a timeout: shown in the page, never a dead server
            outcome = exc
        self.doc.add_next_tick_callback(partial(self._show_runs, outcome))

    def _show_runs(self, outcome: Any) -> None:
        self.rerun.disabled = False
        if isinstance(outcome, Exception):
            first = str(outcome).splitlines()[0] if str(outcome) else repr(outcome)
            self.status.text = f"<span style='color:#a40000'>re-run failed: {html.escape(first)}</span>"
            return
        recorded: list[str] = []
        for run in outcome:
            if run.result.traces is not None:
                recorded += [c for c in D.trace_columns(run.result.traces) if c not in recorded]
        figures = V.trace_figures(port_groups(recorded), outcome, prefix="shortlist-trace")
        for fig in figures:
            fig.height = 240
        V.name_save_tools(figures)
        self.traces.children = figures
        self.status.text = "; ".join(
            f"{html.escape(run.point_id)}: {html.escape(run.result.status)} in {run.result.elapsed:.2f} s"
            + (f" ({html.escape(run.result.message)})" if run.result.message else "") for run in outcome)
