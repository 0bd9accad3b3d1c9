"""What every driver (a sweep, an optimisation, a sensitivity study) does alike with its results folder, its
cluster and its messages: the study skeleton, :class:`StudyFolder` (folder, lock, checks, metadata, final
table) and :func:`study_cluster`, and the pieces it is made of.

A driver writes its rows into a results folder (:class:`~cosim.results.store.ResultsStore`).
Started afresh, the folder must hold no rows; with ``resume`` it must hold rows
of the same spec and of the same kind of study (a sweep's rows do not continue
an optimisation): :func:`check_results_folder`.  Either mistake is the user's,
raised as the driver's own :class:`~cosim.errors.UserError` subclass
naming the folder and the fix.  ``metadata.json`` records the spec, the FMUs'
checksums, package versions, host and user and one entry per run
(:func:`run_metadata`, :func:`finish_metadata`); :func:`say` prints a driver's
messages; :func:`open_room` serves the decision room of the folder while the driver writes it (``Show.explore``).
"""

from __future__ import annotations

import errno
import getpass
import json
import platform
import socket
import sys
import time
from contextlib import contextmanager
from datetime import datetime, timezone
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, TextIO

from cosim.errors import OutputError, UserError
from cosim.parallel.cluster.interrupts import raise_if_stopped
from cosim.studies.options import PYTHON_WORDS

# The distributions whose versions can change a row's numbers (cosim's own is fmi-cosim: "cosim" on the index
# is another project): the FMI runtime, the built-in units' physics and code generation (pin, exudyn, casadi,
# the Panda's URDF in example-robot-data), numerics, the samplers and the sensitivity analysis.
PACKAGES = ("fmi-cosim", "fmpy", "dask", "distributed", "numpy", "pandas", "pyarrow", "scipy", "pin", "exudyn",
            "casadi", "example-robot-data", "optuna", "SALib")


def study_identity(spec_digest: str, kind: str, units: Mapping[str, str],
                   data_files: Mapping[str, Mapping[str, str]]) -> dict[str, Any]:
    """What makes a study's rows comparable: the spec digest, the kind of study and the checksums of its unit
    and data files (:mod:`cosim.results.checksums`).  The store writes it into every file of rows."""
    return {"spec_digest": spec_digest, "kind": kind, "unit_checksums": dict(units),
            "data_file_checksums": {k: dict(v) for k, v in data_files.items()}}


def check_results_folder(store: Any, resume: bool, spec_digest: str, kind: str, to_resume: str,
                         error: type[UserError], note: Callable[[str], None] | None = None,
                         words: Mapping[str, str] = PYTHON_WORDS) -> dict[str, Any] | None:
    """The folder's stored metadata when resuming (None when it has none, or none that can be read);
    raises ``error`` when the folder is unusable.

    ``kind`` is the metadata's ``kind`` the driver writes (a sweep writes
    none: "sweep"); ``to_resume`` completes "add resume to ..." in the
    message for a folder that already holds rows; ``words`` name the options
    (:data:`cosim.studies.options.PYTHON_WORDS` by default).  The spec digest and kind
    are checked against ``metadata.json`` and against the identity every file
    of rows carries, so a lost or damaged ``metadata.json`` does not let rows
    of another spec through.  When resuming, files of rows that cannot be read
    (truncated) are set aside first, each told to ``note``: their points are
    computed again.
    """
    if not resume:
        if store.has_rows():
            raise error(f"{store.folder} already holds results; add {words['resume']} to {to_resume}, or choose "
                        f"another {words['out']}")
        return None
    with results_writes(store.folder, words):
        for line in store.set_aside_damaged():
            if note is not None:
                note(f"{store.folder}: {line}; its points are computed again")
    previous = store.metadata()
    records = [previous] if previous is not None else []
    records += [json.loads(text) for text in store.row_identities() if text]
    for record in records:
        if record.get("spec_digest") != spec_digest:
            raise error(f"{store.folder} holds results of a different spec (digest "
                        f"{str(record.get('spec_digest'))[:12]}…, this one {spec_digest[:12]}…); "
                        f"use another {words['out']}, or run without {words['resume']} into an empty folder")
        if record.get("kind", "sweep") != kind:
            raise error(f"{store.folder} holds {record.get('kind', 'sweep')} results, not {kind} results; use "
                        f"another {words['out']}, or resume it with the study that started it")
    return previous


