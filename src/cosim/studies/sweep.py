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
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence, TextIO

from cosim.errors import SweepError
from cosim.execution.point_row import PointRow
from cosim.parallel.point_stream import BatchSizer, PointStream
from cosim.spec.design import DesignSpace, Point
from cosim.studies.driver import results_writes
from cosim.studies.options import How, Show, Stop, Where, split_options
from cosim.studies.progress import StatusLine, duration
from cosim.studies.pruning import (
    PRUNED,
    FreshFronts,
    FrontKeeper,
    lockstep_group,
    prune_settings,
    pruned_columns,
    pruning_order,
)
from cosim.studies.runner import Run, Study, metadata_of

if TYPE_CHECKING:
    import pandas as pd


# -- client side -------------------------------------------------------------------


class Progress:
    """The sweep's status line: points done, not ok, pruned, rate, time left
    (see :class:`cosim.studies.progress.StatusLine`)."""

    def __init__(self, total: int, stream: TextIO | None = None):
        self.total, self.done, self.failed, self.pruned = total, 0, 0, 0
        self._line = StatusLine(total, stream)
        self._seen: set[str] = set()

    def update(self, done: int, failed: int) -> None:
        self.done += done
        self.failed += failed
        self._line.show(self.done, self.line())

    def rows(self, rows: Sequence[PointRow]) -> None:
        """Count finished points by their rows: each point once, however often its row comes (a stop hands the
        rows it interrupted again, a resume of a pruned study may store a point anew: done never passes the
        total); a pruned point is counted apart, not as 'not ok' (a result, not a failure)."""
        fresh = [r for r in rows if r.point_id not in self._seen]
        self._seen.update(r.point_id for r in fresh)
        self.pruned += sum(r.status == PRUNED for r in fresh)
        self.update(len(fresh), sum(not r.ok and r.status != PRUNED for r in fresh))

    def line(self) -> str:
        elapsed = self._line.elapsed()
        rate = self.done / elapsed if elapsed > 0 else 0.0
        left = (self.total - self.done) / rate if rate > 0 else math.inf
        width = 24
        filled = int(width * self.done / max(self.total, 1))
        bar = "#" * filled + "." * (width - filled)
        pruned = f", {self.pruned} pruned" if self.pruned else ""
        return (f"[{bar}] {self.done}/{self.total} points, {self.failed} not ok{pruned}, {rate:.1f}/s, "
                f"{duration(left)} left")

    def close(self) -> None:
        self._line.close()


# said when a spec without design parameters is swept (issue 39: it ran one point without saying so)
NO_DESIGN_SPACE = ("the spec has no design space (no 'design.parameters'): the sweep runs one point, the spec's "
                   "values as written; add 'design.parameters' to sweep more (docs/spec.md), or use 'cosim run'")


