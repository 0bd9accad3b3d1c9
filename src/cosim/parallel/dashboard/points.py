"""A page of the Dask dashboard counting a sweep's *points* (done, failed, of how many) as they finish.

Dask's own progress bars count tasks, and a cosim task runs a batch of
points, so they cannot show how many points are done.  This module adds a
page to the dashboard that can:

- Workers: :class:`BatchProgress`, used by ``cosim.parallel.tasks.run_batch``, sends the
  number of points of its task done and not ok so far as a Dask event
  (``Worker.log_event``, topic ``cosim-points``) while the batch runs (at
  most every ``EVERY`` seconds) and once when it ends.
- Scheduler: :class:`PointsPlugin`, a scheduler plugin, reads those events
  (``SchedulerPlugin.log_event``), keeps per study the counts of its tasks
  (dropping an attempt lost with its worker: ``transition`` out of
  ``processing`` to anything but ``memory``), and serves ``/cosim`` (an HTML
  page whose script, ``/cosim/page.js``, redraws its table from
  ``/cosim/points.json`` every second without reloading the page: points done,
  not ok so far, the rate over the last ``RATE_WINDOW`` seconds and the time
  left at that rate) on the dashboard's web server.  It adds "Cosim" to the
  dashboard's navigation bar.
- Client: :func:`open_board` registers the plugin and announces the study
  (its total and the points already stored when resuming, and the link of
  its decision room when it runs with ``--explore``: the page links it); the
  returned :class:`Board` says where the page is, or why there is none.

The plugin is sent to the scheduler *by value* (cloudpickle), so the page
does not depend on the cosim version installed where the scheduler runs (it
must have cosim anyway: Dask's scheduler unpickles every task, see
:mod:`cosim.parallel.cluster.scheduler_check`).  It needs the client's Python version
there; when the plugin cannot be installed the study runs as before and its
start line says that there is no page and why.  Everything the plugin uses is
in this module, the standard library, tornado and distributed: nothing else
may be imported at module level here.  The page is served at the web
server's root (``/cosim``), not under a ``--dashboard-prefix``.
"""

from __future__ import annotations

import collections
import html
import json
import sys
import time
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any, Iterator

from distributed.diagnostics.plugin import SchedulerPlugin
from tornado import web

from cosim.parallel.cluster.interrupts import scheduler_gone

if TYPE_CHECKING:  # only named: this module is sent to the scheduler by value, needing nothing of cosim there
    from dask.typing import Key
    from distributed import Worker

    from cosim.execution.point_row import PointRow

TOPIC = "cosim-points"
PLUGIN_NAME = "cosim-points-1"  # the version of the event protocol: a scheduler may keep an older plugin
ROUTE = "cosim"  # the page; its data: ROUTE + "/points.json"
EVERY = 0.5  # seconds between a worker's events for one running task
KEPT_STUDIES = 20  # the page lists the studies of this scheduler, the most recent this many
RATE_WINDOW = 30.0  # seconds: the rate is that of the points done within the last this many seconds


def study_of(key: Any) -> str | None:
    """The study id a task key carries (``...-<study>.<unique>``, see ``dashboard.task_key``), or None."""
    if not isinstance(key, str) or "-" not in key:
        return None
    study, dot, _ = key.rpartition("-")[2].partition(".")
    return study if dot and study else None


# -- worker side -----------------------------------------------------------------------