def resume_differences(store: Any, units: Mapping[str, str], data_files: Mapping[str, Mapping[str, str]],
                       folder: str | Path) -> tuple[list[str], str | None]:
    """What keeps the stored rows from being resumed with the unit and data files as they are now.

    Returns (changed, unverifiable): ``changed`` lines name each unit or data
    file whose checksum differs from ``metadata.json`` or from the identity a
    file of rows carries; ``unverifiable`` says why the rows cannot be checked
    at all (``metadata.json`` missing, empty or damaged and rows without an
    identity of their own), else None.  A resume must fail closed on either.
    """
    from cosim.results.checksums import changed_files

    previous, why = store.metadata_state()
    changed = changed_files(previous, units, data_files, folder) if previous is not None else []
    identities = store.row_identities()
    for text in identities:
        if text:
            changed += [line for line in changed_files(json.loads(text), units, data_files, folder)
                        if line not in changed]
    unmarked = identities.get("", [])
    unverifiable = None
    if previous is None and unmarked:
        names = ", ".join(p.relative_to(store.folder).as_posix() for p in unmarked[:3])
        more = f" and {len(unmarked) - 3} more" if len(unmarked) > 3 else ""
        unverifiable = (f"its metadata.json is {why}, and {len(unmarked)} file(s) of rows ({names}{more}) carry no "
                        "checksums of the unit files that made them, so nothing shows they come from the same model")
    return changed, unverifiable


@contextmanager
def results_writes(out: Path, words: Mapping[str, str] = PYTHON_WORDS) -> Iterator[None]:
    """Turn a failed write into the results folder into an OutputError (exit 2, no traceback).

    Half-written temporary files are removed; the part files already written
    stay, so after freeing space a resume finishes the study exactly.  The
    message says so only when it is true: a folder removed while the study
    ran has lost its rows, and one without rows yet has nothing to resume.
    """
    try:
        yield
    except OSError as exc:
        for leftover in ("results.parquet.tmp", "results.csv.tmp", "metadata.json.tmp"):
            try:
                (out / leftover).unlink(missing_ok=True)
            except OSError:
                pass
        reason = exc.strerror or str(exc) or type(exc).__name__
        if exc.errno == errno.ENOENT and _removed(out):  # removed (rm -rf) while the study wrote into it
            raise OutputError(f"cannot write the results into {out}: the folder was removed while cosim wrote "
                              f"into it ({reason}); the rows it held are gone", file=str(out),
                              fix=f"run it again without {words['resume']}, into a folder nothing else "
                                  "removes") from None
        if _holds_rows(out):
            fix = (f"free space on that filesystem or make the folder writable (or choose another {words['out']}); "
                   f"the rows written so far are kept: run it again with {words['resume']} to finish")
        else:
            fix = ("free space on that filesystem or make the folder writable, or choose another "
                   f"{words['out']}; then run {words['again']} again")
        raise OutputError(f"cannot write the results into {out}: {reason}", file=str(out), fix=fix) from None


def _removed(out: Path, settle: float = 1.0) -> bool:
    """Whether the results folder was removed (or emptied) under the study, after a write in it found no file.

    ``rm -rf`` removes a folder's files before the folder itself, so a write can fail while the folder is still
    there: it is watched for up to ``settle`` seconds. A folder left without both its parts and its metadata
    was emptied by someone: its rows are gone as well."""
    deadline = time.monotonic() + settle
    while True:
        if not out.is_dir() or not ((out / "parts").exists() or (out / "metadata.json").exists()):
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.05)


def _holds_rows(out: Path) -> bool:
    """Whether the folder holds any file of rows (without importing pandas)."""
    try:
        return (out / "results.parquet").is_file() or any(p.name.startswith("part-") and p.suffix == ".parquet"
                                                            for p in (out / "parts").iterdir())
    except OSError:
        return False


def say(text: str, quiet: bool, stream: TextIO | None) -> None:
    """Print a driver's message (start, interruption, notes) on ``stream`` (stderr by default) unless ``quiet``."""
    if not quiet:
        print(text, file=stream or sys.stderr, flush=True)


