"""One runner of studies over pluggable point sources: the run sequence every study shares, written once.

A study is a :class:`PointSource` (which points, and when: a design grid, a sampler's sample, an optimiser, a
sensitivity design) run by a :class:`Study` (how: the results folder, the cluster, the evaluate loop, the
dashboard and the decision room, the metadata, the final table), as Optuna's study runs whatever sampler it is
given.  Its options are the four records of :mod:`cosim.studies.options`.

Prepared (:class:`Study`'s constructor), in this order: the options are checked (a bad timeout, no worker), the
cluster is chosen (:func:`cosim.parallel.cluster.choice.choose_cluster`: a bad cluster file or address is said
before any work), the spec is checked into a System, the source plans its points from it
(:meth:`PointSource.plan`), the results folder is opened and checked (:class:`cosim.studies.driver.StudyFolder`),
the source reads what the folder holds (:meth:`PointSource.bind`: an optimiser's stored settings), and the
payload is made (meanwhile a local cluster starts in the background, with ``How.start_early``).

Run (:meth:`Study.run_to_disk`): with the folder's lock held, the source says how many points are left
(:meth:`PointSource.start`); with none, the table is merged without a cluster.  Otherwise, on the cluster, the
metadata is written, the dashboard's points page opened (and the decision room, with ``Show.explore``), the
opening line said, and the source evaluates its points (:meth:`PointSource.evaluate`) through the one evaluate
loop (:mod:`cosim.parallel.point_stream`), storing each row as its point finishes; then the table is merged
in the source's order (:meth:`PointSource.order`).  A stop (Ctrl-C, SIGTERM, SIGHUP) says where the rows are.

Errors: the source's own subclass of :class:`cosim.errors.StudyError` (exit code 2 on the command line).
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from cosim.studies.driver import StudyFolder, interrupted_note, now_utc, open_room, run_metadata, say, study_cluster
from cosim.studies.options import Options

if TYPE_CHECKING:
    import pandas as pd

    from cosim.errors import StudyError


@dataclass
class Run:
    """What a source's :meth:`PointSource.evaluate` gets: the study, the Dask client, the worker count, the
    dashboard's points page (``board``)."""

    study: "Study"
    client: Any
    n_workers: int
    board: Any


class PointSource(Protocol):
    """Which points a study runs, and when: the part of a study that is not the runner's.

    ``kind`` is the study's kind in ``metadata.json`` and every file of rows (a resume refuses a folder of
    another kind); ``command`` names it on the dashboard and in messages (``cosim sweep``); ``error`` is its
    :class:`~cosim.errors.StudyError` subclass; ``to_resume`` ends "add resume to ..."; ``go_on`` ends the
    interrupted note; ``can_recompute``: a resume may discard rows of changed unit files (with ``recompute``).
    """

    kind: str
    command: str
    to_resume: str
    go_on: str
    can_recompute: bool

    @property
    def error(self) -> type[StudyError]:
        """The source's StudyError subclass (read-only here, so a source may name a subclass of it)."""

    def system(self, spec_path: str | Path) -> Any:
        """The checked System of the spec (raises SpecError)."""

    def plan(self, study: "Study") -> None:
        """Plan the points from ``study.system`` (before the folder is opened; raises SpecError or ``error``)."""

    def bind(self, study: "Study") -> None:
        """Read what ``study.folder`` holds (its previous metadata) before any work."""

    def start(self, study: "Study") -> tuple[int, int]:
        """Get ready to run (read the stored rows, open what the source needs): (points the dashboard counts in
        all, points already done); called with the folder's lock held, before the cluster starts."""

    def metadata(self, study: "Study", run: dict[str, Any]) -> dict[str, Any]:
        """``metadata.json`` of this run (:func:`cosim.studies.driver.run_metadata` with the source's fields)."""

    def opening(self, study: "Study", n_workers: int, link: str, board: Any) -> str:
        """The line said when the points start: what runs, where, the dashboard."""

    def evaluate(self, run: Run) -> None:
        """Evaluate the points, storing each row as its point finishes (through ``run.study.store``)."""

    def nothing_to_do(self, study: "Study") -> str | None:
        """What to say when :meth:`start` leaves no point to run (None: run anyway, e.g. an optimiser)."""

    def order(self, study: "Study") -> Any:
        """The point ids in table order for the final merge (None: as stored)."""

    def missing(self, study: "Study") -> str:
        """The end of the message when a part of rows was damaged: how to get the missing points."""


