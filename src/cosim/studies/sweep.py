"""The Dask layer: every point of a design space, evaluated in parallel, nothing lost.

:class:`Sweep` prepares a sweep (checks the spec, expands the design space,
packs the system and its unit files into a payload) and :meth:`Sweep.run`
evaluates the points on Dask:

- Cluster: by default a ``distributed.LocalCluster`` whose workers (one per
  core, one thread each, bound to 127.0.0.1) run in cosim's process and run
  their points in child processes (FMUs cannot safely share a process; see
  :func:`cosim.parallel.cluster.local.local_cluster`), any running scheduler by address (also from
  ``DASK_SCHEDULER_ADDRESS``), or any Dask cluster class named in a cluster
  file (Slurm, PBS, Kubernetes ...; :mod:`cosim.parallel.cluster`).
- The payload is scattered to the workers once; FMU, ``file.py`` unit and
  played-table bytes travel inside it, and the source of a Python unit named
  ``module:Class`` from the spec's folder (zipped), so workers need no shared
  filesystem (installed modules must be installed where the workers run too).
- Points go in batches, through the one evaluate loop of every study
  (:class:`~cosim.parallel.point_stream.PointStream`).  On a worker,
  :class:`~cosim.parallel.isolation.runner.IsolatedRunner` runs a batch in a child
  process that keeps the loaded system and live unit instances between
  batches, with a per-point watchdog: a point that hangs (``timeout``) or
  kills its process (``crashed``) gets a row and the other points go on.  A
  batch lost with its whole worker process (killed, out of memory, a lost
  node) is run again on another worker by the scheduler; lost a second time
  (KilledWorker) its points without a row run again in small groups, each
  alone on the cluster, then those of a group lost again one at a time, so
  only a point that kills its workers while alone gets ``crashed``
  (:class:`~cosim.parallel.reruns.Reruns`).  Rows out = points in.
- The client streams: a bounded number of batches in flight, and each
  point's row comes back and is appended to the
  :class:`~cosim.results.store.ResultsStore` as soon as that point finishes
  (a task sends its rows while it runs), so the client's memory does not
  grow with the number of points, a stop (Ctrl-C, SIGTERM, SIGHUP) keeps
  every point finished before it, and a kill -9 loses at most the points of
  the last fraction of a second.  ``resume=True`` skips points already stored.
"""

from __future__ import annotations

import math
import os
import shutil
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence, TextIO

from cosim.errors import SweepError
from cosim.execution.point_row import PointRow
from cosim.parallel.cluster.early import EarlyCluster
from cosim.parallel.isolation.children import preload_spare_children, stop_spare_children
from cosim.parallel.isolation.payload import make_payload
from cosim.parallel.isolation.runner import IsolatedRunner
from cosim.parallel.point_stream import BatchSizer, PointStream
from cosim.spec.design import DesignSpace, Point
from cosim.studies.driver import (
    StudyFolder,
    check_timeout,
    interrupted_note,
    now_utc,
    open_room,
    results_writes,
    run_metadata,
    say,
    study_cluster,
)
from cosim.studies.progress import StatusLine, duration
from cosim.studies.pruning import PRUNED, FreshFronts, FrontKeeper, prune_settings, pruned_columns, pruning_order

if TYPE_CHECKING:
    import pandas as pd


# -- client side -------------------------------------------------------------------


class Progress:
    """The sweep's status line: points done, not ok, rate, time left
    (see :class:`cosim.studies.progress.StatusLine`)."""

    def __init__(self, total: int, stream: TextIO | None = None):
        self.total, self.done, self.failed = total, 0, 0
        self._line = StatusLine(total, stream)

    def update(self, done: int, failed: int) -> None:
        self.done += done
        self.failed += failed
        self._line.show(self.done, self.line())

    def line(self) -> str:
        elapsed = self._line.elapsed()
        rate = self.done / elapsed if elapsed > 0 else 0.0
        left = (self.total - self.done) / rate if rate > 0 else math.inf
        width = 24
        filled = int(width * self.done / max(self.total, 1))
        bar = "#" * filled + "." * (width - filled)
        return (f"[{bar}] {self.done}/{self.total} points, {self.failed} not ok, {rate:.1f}/s, "
                f"{duration(left)} left")

    def close(self) -> None:
        self._line.close()