def run_metadata(store: Any, system: Any, run: Mapping[str, Any], **fields: Any) -> dict[str, Any]:
    """``metadata.json`` at the start of a run: the spec, FMU checksums, host, user and ``fields``.

    ``run`` (when and how this run started) is appended to the runs already
    stored; ``started`` and ``counts`` stay those of the first run until
    :func:`finish_metadata`.  ``fields`` are the driver's own (points, design
    method, kind, ...); a ``packages`` field adds to the common versions.
    """
    from cosim.units.fmu.description import FmuUnitType

    previous = store.metadata() or {}
    spec = system.spec
    return {
        "spec_path": str(Path(spec.path).resolve()), "spec_digest": spec.digest, "spec": spec.raw,
        "fmu_checksums": {name: su.unit_type.digest for name, su in system.units.items()
                          if isinstance(su.unit_type, FmuUnitType)},
        "host": socket.gethostname(), "user": user_name(),
        **fields,
        "packages": {**package_versions(), **fields.get("packages", {})},
        "started": previous.get("started", run["started"]), "runs": previous.get("runs", []) + [dict(run)],
        "ended": None, "counts": previous.get("counts"),
    }


def finish_metadata(store: Any, counts: Mapping[str, int]) -> None:
    """Record the end of the run and the final counts by status in ``metadata.json``."""
    meta = store.metadata() or {}
    meta.update(ended=now_utc(), counts=dict(counts))
    if meta.get("runs"):
        meta["runs"][-1]["ended"] = meta["ended"]
    store.write_metadata(meta)


def package_versions(*extra: str) -> dict[str, str]:
    """Versions of Python and of the packages a run's numbers depend on (those installed), for the metadata."""
    versions = {"python": platform.python_version()}
    for name in (*PACKAGES, *extra):
        try:
            versions[name] = importlib_metadata.version(name)
        except importlib_metadata.PackageNotFoundError:
            pass
    return versions


def now_utc() -> str:
    """The current UTC time as ISO 8601 text (seconds), as the metadata records it."""
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def user_name() -> str:
    """The login name for the metadata, or '' when the system cannot tell."""
    try:
        return getpass.getuser()
    except Exception:
        return ""


# -- the skeleton every study shares ---------------------------------------------------------------------------


class StudyFolder:
    """One study's results folder from the first check to the final table: the part sweep, optimize and
    sensitivity do alike, in this order.

    1. The folder is opened (created when missing) and its lock checked free (FolderInUse otherwise), so a
       study running into it is the first thing said; a folder that cannot be written is an OutputError.
    2. :func:`check_results_folder`: rows of this spec and ``kind`` when resuming (:attr:`previous`, the
       stored metadata), none otherwise.  When resuming, the unit and data files must be those that made the
       rows (:func:`resume_differences`), else ``error`` names the files; a study that ``can_recompute``
       (a sweep) then discards the rows when ``recompute`` is asked instead of refusing.
    3. :meth:`locked` holds the lock while the study runs; :meth:`write_metadata` writes ``metadata.json``.
    4. :meth:`finish` sets aside a part damaged meanwhile, merges the parts into ``results.parquet`` and
       records the counts; ``error`` says which points are missing when a part was set aside.

    ``to_resume`` completes "add resume ... to" in the refusal of a folder that already holds rows;
    ``command`` names the study in the lock ("cosim sweep"); ``note`` gets the notes that matter even when
    quiet (a file of rows set aside); ``words`` how its messages name the options
    (:data:`cosim.studies.options.PYTHON_WORDS` by default).
    """

    def __init__(self, out: Path, system: Any, kind: str, resume: bool, error: type[UserError], to_resume: str,
                 command: str, note: Callable[[str], None], can_recompute: bool = False, recompute: bool = False,
                 words: Mapping[str, str] = PYTHON_WORDS):
        from cosim.results.checksums import data_file_checksums, unit_checksums
        from cosim.results.lock import FolderLock
        from cosim.results.store import ResultsStore  # (pandas and pyarrow are imported when the first rows come)

        self.out, self.kind, self.error, self.command = Path(out), kind, error, command
        self.words = {**PYTHON_WORDS, **words}
        with results_writes(self.out, self.words):  # a read-only or full disk: said with what to do (exit 2)
            self.store = ResultsStore(self.out)
            self.lock = FolderLock(self.out)
            self.lock.check_free()  # a study running into this folder is the first thing to say
        spec = system.spec
        self.checksums, self.data_checksums = unit_checksums(system), data_file_checksums(system)
        self.previous = check_results_folder(self.store, resume, spec.digest, kind, to_resume, error, note=note,
                                             words=self.words)
        if resume:
            self._check_unit_files(spec.folder, can_recompute, recompute)
        self.store.identity = study_identity(spec.digest, kind, self.checksums, self.data_checksums)

    def _check_unit_files(self, folder: Path, can_recompute: bool, recompute: bool) -> None:
        changed, unverifiable = resume_differences(self.store, self.checksums, self.data_checksums, folder)
        words = self.words
        if can_recompute:
            whole, rows, fix = ("table", "results", f"use another {words['out']}, or add {words['recompute']} to "
                                "discard the stored rows and compute every point again")
        else:
            whole, rows, fix = "study", "trials", f"or start afresh in another {words['out']}"
        if unverifiable and not recompute:
            raise self.error(f"cannot resume {self.out}: {unverifiable}; resuming could mix two models in one "
                             f"{whole}; restore metadata.json, {fix}")
        if changed and not recompute:
            raise self.error(f"{self.out} holds {rows} of other unit files than the spec names now ("
                             + "; ".join(changed) + f"); resuming would mix two models in one {whole}; restore "
                             f"the files, {fix}")
        if changed or unverifiable:  # only with recompute: the stored rows go
            self.store.discard_rows()

    @contextmanager
    def locked(self) -> Iterator[None]:
        """Hold the folder's lock for the block (FolderInUse when another process holds it)."""
        with results_writes(self.out, self.words):
            self.lock.acquire(self.command)  # released when this process ends, however it ends
        try:
            yield
        finally:
            self.lock.release()

    def write_metadata(self, metadata: Mapping[str, Any]) -> None:
        """Write ``metadata.json`` (a failed write is an OutputError naming the folder and the fix)."""
        with results_writes(self.out, self.words):
            self.store.write_metadata(metadata)

    def finish(self, missing: str, order: Any = None, csv: bool = False) -> dict[str, int]:
        """Merge the rows into ``results.parquet`` (in ``order`` of point ids when given, see
        ResultsStore.compact), record the counts by status; returns them.

        Raises ``error`` when a part was damaged while the study ran (it is set aside): its message names
        the part and ends with ``missing``, which may use ``{rows}`` (the rows in the table).
        """
        raise_if_stopped()  # a stop never ends as a complete study (issue 38.4), even one swallowed on its way
        with results_writes(self.out, self.words):  # a full disk during the final merge loses nothing (see compact)
            aside = self.store.set_aside_damaged()  # a part damaged while the study ran: its points are missing
            counts = self.store.compact(order=order, csv=csv)
            finish_metadata(self.store, counts)
        if aside:
            raise self.error(f"{self.out}: " + "; ".join(aside) + "; " + missing.format(rows=sum(counts.values())))
        return counts