class DesignGrid:
    """The point source of a sweep: every point of a design (the spec's design space, or ``design(spec)``, e.g.
    a sensitivity study's sample), each once, in the design's order; a resume skips the points stored.

    ``design`` builds the points from the checked Spec (default :meth:`DesignSpace.from_spec`): an object with
    DesignSpace's ``__iter__``, ``__len__``, ``head``, ``spread``, ``columns``, ``targets`` and ``method``.
    ``kind`` is the study's kind (``sweep``; ``sensitivity`` runs its sample as a sweep of that kind).
    ``experiment`` overrides the spec's experiment, ``fixed`` sets parameters for every point.
    """

    error = SweepError
    can_recompute = True
    go_on = "finish"

    def __init__(self, design: Any = None, kind: str = "sweep", experiment: dict | None = None,
                 fixed: dict[str, Any] | None = None):
        self.design, self.kind, self.command = design or DesignSpace.from_spec, kind, kind
        self.experiment, self.fixed = experiment, fixed
        self.to_resume = f"finish that {kind}"
        self.space: Any = None
        self.prune: Any = None
        self._done: set[str] = set()
        self._order_note: Any = None
        self._todo = 0

    def system(self, spec_path: str | Path) -> Any:
        from cosim.system.validate import check_spec

        # experiment: overrides of the spec's experiment; fixed: parameters set for every point (--set)
        return check_spec(spec_path, self.experiment, fixed=self.fixed)

    def plan(self, study: Study) -> None:
        spec = study.spec
        _refuse_design_of_players(spec)
        self.space = self.design(spec)
        how = study.how
        if how.prune:  # exact pruning (cosim.studies.pruning): what to prune on, checked before any work
            section = spec.raw.get("optimize") or {} if isinstance(spec.raw, dict) else {}
            objectives = how.prune_objectives or list((section.get("objectives") or {}).items()) or None
            self.prune = prune_settings(study.system, objectives,
                                        how.prune_constraints or section.get("constraints", ()))
        if self.kind == "sweep" and not self.space.targets:
            study.say(NO_DESIGN_SPACE)

    def bind(self, study: Study) -> None:
        pass  # a grid reads nothing of the folder before it runs

    def start(self, study: Study) -> tuple[int, int]:
        done = study.store.done_ids() if study.where.resume else set()
        if done and self.prune is None:  # a pruned design is done for a pruned study only: run it now
            done -= study.store.ids_with_status(PRUNED)
        self._done = done
        total = len(self.space)
        self._todo = total - len(done & {p.id for p in self.space}) if done else total
        return total, total - self._todo

    def nothing_to_do(self, study: Study) -> str | None:
        return f"cosim {self.kind} {study.spec.name}: all {len(self.space)} points already in {study.out}"

    def metadata(self, study: Study, run: dict[str, Any]) -> dict[str, Any]:
        fields: dict[str, Any] = {}
        if self.prune is not None:
            fields["pruning"] = {
                "objectives": [list(o) for o in self.prune.objectives],
                "constraints": [f"{n} {op} {c:g}" for n, op, c in self.prune.constraints],
                "order": self._order_note,
                "pruned_rows": "status 'pruned': the objective columns hold BOUNDS (the best value the design could "
                               "still reach when it stopped; NaN where unbounded), not results; pruned_by names "
                               "the finished design that strictly dominated the bound (empty for a broken "
                               "constraint), pruned_at the time it stopped"}
        return metadata_of(study, run, unit_checksums=study.folder.checksums,
                           data_file_checksums=study.folder.data_checksums, points=len(self.space),
                           design_method=self.space.method, **fields)

    def opening(self, study: Study, n_workers: int, link: str, board: Any) -> str:
        total, todo = len(self.space), self._todo
        return (f"cosim {self.kind} {study.spec.name}: {total} points ({todo} to run) on {n_workers} "
                f"worker(s); dashboard: {link} ({board.describe()}); results: {study.out}")

    def evaluate(self, run: Run) -> None:
        """Run the points not done through the one evaluate loop; each row is stored as its point finishes."""
        study = run.study
        total, todo = len(self.space), self._todo
        progress = Progress(todo, study.show.progress) if not study.show.quiet else None
        points: Any = (p for p in self.space if p.id not in self._done)
        keeper = None
        if self.prune is not None:
            keeper = FrontKeeper(self.prune)
            if self._done:  # a resumed pruned study: the designs finished before prune from the start
                for _, row in study.store.read().iterrows():
                    if row.get("status") == "ok":
                        keeper.add(str(row["point_id"]), row.to_dict())
            points, self._order_note = pruning_order(list(points))
            study.write_metadata(study.run_info)

        def store(pairs: list[tuple[Point, PointRow]]) -> None:
            if keeper is not None:
                for p, r in pairs:
                    if r.ok:
                        keeper.add(p.id, r.objectives)
            with results_writes(study.out, study.show.words):
                study.store.append([self._row(study, p, r) for p, r in pairs])
            if progress is not None:
                progress.rows([r for _, r in pairs])

        with run.board.running():
            with PointStream(run.client, study.payload, run.n_workers, self.kind, study.spec.name,
                             timeout=study.how.timeout, adaptive_timeout=True, board=run.board,
                             prune=keeper.order if keeper else None) as stream:
                if keeper is not None:  # lock-step groups where the system allows: tasks big enough for them
                    sizer: Any = FreshFronts(todo, run.n_workers, study.how.batch_size, lockstep_group(study.system))
                else:
                    sizer = BatchSizer(todo, run.n_workers, study.how.batch_size)
                stream.run(points, sizer, store, total=total)
            if progress is not None:
                progress.close()

    def _row(self, study: Study, point: Point, row: PointRow) -> dict[str, Any]:
        # the design index is only in part files (cosim.results.store)
        columns = {study.store.INDEX_COLUMN: point.index, **self.space.columns(point.values)}
        if self.prune is not None:
            columns.update(pruned_columns(row))
        return row.to_dict(columns)

    def order(self, study: Study) -> Any:
        return (p.id for p in self.space)  # parts of an older cosim carry no design index

    def missing(self, study: Study) -> str:
        return (f"the table holds {{rows}} of {len(self.space)} points: run it again with "
                f"{study.show.word('resume')} to compute the others")