# said when a spec without design parameters is swept (issue 39: it ran one point without saying so)
NO_DESIGN_SPACE = ("the spec has no design space (no 'design.parameters'): the sweep runs one point, the spec's "
                   "values as written; add 'design.parameters' to sweep more (docs/spec.md), or use 'cosim run'")


class Sweep:
    """A prepared sweep of the spec at ``spec_path`` (see the module docstring).

    The constructor reads everything a sweep needs from disk (spec, units, FMU
    bytes) and checks the results folder.  Raises SpecError for a bad spec or
    design space, SweepError when ``out`` cannot be used as asked.
    ``space_of`` builds the points from the checked Spec (default: its design
    space); a driver such as ``cosim sensitivity`` passes its own sample (an
    object with DesignSpace's ``__iter__``, ``__len__``, ``head``, ``columns``,
    ``targets`` and ``method``).

    ``kind`` is the study's kind in ``metadata.json`` and in every file of
    rows (a ``sensitivity`` study runs its sample as a sweep of that kind):
    a resume refuses a folder of another kind.

    ``start_early`` (``cosim sweep``'s way): once the spec is checked, the
    local cluster (when one is used) starts in the background while the rest
    is prepared (:mod:`cosim.parallel.cluster.early`); :meth:`run`,
    :meth:`run_to_disk` or :meth:`close` then ends it.
    """

    def __init__(self, spec_path: str | Path, workers: int | None = None, out: str | Path | None = None,
                 scheduler: str | None = None, timeout: float | None = None, resume: bool = False,
                 batch_size: int | None = None, csv: bool = False, progress: TextIO | None = None,
                 quiet: bool = False, experiment: dict | None = None, space_of: Any = None,
                 cluster: str | Path | None = None, recompute: bool = False, start_early: bool = False,
                 explore: bool = False, kind: str = "sweep", prune: bool = False,
                 prune_objectives: Sequence[tuple[str, str]] | None = None, prune_constraints: Sequence[str] = (),
                 fixed: dict[str, Any] | None = None):
        from cosim.parallel.cluster.choice import choose_cluster
        from cosim.system.validate import check_spec

        check_timeout(timeout, SweepError)
        if workers is not None and workers < 1:
            raise SweepError(f"workers must be at least 1, got {workers}")
        self.workers = workers or os.cpu_count() or 1
        # which cluster, checked before any work (a bad cluster file: ClusterFileError; a malformed address)
        self.cluster = choose_cluster(self.workers, scheduler, cluster)
        # experiment: command-line overrides; fixed: parameters set for every point (cosim sweep --set)
        self.system = check_spec(spec_path, experiment, fixed=fixed)
        self.spec = self.system.spec
        _refuse_design_of_players(self.spec)
        self.space = (space_of or DesignSpace.from_spec)(self.spec)
        # exact pruning (cosim.studies.pruning): what to prune on, checked before any work
        section = self.spec.raw.get("optimize") or {} if isinstance(self.spec.raw, dict) else {}
        objectives = prune_objectives or list((section.get("objectives") or {}).items()) or None
        self.prune = prune_settings(self.system, objectives, prune_constraints or section.get("constraints", ())
                                    ) if prune else None
        self.timeout, self.resume = timeout, resume
        self.batch_size, self.csv, self.quiet = batch_size, csv, quiet
        self.progress_stream, self.kind = progress, kind
        if kind == "sweep" and not self.space.targets:
            self._say(NO_DESIGN_SPACE)
        self._temporary = out is None
        self.explore = explore
        if explore and out is None:
            raise SweepError("explore serves the results folder while the sweep writes it: give one (--out DIR)")
        if resume and out is None:
            raise SweepError("resume needs the results folder of the interrupted sweep (--out DIR)")
        if start_early and self.cluster.local:
            # the spare point children `cosim sweep` started load the system now, while this process starts
            # the cluster (importing Dask) and prepares the results folder (importing pandas)
            self.payload = make_payload(self.system)  # FMU bytes read now: workers never open these paths
            preload_spare_children(self.payload)
            self._early = EarlyCluster(self.workers)
        else:
            stop_spare_children()  # none of them will be used
            self._early = None
        try:
            self.out = Path(out) if out is not None else Path(tempfile.mkdtemp(prefix="cosim_sweep_"))
            self.folder = StudyFolder(self.out, self.system, self.kind, resume, SweepError, f"finish that {kind}",
                                      f"cosim {kind}", self._note, can_recompute=True, recompute=recompute)
            self.store = self.folder.store
            if self._early is None:
                self.payload = make_payload(self.system)
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Stop the cluster started early if no run took it (a no-op otherwise)."""
        early, self._early = self._early, None
        if early is not None:
            early.close()

    def _say(self, text: str) -> None:
        say(text, self.quiet, self.progress_stream)

    def _metadata(self, client_info: dict[str, Any]) -> dict[str, Any]:
        fields: dict[str, Any] = {}
        if self.prune is not None:
            fields["pruning"] = {
                "objectives": [list(o) for o in self.prune.objectives],
                "constraints": [f"{n} {op} {c:g}" for n, op, c in self.prune.constraints],
                "order": getattr(self, "_order_note", None),
                "pruned_rows": "status 'pruned': the objective columns hold BOUNDS (the best value the design could "
                               "still reach when it stopped; NaN where unbounded), not results; pruned_by names "
                               "the finished design that strictly dominated the bound (empty for a broken "
                               "constraint), pruned_at the time it stopped"}
        return run_metadata(self.store, self.system, client_info, kind=self.kind,
                            unit_checksums=self.folder.checksums, data_file_checksums=self.folder.data_checksums,
                            points=len(self.space), design_method=self.space.method, **fields)

    def run(self) -> pd.DataFrame:
        """Evaluate every missing point; returns the whole table (every point once, in design order).

        Raises SweepError when no Dask workers are reachable, FolderInUse when
        another sweep writes into the same folder.  Ctrl-C stops the sweep;
        the rows written so far stay and ``resume`` finishes the rest.
        """
        self._run()
        table = self.store.table()
        self._remove_temporary()
        return table

    def run_to_disk(self) -> dict[str, int]:
        """Like :meth:`run`, but returns only the counts by status: the table stays on disk, never in memory.

        The command line's way, for sweeps of any size.
        """
        counts = self._run()
        self._remove_temporary()
        return counts

    def _remove_temporary(self) -> None:
        if self._temporary:
            shutil.rmtree(self.out, ignore_errors=True)

    def _run(self) -> dict[str, int]:
        try:
            with self.folder.locked():
                return self._run_locked()
        finally:
            self.close()  # the early cluster, if no cluster took it

    def _run_locked(self) -> dict[str, int]:
        from cosim.parallel.dashboard.points import open_board

        started = now_utc()
        done = self.store.done_ids() if self.resume else set()
        if done and self.prune is None:  # a pruned design is done for a pruned study only: run it now
            done -= self.store.ids_with_status(PRUNED)
        total = len(self.space)
        todo = total - len(done & {p.id for p in self.space}) if done else total
        if todo == 0:
            self.close()
            self._say(f"cosim {self.kind} {self.spec.name}: all {total} points already in {self.out}")
            if self.store.metadata() is None:  # lost or damaged, and the rows showed the same model: written anew
                self.folder.write_metadata(self._metadata({"started": started, "scheduler": "", "workers": 0,
                                                           "timeout": self.timeout}))
            return self._finish()
        with study_cluster(self.cluster, SweepError, self._interrupted,
                           early=self._early) as (client, n_workers, link):
            info = {"started": started, "scheduler": client.scheduler.address, "workers": n_workers,
                    "timeout": self.timeout}
            self._client_info = info
            self.folder.write_metadata(self._metadata(info))
            room = open_room(self.out) if self.explore else None
            board = open_board(client, self.kind, self.spec.name, total, before=total - todo, dashboard=link,
                               room=room.link if room else None)
            self._say(f"cosim {self.kind} {self.spec.name}: {total} points ({todo} to run) on {n_workers} "
                      f"worker(s); dashboard: {link} ({board.describe()}); results: {self.out}"
                      + (f"; decision room: {room.link}" if room else ""))
            try:
                with board.running():
                    self._evaluate(client, done, todo, n_workers, board)
            finally:
                if room is not None:
                    room.stop()
        return self._finish()

    def _interrupted(self) -> None:
        self._say(interrupted_note(self.store, self.out, "finish"))

    def _note(self, text: str) -> None:
        """A note that matters even with ``quiet`` (a file of rows set aside): always on stderr."""
        print(f"cosim: {text}", file=self.progress_stream or sys.stderr, flush=True)

    def _finish(self) -> dict[str, int]:
        # order: parts of an older cosim carry no design index
        return self.folder.finish(f"the table holds {{rows}} of {len(self.space)} points: run the same command "
                                  "with --resume (or resume=True from Python) to compute the others",
                                  order=(p.id for p in self.space), csv=self.csv)

    def _evaluate(self, client: Any, done: set[str], todo: int, n_workers: int, board: Any = None) -> None:
        """Run the points not in ``done`` through the one evaluate loop; each row is stored as its point finishes."""
        progress = Progress(todo, self.progress_stream) if not self.quiet else None
        points: Any = (p for p in self.space if p.id not in done)
        keeper = None
        if self.prune is not None:
            keeper = FrontKeeper(self.prune)
            if done:  # a resumed pruned study: the designs finished before prune from the start
                for _, row in self.store.read().iterrows():
                    if row.get("status") == "ok":
                        keeper.add(str(row["point_id"]), row.to_dict())
            points, self._order_note = pruning_order(list(points))
            self.folder.write_metadata(self._metadata(self._client_info))

        def store(pairs: list[tuple[Point, PointRow]]) -> None:
            if keeper is not None:
                for p, r in pairs:
                    if r.ok:
                        keeper.add(p.id, r.objectives)
            with results_writes(self.out):
                self.store.append([self._row(p, r) for p, r in pairs])
            if progress is not None:
                progress.update(len(pairs), sum(not r.ok for _, r in pairs))

        with PointStream(client, self.payload, n_workers, self.kind, self.spec.name, timeout=self.timeout,
                         adaptive_timeout=True, board=board, prune=keeper.order if keeper else None) as stream:
            sizer = (FreshFronts if keeper is not None else BatchSizer)(todo, n_workers, self.batch_size)
            stream.run(points, sizer, store, total=len(self.space))
        if progress is not None:
            progress.close()

    def _row(self, point: Point, row: PointRow) -> dict[str, Any]:
        # the design index is only in part files (cosim.results.store)
        columns = {self.store.INDEX_COLUMN: point.index, **self.space.columns(point.values)}
        if self.prune is not None:
            columns.update(pruned_columns(row))
        return row.to_dict(columns)

    def sample_runs(self, n: int = 8) -> list[PointRow]:
        """Rows of about ``n`` points stratified over the space (:meth:`DesignSpace.stratified`), run locally in
        a child process (a crash cannot hit the caller), after one warm-up run of the first of them whose row
        is dropped: it also loads and instantiates the units, which a sweep does once per worker."""
        runner = IsolatedRunner(self.payload)
        try:
            points = [(p.id, p.values) for p in self.space.stratified(n)]
            runner.run(points[:1], self.timeout)
            return runner.run(points, self.timeout)
        finally:
            runner.close()


def _refuse_design_of_players(spec: Any) -> None:
    """A design parameter of a unit replaced by a player varies nothing: SweepError naming it and the fix."""
    from cosim.system.signals import split_unit_name
    from cosim.units.registry import replaying_units

    players = {u.name: u.source for u in spec.units if u.name in replaying_units(spec.units)}
    for p in spec.design.parameters:
        unit = split_unit_name(p.target, [u.name for u in spec.units])[0]
        if unit in players:
            raise SweepError(f"{spec.path}: $.design.parameters.{p.target}: unit '{unit}' is a player of "
                             f"{players[unit]} (a recording made with one value of each parameter), so "
                             f"'{p.target}' would vary nothing; remove it from design.parameters, or sweep the "
                             "recorded unit itself")


def sweep(spec_path: str | Path, workers: int | None = None, out: str | Path | None = None,
          scheduler: str | None = None,
          timeout: float | None = None, resume: bool = False, **options: Any) -> pd.DataFrame:
    """Evaluate every point of the spec's design space on Dask; returns the results table.

    One row per point: point_id, parameters, objectives, status (ok, failed,
    timeout, crashed), message, run_time, worker.  ``out`` keeps the results
    folder (results.parquet, metadata.json); without it the table is only
    returned.  ``scheduler`` is the address of a running Dask scheduler
    (default: a local cluster of ``workers`` processes, one per core like
    ``cosim sweep``).  ``timeout``: seconds
    a point may run.  ``resume`` runs only the points missing in ``out``.
    Further options: ``batch_size``, ``csv``, ``progress`` (a stream), ``quiet``, ``explore`` (serve the
    decision room of ``out`` while the sweep runs, linked from the dashboard's Cosim page).

    Raises SpecError for a bad spec or design space, SweepError when ``out``
    or the scheduler cannot be used.
    """
    return Sweep(spec_path, workers=workers, out=out, scheduler=scheduler, timeout=timeout, resume=resume,
                 **options).run()