@contextmanager
def study_cluster(choice: Any, error: type[UserError], interrupted: Callable[[], None],
                  early: Any = None) -> Iterator[tuple[Any, int, str]]:
    """:func:`cosim.parallel.cluster.client.dask_client` on ``choice`` (a
    :class:`~cosim.parallel.cluster.choice.ClusterChoice`) for a study: ``(client, worker threads, dashboard link)``.

    A cluster that cannot be had is the study's ``error`` (exit 2); on a stop (KeyboardInterrupt)
    ``interrupted()`` says where the rows are before it goes on.
    """
    from cosim.errors import ClusterError
    from cosim.parallel.cluster.client import dask_client

    try:
        with dask_client(choice, early=early) as connected:
            yield connected
    except ClusterError as exc:
        raise error(str(exc)) from None
    except KeyboardInterrupt:
        interrupted()
        raise


def interrupted_note(store: Any, out: Path, go_on: str, words: Mapping[str, str] = PYTHON_WORDS) -> str:
    """What an interrupted study says about its folder: how many rows it holds, or that it holds none yet
    (it said "the rows so far are in DIR" when there were none: issue 38.7).  ``go_on`` ends the sentence."""
    try:
        rows = len(store.done_ids())
    except Exception:  # noqa: BLE001 - a part half written as the stop came: the count is not worth a traceback
        rows = -1
    if rows == 0:
        return f"interrupted before any row was written: {out} holds none yet; run {words['again']} again to start"
    held = f"the {rows} row(s) so far are" if rows > 0 else "the rows so far are"
    return f"interrupted: {held} in {out}; run again with {words['resume']} to {go_on}"


def open_room(folder: Path) -> Any:
    """The decision room of ``folder`` served on loopback from a thread while the study writes it (``Show.explore``):
    a :class:`cosim.analysis.room.server.RoomServer` with its ``link``; stopped by the caller.  Raises
    AnalysisError when no port can be bound."""
    from cosim.analysis.room.live import LiveStudy
    from cosim.analysis.room.server import RoomServer

    return RoomServer(LiveStudy(folder))