class BatchProgress:
    """Counts the rows of the batch running in this Dask task and sends them as events (module docstring).

    Outside a Dask worker (a sample run, a test) it does nothing.
    """

    def __init__(self) -> None:
        self.done = self.failed = 0
        self._sent_at = time.monotonic()
        self._flush_pending = self._closed = False
        self._worker: Worker | None = None
        self._key: Key | None = None
        try:
            from distributed import get_worker

            self._worker = get_worker()
            self._key = self._worker.get_current_task()
        except (ImportError, ValueError):  # not on a worker
            self._worker, self._key = None, None
        if study_of(self._key) is None:
            self._worker = None

    def row(self, row: PointRow) -> None:
        """One more point finished with ``row``: sent now, or within EVERY seconds (the next point may take hours)."""
        self.done += 1
        self.failed += not row.ok
        if self._worker is None:
            return
        wait = EVERY - (time.monotonic() - self._sent_at)
        if wait <= 0:
            self._send()
        elif not self._flush_pending:  # later, from the worker's event loop (this is the task's thread)
            self._flush_pending = True
            loop = self._worker.loop
            loop.add_callback(loop.call_later, wait, self._flush)

    def close(self) -> None:
        """The batch ended: its final counts (sent before Dask reports the task done: same stream, in order)."""
        self._closed = True
        if self._worker is not None:
            self._send()

    def _flush(self) -> None:
        self._flush_pending = False
        if not self._closed:
            self._send()

    def _send(self) -> None:
        self._sent_at = time.monotonic()
        worker = self._worker
        if worker is None:  # never: row() and close() send only with a worker
            return
        try:
            worker.log_event(TOPIC, {"key": self._key, "done": self.done, "failed": self.failed})
        except Exception:  # a closing worker: the counts are the page's only, never the point's business
            pass


# -- scheduler side ---------------------------------------------------------------------


class PointsPlugin(SchedulerPlugin):
    """Per study: total, points stored before this run, and per task the latest counts (module docstring)."""

    idempotent = True  # a second sweep on the same scheduler keeps the plugin and its history

    def __init__(self) -> None:
        self.studies: dict[str, dict[str, Any]] = {}
        self.tasks: dict[str, dict[str, tuple[int, int]]] = {}  # study -> task key -> (done, failed)
        self.running: dict[str, set[str]] = {}  # study -> keys of tasks still running
        self.history: dict[str, collections.deque[tuple[float, int]]] = {}  # study -> (time, points done this run)

    async def start(self, scheduler: Any) -> None:
        handlers = [(rf"/{ROUTE}", PageHandler, {"plugin": self}),
                    (rf"/{ROUTE}/points.json", JsonHandler, {"plugin": self}),
                    (rf"/{ROUTE}/page.js", ScriptHandler)]
        application = getattr(scheduler, "http_application", None)
        if application is not None:
            application.add_handlers(r".*", handlers)
        _link_from_the_navigation_bar(scheduler)

    def dashboard_loaded(self, scheduler: Any) -> None:
        """The dashboard was built after this plugin started (see :mod:`cosim.parallel.dashboard.on_demand`)."""
        _link_from_the_navigation_bar(scheduler)

    def log_event(self, topic: str, msg: Any) -> None:
        if topic != TOPIC or not isinstance(msg, dict):
            return
        if msg.get("op") == "start":
            self._start(msg)
        elif msg.get("op") == "end":
            name = msg.get("study")
            study = self.studies.get(name) if isinstance(name, str) else None  # study ids are str
            if study is not None:
                study.update(state=str(msg.get("state", "ended")), ended=time.time())
        elif "key" in msg:
            study_id = study_of(msg["key"])
            if study_id is not None and study_id in self.tasks:
                self.tasks[study_id][msg["key"]] = (int(msg.get("done", 0)), int(msg.get("failed", 0)))
                if not msg.get("final"):  # final: rows the client made for a task lost with its workers
                    self.running[study_id].add(msg["key"])
                self._note_progress(study_id)

    def _start(self, msg: dict[str, Any]) -> None:
        study = str(msg.get("study"))
        self.studies[study] = {"study": study, "name": str(msg.get("name", "")), "kind": str(msg.get("kind", "")),
                               "total": int(msg.get("total", 0)), "before": int(msg.get("before", 0)),
                               "client": msg.get("client"), "room": msg.get("room"),
                               "state": "running", "started": time.time(), "ended": None}
        self.tasks[study], self.running[study] = {}, set()
        self.history[study] = collections.deque([(time.time(), 0)])
        for old in list(self.studies)[:-KEPT_STUDIES]:
            for table in (self.studies, self.tasks, self.running, self.history):
                table.pop(old, None)

    def _note_progress(self, study: str) -> None:
        """Remember when the study had how many points done (this run), for the rate; forget what is older
        than the rate's window, keeping one sample from before it to measure from."""
        history = self.history.setdefault(study, collections.deque())
        now = time.time()
        history.append((now, sum(d for d, _ in self.tasks[study].values())))
        while len(history) > 2 and history[1][0] < now - RATE_WINDOW:
            history.popleft()

    def _rate(self, study: str, now: float) -> float | None:
        """Points per second over the last RATE_WINDOW seconds (from the study's start when it is younger);
        None before two counts are known. Points lost with their workers and counted again may dip it."""
        history = self.history.get(study)
        if not history or len(history) < 2:
            return None
        (t0, d0), (_, d1) = history[0], history[-1]
        span = max(now, history[-1][0]) - t0
        return max(d1 - d0, 0) / span if span > 0 else None

    def transition(self, key: Any, start: str, finish: str, *args: Any, **kwargs: Any) -> None:
        if start != "processing":
            return
        study = study_of(key)
        if study not in self.tasks or key not in self.tasks[study]:
            return
        self.running[study].discard(key)
        if finish != "memory":  # this attempt was lost with its worker: its points run again
            del self.tasks[study][key]

    def remove_client(self, scheduler: Any, client: str) -> None:
        for study in self.studies.values():
            if study["client"] == client and study["state"] == "running":
                study.update(state="client gone", ended=time.time())

    def summary(self) -> list[dict[str, Any]]:
        """Every study kept, the most recent first: points done (of total), not ok (this run), tasks running,
        ``rate`` (points per second lately, None until known) and ``left_s`` (seconds left at that rate, None
        when unknown or ended)."""
        out, now = [], time.time()
        for sid, study in reversed(self.studies.items()):
            counts = self.tasks.get(sid, {}).values()
            done = study["before"] + sum(d for d, _ in counts)
            failed = sum(f for _, f in counts)  # of this run (a resume's stored rows are not read)
            running = study["state"] == "running"
            rate = self._rate(sid, now if running else study["ended"] or now)
            left = max(study["total"] - done, 0) / rate if running and rate else None
            out.append({"study": sid, "name": study["name"], "kind": study["kind"], "total": study["total"],
                        "done": done, "failed": failed, "running_tasks": len(self.running.get(sid, ())),
                        "state": study["state"], "started": study["started"], "ended": study["ended"],
                        "room": study.get("room"), "rate": rate, "left_s": left})
        return out