class Sweep(Study):
    """A prepared sweep of the spec at ``spec_path``: a :class:`DesignGrid` run by the study runner
    (:class:`cosim.studies.runner.Study`; see the module docstring).

    Options: the records ``where``, ``how``, ``show`` (:mod:`cosim.studies.options`), or their fields as
    keyword arguments (``out``, ``resume``, ``workers``, ``timeout``, ``quiet`` ...), as ``cosim.sweep``
    takes them; the point source ``grid`` (a :class:`DesignGrid`), or its options as keyword arguments:
    ``design`` builds the points from the checked Spec (default: its design space; a sensitivity study passes
    its sample), ``kind`` is the study's kind in ``metadata.json`` (a resume refuses a folder of another kind),
    ``experiment`` overrides the spec's experiment and ``fixed`` sets parameters for every point.

    The constructor reads everything a sweep needs from disk (spec, units, FMU bytes) and checks the results
    folder.  Raises SpecError for a bad spec or design space, SweepError when the folder or options cannot be
    used as asked.  With ``start_early`` the local cluster (when one is used) starts in the background once
    the spec is checked; :meth:`run`, :meth:`run_to_disk` or :meth:`close` then ends it.
    """

    GRID_OPTIONS = ("design", "space_of", "kind", "experiment", "fixed")  # the flat names of the grid's own

    def __init__(self, spec_path: str | Path, where: Where | None = None, how: How | None = None,
                 show: Show | None = None, grid: DesignGrid | None = None, **options: Any):
        own = {name: options.pop(name) for name in self.GRID_OPTIONS if name in options}
        if grid is not None and own:
            raise TypeError(f"give {', '.join(own)} to the DesignGrid, not beside it")
        if "space_of" in own:  # the design's name before the study runner
            own["design"] = own.pop("space_of")
        self.grid = grid or DesignGrid(**own)
        super().__init__(spec_path, self.grid, split_options(where, how, Stop(), show, **options))

    @property
    def space(self) -> Any:
        """The design's points (a DesignSpace, or the design given)."""
        return self.grid.space

    @property
    def prune(self) -> Any:
        """The pruning settings (None: no pruning)."""
        return self.grid.prune

    def run(self) -> pd.DataFrame:
        """Evaluate every missing point; returns the whole table (every point once, in design order).

        Raises SweepError when no Dask workers are reachable, FolderInUse when another sweep writes into the
        same folder.  Ctrl-C stops the sweep; the rows written so far stay and a resume finishes the rest.
        """
        Study.run_to_disk(self)
        table = self.table()
        self.remove_temporary()
        return table

    def run_to_disk(self) -> dict[str, int]:
        """Like :meth:`run`, but returns only the counts by status: the table stays on disk, never in memory.

        The command line's way, for sweeps of any size.
        """
        counts = super().run_to_disk()
        self.remove_temporary()
        return counts

    def sample_runs(self, n: int = 8) -> list[PointRow]:
        """Rows of about ``n`` points stratified over the space (:meth:`DesignSpace.stratified`), run locally in
        a child process (a crash cannot hit the caller), after one warm-up run of the first of them whose row
        is dropped: it also loads and instantiates the units, which a sweep does once per worker."""
        from cosim.parallel.isolation.runner import IsolatedRunner

        runner = IsolatedRunner(self.payload)
        try:
            points = [(p.id, p.values) for p in self.space.stratified(n)]
            runner.run(points[:1], self.how.timeout)
            return runner.run(points, self.how.timeout)
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


def sweep(spec_path: str | Path, where: Where | None = None, how: How | None = None, show: Show | None = None,
          **options: Any) -> pd.DataFrame:
    """Evaluate every point of the spec's design space on Dask; returns the results table.

    One row per point: point_id, parameters, objectives, status (ok, failed, timeout, crashed), message,
    run_time, worker.  Options as :class:`Sweep`: ``out`` keeps the results folder (results.parquet,
    metadata.json; without it the table is only returned), ``scheduler`` is the address of a running Dask
    scheduler (default: a local cluster of ``workers`` processes, one per core like ``cosim sweep``),
    ``timeout`` the seconds a point may run, ``resume`` runs only the points missing in ``out``; also
    ``batch_size``, ``csv``, ``progress`` (a stream), ``quiet``, ``explore``.

    Raises SpecError for a bad spec or design space, SweepError when ``out`` or the scheduler cannot be used.
    """
    return Sweep(spec_path, where, how, show, **options).run()