class Study:
    """A prepared study of the spec at ``spec_path``: ``source`` run with ``options`` (module docstring).

    Raises SpecError for a bad spec, ClusterFileError or SchedulerAddressError for a bad cluster, the
    source's ``error`` when the options or the folder cannot be used as asked (FolderInUse when another cosim
    process writes into it).
    """

    def __init__(self, spec_path: str | Path, source: PointSource, options: Options):
        from cosim.parallel.cluster.choice import choose_cluster
        from cosim.parallel.isolation.children import stop_spare_children

        self.source, self.error = source, source.error
        self.where, self.stop, self.show = options.where, options.stop, options.show
        self.how = options.how.checked(self.error)
        # which cluster, checked before any work (a bad cluster file: ClusterFileError; a malformed address)
        self.cluster = choose_cluster(self.how.workers or 1, self.how.scheduler, self.how.cluster)
        self.system = source.system(spec_path)
        self.spec = self.system.spec
        source.plan(self)
        out = self.where.out
        if out is None and self.show.explore:
            raise self.error(f"explore serves the results folder while the {source.command} writes it: give one "
                             f"({self.show.word('out_dir')})")
        if out is None and self.where.resume:
            raise self.error(f"resume needs the results folder of the interrupted {source.command} "
                             f"({self.show.word('out_dir')})")
        self._early: Any = None
        early_payload: dict[str, Any] | None = None  # made at once when the spare children load it meanwhile
        if self.how.start_early and self.cluster.local:
            early_payload = self._start_early()
        else:
            stop_spare_children()  # none of them will be used
        self._temporary = out is None
        try:
            self.out = Path(out) if out is not None else Path(tempfile.mkdtemp(prefix=f"cosim_{source.kind}_"))
            self.folder = StudyFolder(self.out, self.system, source.kind, self.where.resume, self.error,
                                      source.to_resume, f"cosim {source.command}", self.note,
                                      can_recompute=source.can_recompute, recompute=self.where.recompute,
                                      words=self.show.words)
            self.store = self.folder.store
            source.bind(self)
            self.payload = early_payload if early_payload is not None else self._make_payload()
        except BaseException:
            self.close()
            raise

    def _make_payload(self) -> dict[str, Any]:
        from cosim.parallel.isolation.payload import make_payload

        # FMU bytes read now: workers never open these paths; a warm-up within the study's timeout (issue 38)
        return make_payload(self.system, self.how.timeout)

    def _start_early(self) -> dict[str, Any]:
        """The spare point children the command started load the system now, while this process starts the local
        cluster (importing Dask) in the background and prepares the results folder (importing pandas); returns
        the payload they load."""
        from cosim.parallel.cluster.early import EarlyCluster
        from cosim.parallel.isolation.children import preload_spare_children

        payload = self._make_payload()
        preload_spare_children(payload)
        self._early = EarlyCluster(self.how.workers or 1)
        return payload

    # the options most read from outside, under the names they had as flat arguments
    @property
    def workers(self) -> int:
        """The worker count of a local cluster (one per core unless given)."""
        return self.how.workers or 1

    @property
    def timeout(self) -> float | None:
        """Seconds a point may run (None: from the points measured)."""
        return self.how.timeout

    @property
    def resume(self) -> bool:
        """Whether the study finishes the one already in its folder."""
        return self.where.resume

    # -- what it says ---------------------------------------------------------------------------------------------

    def say(self, text: str) -> None:
        """Say ``text`` on the progress stream (stderr by default) unless quiet."""
        say(text, self.show.quiet, self.show.progress)

    def note(self, text: str) -> None:
        """A note that matters even when quiet (a file of rows set aside): always said."""
        print(f"cosim: {text}", file=self.show.progress or sys.stderr, flush=True)

    def _interrupted(self) -> None:
        self.say(interrupted_note(self.store, self.out, self.source.go_on, self.show.words))

    # -- the run ------------------------------------------------------------------------------------------------

    def close(self) -> None:
        """Stop the cluster started early if no run took it (a no-op otherwise)."""
        early, self._early = self._early, None
        if early is not None:
            early.close()

    def run_to_disk(self) -> dict[str, int]:
        """Run the study; returns the counts by status: the table stays on disk, never in memory.

        Raises the source's ``error`` when no Dask workers are reachable, FolderInUse when another study writes
        into the same folder, OutputError when the folder cannot be written.  A stop keeps the rows written so
        far; a resume finishes the rest.
        """
        try:
            with self.folder.locked():
                return self._run_locked()
        finally:
            self.close()  # the early cluster, if no cluster took it

    def table(self) -> pd.DataFrame:
        """The whole table (every point once, in the source's order)."""
        return self.store.table()

    def remove_temporary(self) -> None:
        """Remove the results folder when it is a temporary one (no ``out`` given)."""
        if self._temporary:
            shutil.rmtree(self.out, ignore_errors=True)

    def _run_locked(self) -> dict[str, int]:
        from cosim.parallel.dashboard.points import open_board

        started = now_utc()
        total, done = self.source.start(self)
        said = self.source.nothing_to_do(self) if done >= total else None
        if said is not None:
            self.close()
            self.say(said)
            if self.store.metadata() is None:  # lost or damaged, and the rows showed the same model: written anew
                self.folder.write_metadata(self.source.metadata(self, self._run_info(started, "", 0)))
            return self.finish()
        with study_cluster(self.cluster, self.error, self._interrupted, early=self._early) as \
                (client, n_workers, link):
            self.run_info = self._run_info(started, client.scheduler.address, n_workers)
            self.folder.write_metadata(self.source.metadata(self, self.run_info))
            room = open_room(self.out) if self.show.explore else None
            board = open_board(client, self.source.command, self.spec.name, total, before=done, dashboard=link,
                               room=room.link if room else None)
            self.say(self.source.opening(self, n_workers, link, board)
                     + (f"; decision room: {room.link}" if room else ""))
            try:
                self._evaluate(Run(self, client, n_workers, board))
            finally:
                if room is not None:
                    room.stop()
        return self.finish()

    def _evaluate(self, run: Run) -> None:
        """The source evaluates its points on the cluster (one step of the run: tests wrap it to stop a study at
        a chosen moment)."""
        self.source.evaluate(run)

    def _run_info(self, started: str, scheduler: str, n_workers: int) -> dict[str, Any]:
        return {"started": started, "scheduler": scheduler, "workers": n_workers, "timeout": self.how.timeout}

    def finish(self) -> dict[str, int]:
        """Merge the rows into ``results.parquet`` in the source's order; returns the counts by status."""
        return self.folder.finish(self.source.missing(self), order=self.source.order(self), csv=self.where.csv)

    def write_metadata(self, run: dict[str, Any]) -> None:
        """Write ``metadata.json`` anew for ``run`` (the source's fields changed, e.g. a pruning order)."""
        self.folder.write_metadata(self.source.metadata(self, run))


def metadata_of(study: Study, run: dict[str, Any], **fields: Any) -> dict[str, Any]:
    """``metadata.json`` of ``study`` at the start of ``run``, with the source's ``fields`` (in their order)."""
    return run_metadata(study.store, study.system, run, kind=study.source.kind, **fields)