def _link_from_the_navigation_bar(scheduler: Any) -> None:
    """Add "cosim" to the pages of the dashboard's navigation bar (distributed's memoized template variables).

    Only a link: when distributed changes these internals the page is still
    there, at its address.  Only once the dashboard is loaded: the local
    cluster cosim starts builds it when first opened
    (:mod:`cosim.parallel.dashboard.on_demand`, which then calls
    :meth:`PointsPlugin.dashboard_loaded`); importing it here would build it
    at every sweep.
    """
    if "distributed.dashboard.scheduler" not in sys.modules:
        return
    try:
        from distributed.dashboard.scheduler import template_variables

        pages = template_variables(scheduler)["pages"]
        if ROUTE not in pages:
            pages.append(ROUTE)
    except Exception:
        pass


class JsonHandler(web.RequestHandler):
    """``/cosim/points.json``: ``{"studies": PointsPlugin.summary()}``."""

    def initialize(self, plugin: PointsPlugin) -> None:
        self.plugin = plugin

    def get(self) -> None:
        self.set_header("Content-Type", "application/json")
        self.write(json.dumps({"studies": self.plugin.summary()}))


class PageHandler(JsonHandler):
    """``/cosim``: one line per study with a bar, drawn here once and redrawn every second by ``page.js``."""

    def get(self) -> None:
        rows = "".join(_row_html(s) for s in self.plugin.summary())
        body = rows or "<tr><td colspan='8'>no cosim study has run on this scheduler yet</td></tr>"
        self.set_header("Content-Type", "text/html; charset=utf-8")
        self.write(PAGE.format(rows=body))


class ScriptHandler(web.RequestHandler):
    """``/cosim/page.js``: the page's script (a file of its own: the page has no inline script)."""

    def get(self) -> None:
        self.set_header("Content-Type", "text/javascript; charset=utf-8")
        self.set_header("Cache-Control", "no-cache")
        self.write(SCRIPT)


def duration_text(seconds: float | None) -> str:
    """``42 s``, ``7 min``, ``2.5 h``; a dash for unknown (page.js's ``duration`` writes the same)."""
    if seconds is None:
        return "\u2013"
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def rate_text(rate: float | None) -> str:
    """``3.25 /s`` (below 10 a second), ``120 /s``; a dash for unknown (as page.js's ``rate``)."""
    if not rate:
        return "\u2013"
    return f"{rate:.2f} /s" if rate < 10 else f"{rate:.0f} /s"


def _row_html(s: dict[str, Any]) -> str:
    room = s.get("room")
    link = (f" <a class='room' href='{html.escape(room)}'>explore</a>"
            if isinstance(room, str) and room.startswith(("http://", "https://")) else "")
    left = duration_text(s["left_s"]) if s["state"] == "running" else "\u2013"
    return (f"<tr><td class='name'>{html.escape(s['kind'])} {html.escape(s['name'])}{link}</td>"
            f"<td><progress max='{s['total']}' value='{s['done']}'></progress></td>"
            f"<td class='points'>{s['done']} / {s['total']}</td><td class='failed'>{s['failed']}</td>"
            f"<td class='rate'>{rate_text(s['rate'])}</td><td class='left'>{left}</td>"
            f"<td class='tasks'>{s['running_tasks']}</td><td class='state'>{html.escape(s['state'])}</td></tr>")


PAGE = """<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>cosim: points</title>
<noscript><meta http-equiv="refresh" content="2"></noscript>
<style>body {{font-family: sans-serif; margin: 1.5em}} td, th {{padding: 0.2em 0.8em; text-align: left}}
progress {{width: 20em}} #updated {{color: #666}}</style>
<script src="cosim/page.js" defer></script></head>
<body><p><a href="status">&larr; Dask dashboard</a></p>
<h2>cosim: points of each study on this scheduler</h2>
<table><thead><tr><th>study</th><th></th><th>points done</th><th>not ok (this run)</th><th>rate</th>
<th>time left</th><th>tasks running</th><th>state</th></tr></thead>
<tbody id="studies">{rows}</tbody></table>
<p id="updated"></p>
<p>Points done counts every point with a row (ok or not); a task lost with its worker is counted again when it
runs again. The rate is that of the last 30 s, and the time left is what is left at that rate. <i>explore</i>
opens a study's decision room (a study run with explore): its points as they arrive.
Data: <a href="cosim/points.json">cosim/points.json</a>.</p></body></html>
"""

SCRIPT = r"""// cosim's points page: the table is redrawn from points.json every second, without reloading the page.
// Every value is written as text (textContent), never as markup: a study's name comes from a user's file.
"use strict";
function duration(s) {
  if (s === null || s === undefined) return "–";
  if (s < 120) return Math.round(s) + " s";
  if (s < 7200) return Math.round(s / 60) + " min";
  return (s / 3600).toFixed(1) + " h";
}
function rate(r) {
  if (!r) return "–";
  return r < 10 ? r.toFixed(2) + " /s" : Math.round(r) + " /s";
}
function cell(row, text, name) {
  const td = document.createElement("td");
  td.textContent = text;
  if (name) td.className = name;
  row.appendChild(td);
  return td;
}
function studyRow(s) {
  const tr = document.createElement("tr");
  const name = cell(tr, s.kind + " " + s.name, "name");
  if (typeof s.room === "string" && /^https?:\/\//.test(s.room)) {
    const a = document.createElement("a");
    a.href = s.room; a.className = "room"; a.textContent = "explore";
    name.append(" ", a);
  }
  const bar = document.createElement("progress");
  bar.max = s.total; bar.value = s.done;
  cell(tr, "", "").appendChild(bar);
  cell(tr, s.done + " / " + s.total, "points");
  cell(tr, String(s.failed), "failed");
  cell(tr, rate(s.rate), "rate");
  cell(tr, s.state === "running" ? duration(s.left_s) : "–", "left");
  cell(tr, String(s.running_tasks), "tasks");
  cell(tr, s.state, "state");
  return tr;
}
async function refresh() {
  const note = document.getElementById("updated");
  try {
    const answer = await fetch("cosim/points.json", {cache: "no-store"});
    if (!answer.ok) throw new Error("HTTP " + answer.status);
    const studies = (await answer.json()).studies;
    const rows = studies.map(studyRow);
    if (!rows.length) {
      const tr = document.createElement("tr");
      cell(tr, "no cosim study has run on this scheduler yet", "").colSpan = 8;
      rows.push(tr);
    }
    document.getElementById("studies").replaceChildren(...rows);
    note.textContent = "updated " + new Date().toLocaleTimeString();
  } catch (error) {
    note.textContent = "the scheduler does not answer (" + error.message + "); trying again";
  }
}
refresh();
setInterval(refresh, 1000);
"""


# -- client side ------------------------------------------------------------------------


class Board:
    """A study announced to the scheduler's :class:`PointsPlugin`; ``link`` is its page, or ``why_not`` says."""

    def __init__(self, client: Any, study: str, link: str | None, why_not: str = ""):
        self.client, self.study, self.link, self.why_not = client, study, link, why_not

    @property
    def run(self) -> str:
        """What the study's task keys carry (``dashboard.task_key(run=...)``); '' without a page: workers then send
        nothing."""
        return self.study if self.link else ""

    def describe(self) -> str:
        """For the study's start line: the page's address, or why there is none."""
        return f"points: {self.link}" if self.link else f"no points page ({self.why_not})"

    @contextmanager
    def running(self) -> Iterator[None]:
        """The study runs within the block; it ends ``finished``, ``interrupted`` (Ctrl-C) or ``failed``."""
        try:
            yield
        except KeyboardInterrupt:
            # the signal may have ended the scheduler too (a cluster file's `dask spec` closes on Ctrl-C): then
            # there is no page to tell, and otherwise the stop does not wait the usual 5 s for it
            if not scheduler_gone(self.client):
                self.end("interrupted", wait=1)
            raise
        except BaseException:
            self.end("failed")
            raise
        self.end("finished")

    def rows_made_here(self, key: str, rows: list[PointRow]) -> None:
        """Rows the client made for the points of task ``key`` (lost with its workers): counted on the page."""
        self._send({"key": key, "done": len(rows), "failed": sum(not r.ok for r in rows),
                    "final": True})

    def end(self, state: str, wait: float = 5) -> None:
        """Tell the page the study ended (``finished``, ``interrupted``, ``failed``), waiting at most ``wait``
        seconds for the scheduler; never raises."""
        self._send({"op": "end", "study": self.study, "state": state}, wait)

    def _send(self, msg: dict[str, Any], wait: float = 5) -> None:
        if self.link is None:
            return
        try:
            self.client.sync(self.client.scheduler.log_event, topic=TOPIC, msg=msg, callback_timeout=wait)
        except BaseException:  # also while Ctrl-C stops the study: the page's counts are not worth a traceback
            pass


def open_board(client: Any, kind: str, name: str, total: int, before: int = 0,
               dashboard: str | None = None, room: str | None = None) -> Board:
    """Register the plugin on ``client``'s scheduler and announce a study; never raises.

    ``before``: the points already stored (a resume), counted as done.
    ``dashboard`` is the dashboard's link (its ``status`` page); the returned
    Board's ``link`` is the points page beside it, None when the plugin could
    not be registered or there is no dashboard.  ``room``: the link of the study's decision room
    (``--explore``), shown on the page.
    """
    import uuid
    from urllib.parse import urljoin

    import cloudpickle

    study = uuid.uuid4().hex[:12]
    if not dashboard or not dashboard.startswith("http"):
        return Board(client, study, None, "no Dask dashboard")
    try:
        cloudpickle.register_pickle_by_value(sys.modules[__name__])  # whatever cosim version the scheduler has
        client.register_plugin(PointsPlugin(), name=PLUGIN_NAME)
        client.log_event(TOPIC, {"op": "start", "study": study, "kind": kind, "name": name, "total": total,
                                 "before": before, "client": client.id, "room": room})
    except Exception as exc:
        reason = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
        return Board(client, study, None, f"the scheduler did not take cosim's plugin: {reason[:200]}")
    return Board(client, study, urljoin(dashboard, ROUTE))
