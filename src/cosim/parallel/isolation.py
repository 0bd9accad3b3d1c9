"""Running design points in a child process, so a point can hang or segfault safely.

An FMU is native code from someone else: it may crash its process or never
return.  :class:`IsolatedRunner` keeps one child Python process (running
:func:`child_main`) that loads the system once and runs
points one after the other, reusing live unit instances (``reset()`` between
points, re-instantiated after a failed point).  The parent sends a whole batch
and reads one row per point with a watchdog:

- no row within ``timeout`` seconds of the previous one: the child is killed,
  the point gets status ``timeout``;
- the child dies (segfault, abort, os._exit): the point gets ``crashed`` with
  the signal or exit code;

- the child writes something that is not a row into its channel to the
  parent (junk from a unit): the child is killed, the point gets ``crashed``;

and a fresh child takes the remaining points.  So :meth:`IsolatedRunner.run`
always returns exactly one row per point it was given, and no read of the
parent waits without a deadline (without a timeout, the
``timeout_first_seconds`` limit applies).

A child caps its own data memory (``COSIM_CHILD_MEMORY_MB``: an allocation
beyond it fails the point, not the machine) and ends itself after
``COSIM_CHILD_POINTS`` points or once it holds more than
``COSIM_CHILD_RSS_MB`` resident (a leaking unit); the parent then starts a
fresh one for the rest of the batch.

The *payload* (:func:`make_payload`) carries the pickled
:class:`~cosim.system.builder.System` together with the bytes of the files its
unit types read (FMUs, ``file.py`` units, played tables); the child writes them
into its own temporary folder and points the unit types there, so no shared
filesystem is assumed.
"""

from __future__ import annotations

import atexit
import hashlib
import logging
import os
import pickle
import queue
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import replace
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any, Callable, Sequence

from cosim.execution.point_row import PointRow
from cosim.parallel.leftovers import mark, remove_leftovers
from cosim.units.python import import_guard
from cosim.util.limits import LIMITS, limit

LOAD_TIMEOUT = 300.0  # seconds a fresh child may take to import, unpack and load the system

# -- the payload ------------------------------------------------------------------


def make_payload(system: Any) -> dict[str, Any]:
    """Everything a child needs to run points of ``system``, with no file shared with this process.

    Keys: ``key`` (a digest of the whole payload), ``system`` (pickled System),
    ``files`` (unit name -> [(file name, bytes), ...]): the files each unit
    type reads (:meth:`~cosim.units.protocol.UnitType.files`: FMUs, ``file.py``
    units, played tables, a plug-in kind's files).  A spec with ``experiment.warm_start`` is warmed up here,
    once, in a child process (:func:`warm_up_isolated`): the pickled System carries the units' serialized states.
    Raises OSError when a unit's file cannot be read, UserError when the warm-up cannot be made.
    """
    if system.spec.experiment.warm_start is not None and system.warm_start is None:
        # the warm-up runs once, in a child process like any point (it may crash or hang); its states travel
        system = replace(system, warm_start=warm_up_isolated(_plain_payload(system, "-warm-up"), system))
    return _plain_payload(system)


def _plain_payload(system: Any, key_suffix: str = "") -> dict[str, Any]:
    """The payload of ``system`` as it is (see :func:`make_payload`); ``key_suffix`` sets its key apart."""
    files: dict[str, list[tuple[str, bytes]]] = {}
    for name, system_unit in system.units.items():
        paths = system_unit.unit_type.files()
        if paths:
            files[name] = [(Path(p).name, Path(p).read_bytes()) for p in paths]
    blob = pickle.dumps(system, protocol=pickle.HIGHEST_PROTOCOL)
    h = hashlib.sha256(system.spec.digest.encode())
    for name in sorted(files):
        h.update(name.encode())
        for _, data in files[name]:
            h.update(hashlib.sha256(data).digest())
    from cosim.util.limits import settings

    # the client's limits hold in every worker child, wherever it runs (cosim.util.limits)
    # where each file came from: a message the child writes names the user's file, not the child's copy
    origins = {name: [str(Path(p).resolve()) for p in system.units[name].unit_type.files()] for name in files}
    return {"key": h.hexdigest()[:16] + key_suffix, "system": blob, "files": files, "limits": settings(),
            "origins": origins}


def warm_up_isolated(payload: dict[str, Any], system: Any) -> Any:
    """The warm state of ``system`` (:mod:`cosim.execution.warm_start`), made in a child process loaded with
    ``payload`` (its system without a warm state), within the ``timeout_first_seconds`` limit.

    Raises UserError naming the spec's ``experiment.warm_start`` when the warm-up cannot be made: a unit fails,
    cannot save its state, the child crashes or hangs.
    """
    from cosim.errors import Problem, UserError

    runner = IsolatedRunner(payload)
    try:
        state, why = runner.warm_up(float(limit("timeout_first_seconds")))
    finally:
        runner.close()
    if state is None:
        if isinstance(why, UserError):
            raise why
        raise UserError([Problem(system.spec.path, "$.experiment.warm_start", f"the warm-up run to t="
                                 f"{system.spec.experiment.warm_start:g} failed: {why}",
                                 "fix what makes the run with the spec's own values fail, or remove warm_start")])
    return state


def load_payload(payload: dict[str, Any], folder: str, origins: dict[str, str] | None = None) -> Any:
    """The System of ``payload``, its unit files written under ``folder`` and used from there.

    ``origins``, when given, is filled with each copy's path -> the path of the file it was copied from on the
    client (for :func:`named_for_the_user`)."""
    system = pickle.loads(payload["system"])
    for name, unit_files in payload["files"].items():
        copies = []
        sources = payload.get("origins", {}).get(name, [])
        for i, (file_name, data) in enumerate(unit_files):
            unit_folder = Path(folder) / name / str(i)  # one folder per unit and file: names may repeat
            unit_folder.mkdir(parents=True, exist_ok=True)
            local = unit_folder / file_name
            local.write_bytes(data)
            copies.append(local)
            if origins is not None and i < len(sources):
                origins[str(local)] = sources[i]
        system.units[name].unit_type.relocate(copies)
    return system


def named_for_the_user(row: PointRow, origins: dict[str, str]) -> PointRow:
    """``row`` with the paths of the child's copies of unit files in its message replaced by the user's own
    paths (issue 39: a unit's traceback named /tmp/cosim_worker_*/payload_*/b/0/unit.py, a file the user never
    saw and which is gone when the sweep ends)."""
    message = row.message
    for local, original in origins.items():
        if local in message:
            message = message.replace(local, original)
    return row if message == row.message else replace(row, message=message)


# -- the child ------------------------------------------------------------------------


class PointRunner:
    """Runs points of one system in this process, reusing unit instances between points.

    Units are reset (``fmi2Reset``/``fmi3Reset`` for an FMU) after each point that ended cleanly and reused
    for the next; after a failed point, and for a unit whose spec says ``"reuse": false``, they are made anew.
    A reset is trusted only once checked: the first clean point is run a second time on the reset units, and
    when its objectives differ in any bit from the fresh run's, no unit is reused in this runner again
    (``reset_broken``; logged once).
    """

    def __init__(self, system: Any):
        self.system = system
        self.units: dict[str, Any] | None = None
        self.reset_checked = False
        self.reset_broken = False
        self._fresh_only = {n for n, su in system.units.items() if su.spec.options.get("reuse") is False}
        # checked for FMUs only: a Python unit's reset is its own code, and running a point twice would show
        # in what it counts or writes
        self.reset_checked = any(su.description.kind != "fmu" for su in system.units.values())

    def run(self, point_id: str, values: dict[str, Any], prune: Any = None) -> PointRow:
        """One row for one point: status ok, failed or (with ``prune``, a
        :class:`~cosim.execution.prune.PruneOrder`) pruned, its message, run_time and objectives."""
        from cosim.errors import CosimError, SpecError
        from cosim.execution.point import run_point
        from cosim.execution.prune import PruneBound

        started = time.perf_counter()
        try:
            self._instantiate_missing()
        except Exception as exc:
            self.close()
            cause = str(exc) if isinstance(exc, CosimError) else f"{type(exc).__name__}: {exc}"
            return _row(point_id, "failed", f"cannot instantiate the units: {cause}", started)
        try:
            observers = [PruneBound(self.system, prune.settings, prune.front())] if prune is not None else []
            result = run_point(self.system, values, units=self.units, observers=observers)
        except SpecError as exc:  # raised before the units are touched: they stay fresh for the next point
            return _row(point_id, "failed", "; ".join(p.message for p in exc.problems), started)
        if (result.ok or result.status == "pruned") and not self.reset_broken:  # a clean stop at a point
            self._reset()
            if result.ok and not self.reset_checked and prune is None and self.units is not None:
                self._check_reset(values, result)
        else:
            self.close()  # after a failure, trust no instance's state
        return PointRow.of(point_id, result, time.perf_counter() - started)

    def _instantiate_missing(self) -> None:
        units = self.units if self.units is not None else {}
        for name, su in self.system.units.items():
            if name not in units:
                units[name] = su.unit_type.instantiate(name)
        self.units = dict((n, units[n]) for n in self.system.units)  # the system's order

    def _reset(self) -> None:
        """Reset every unit for the next point; units that opt out are terminated (made anew next time)."""
        assert self.units is not None
        try:
            for name in list(self.units):
                if name in self._fresh_only:
                    self.units.pop(name).terminate()
                else:
                    self.units[name].reset()
        except Exception:
            self.close()  # a unit that cannot reset is instantiated afresh for the next point

    def _check_reset(self, values: dict[str, Any], fresh: Any) -> None:
        """Run the point again on the reset units; a difference in any bit of an objective marks the reset
        broken (every point from now on gets fresh instances)."""
        from cosim.execution.point import run_point

        self.reset_checked = True
        self._instantiate_missing()
        again = run_point(self.system, values, units=self.units)
        same = again.status == fresh.status and list(again.objectives) == list(fresh.objectives) and all(
            struct.pack("<d", float(again.objectives[k])) == struct.pack("<d", float(v))
            for k, v in fresh.objectives.items())
        if same and again.ok:
            self._reset()
            return
        self.reset_broken = True
        logging.getLogger(__name__).warning(
            "note: a point run again on reset units gave other objectives than on fresh units: the units' "
            "reset is not trusted, every point gets fresh instances (set \"reuse\": false on the unit whose "
            "reset is broken to say so in the spec)")
        self.close()

    def close(self) -> None:
        for unit in (self.units or {}).values():
            try:
                unit.terminate()
            except Exception:
                pass  # terminating the others matters more
        self.units = None


def _row(point_id: str, status: str, message: str, started: float) -> PointRow:
    """The row of a point that gave no result (it failed before running, hung or crashed)."""
    return PointRow(point_id, status, message, time.perf_counter() - started)


_leftovers_removed = False  # whether this process removed the cosim_worker_* folders killed ones left


def _remove_own_folder() -> None:
    """Remove the temporary folder the parent made for this child (the parent may be gone already)."""
    folder = os.environ.get("TMPDIR", "")
    if Path(folder).name.startswith("cosim_worker_"):
        shutil.rmtree(folder, ignore_errors=True)


def _remove_own_folder_and_exit(*_: Any) -> None:
    _remove_own_folder()
    os._exit(3)


def _watch_parent(parent: int) -> None:
    """Exit when the parent is gone, even while the main thread hangs inside an FMU."""
    while True:
        if os.getppid() != parent:
            _remove_own_folder_and_exit()  # e.g. a Dask worker stopped with SIGTERM or SIGKILL
        time.sleep(0.5)


def _limit_memory(size: int) -> None:
    """Cap this process's data memory (RLIMIT_DATA: heap and private mappings) at ``size`` bytes.

    A unit that allocates beyond it gets MemoryError (Python) or a failed
    malloc (native code) in this child instead of starving the machine.
    """
    try:
        import resource

        soft, hard = resource.getrlimit(resource.RLIMIT_DATA)
        if hard == resource.RLIM_INFINITY or size < hard:
            resource.setrlimit(resource.RLIMIT_DATA, (size, hard))
    except (ImportError, ValueError, OSError):
        pass  # not on this platform: the recycling below still bounds a leak


def _resident_bytes() -> int:
    """This process's resident memory now (Linux /proc; 0 where unavailable)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


def _recycle_reason(served: int) -> str | None:
    """Why this child should be replaced after ``served`` points, or None."""
    if served >= limit("child_points"):
        return f"ran {served} points (COSIM_CHILD_POINTS)"
    resident = _resident_bytes()
    if resident > int(limit("child_rss_mb")) << 20:
        return f"holds {resident >> 20} MB (COSIM_CHILD_RSS_MB)"
    return None


def child_main(read_fd: int, write_fd: int, parent: int) -> None:
    """The child's loop: load the payload, then answer 'run' messages with one row per point."""
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True).start()
    signal.signal(signal.SIGTERM, _remove_own_folder_and_exit)  # a group SIGTERM reaches this child too
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole group: the parent decides, quietly
    import_guard.CHECK_IN_CHILD = False  # this child is the isolation: a unit killing it costs a crashed point
    inbox, outbox = Connection(read_fd, writable=False), Connection(write_fd, readable=False)
    folder = tempfile.mkdtemp(prefix="payload_")  # under the TMPDIR the parent made for this child
    _limit_memory(int(limit("child_memory_mb")) << 20)
    runner = grouped = None
    served = 0
    try:
        # what every payload needs (the stepping loop, numpy, the lock-step runner), imported before it comes:
        # a spare child (start_spare_children) is ready for it that much sooner
        from cosim.execution import lockstep, point  # noqa: F401

        kind, payload = inbox.recv()
        origins: dict[str, str] = {}
        try:
            runner = PointRunner(load_payload(payload, folder, origins))
            outbox.send(("ready", None))
        except Exception as exc:
            outbox.send(("error", f"cannot load the system on this worker: {type(exc).__name__}: {exc}"))
            return
        while True:
            try:
                kind, points = inbox.recv()
            except EOFError:
                return
            if kind == "warm":  # the study's warm-up (cosim.execution.warm_start), once, before any point
                outbox.send(("warm", _warm_up_here(runner.system)))
                continue
            if kind not in ("run", "run_each", "prune"):
                return
            if kind == "prune":  # one by one, each with the front that came with the batch (cosim.studies.pruning)
                points, order = points
                rows = (runner.run(point_id, values, prune=order) for point_id, values in points)
            elif kind == "run":  # lock-step groups where the system allows (cosim.execution.lockstep)
                from cosim.execution.lockstep import LockstepRunner

                grouped = grouped or LockstepRunner(runner)
                rows = grouped.rows(points, announce=lambda n: outbox.send(("group", n)))
            else:  # after a crash or timeout: one by one, so the row names the point that caused it
                rows = (runner.run(point_id, values) for point_id, values in points)
            for row in rows:
                row = named_for_the_user(row, origins)
                served += 1
                reason = _recycle_reason(served)  # not None: the parent starts a fresh child for the rest
                outbox.send(("row", (row, reason)))
                if reason:
                    return
    except (BrokenPipeError, ConnectionResetError, EOFError):
        # the parent is gone (a kill -9 of the sweep; or it ended before giving a spare child its payload: a
        # sweep refused for its spec's problems) or stopped listening: nobody waits for this row, and a
        # traceback here would land on the terminal of a client that no longer runs, after its last line
        return
    finally:
        if grouped is not None:
            grouped.close()
        if runner is not None:
            runner.close()
        from cosim.units.fmu.description import EXTRACTED

        EXTRACTED.clear()
        _remove_own_folder()


def _warm_up_here(system: Any) -> tuple[Any, Any]:
    """(the warm state, None), or (None, why it could not be made: the UserError itself, or a message)."""
    from cosim.errors import UserError
    from cosim.execution.warm_up import warm_up

    try:
        state, result = warm_up(system)
    except UserError as exc:
        return None, exc
    except Exception as exc:  # a bug of cosim's must still reach the study as a reason, not a lost child
        return None, f"internal error: {type(exc).__name__}: {exc}"
    return (state, None) if state is not None else (None, result.message)


# -- the parent side -----------------------------------------------------------------------

MAX_MESSAGE = 64 << 20  # bytes of one message from a child (a row is a few kB)
# "row": (PointRow, why the child ends itself after it or None); "group": n rows of one lock-step run follow
# (cosim.execution.lockstep); "warm": (the warm state or None, why not) for a study's warm-up
_KINDS = ("ready", "error", "row", "group", "warm")


class _Channel:
    """Messages from a child, read by a thread, so that every wait of the parent has a deadline.

    A unit runs inside the child and can write anything into the pipe back to
    the parent (a C library writing to the wrong file descriptor, a hostile
    unit).  The reader thread turns whatever arrives into ``(kind, body)``:
    a well-formed message, ``("eof", None)`` when the child is gone, or
    ``("junk", why)`` for bytes that are not a message; a message that is
    too long or does not unpickle to one of the known kinds is junk.  A
    partial message blocks only the thread, never the parent: the parent's
    deadline expires and the child is killed, which ends the thread.
    """

    def __init__(self, conn: Connection):
        self._queue: queue.Queue = queue.Queue()
        threading.Thread(target=self._read, args=(conn,), daemon=True).start()

    def _read(self, conn: Connection) -> None:
        try:
            self._read_until_the_end(conn)
        finally:
            # This thread closes the pipe, not IsolatedRunner.close: closed under a thread about to read again,
            # its descriptor number would go to the next child's pipe and this thread would steal that child's
            # first bytes (seen as "junk on its channel while loading the system" after a recycled child).
            conn.close()

    def _read_until_the_end(self, conn: Connection) -> None:
        while True:
            try:
                data = conn.recv_bytes(MAX_MESSAGE)
            except EOFError:
                self._queue.put(("eof", None))
                return
            except OSError as exc:  # a length over MAX_MESSAGE, or the pipe closed under us
                self._queue.put(("junk", f"{exc}"))
                return
            except Exception as exc:  # a malformed length header
                self._queue.put(("junk", f"{type(exc).__name__}: {exc}"))
                return
            try:
                message = pickle.loads(data)
            except Exception as exc:
                self._queue.put(("junk", f"undecodable bytes ({type(exc).__name__})"))
                return
            if not (isinstance(message, tuple) and len(message) == 2 and message[0] in _KINDS):
                self._queue.put(("junk", "a message of unknown form"))
                return
            self._queue.put(message)

    def get(self, timeout: float) -> tuple[str, Any] | None:
        """The next message, or None when none came within ``timeout`` seconds."""
        try:
            return self._queue.get(timeout=timeout)
        except queue.Empty:
            return None


_LIVE: set["IsolatedRunner"] = set()


_kill_children_registered = False


def _register_exit_hook() -> None:
    """At the first child process, not at import: importing cosim leaves no exit hook."""
    global _kill_children_registered
    atexit.register(_kill_children)
    _kill_children_registered = True


def _kill_children() -> None:
    stop_spare_children()  # no need to wait for a child that never had work
    runners = list(_LIVE)
    for runner in runners:  # all asked first, so they finish (terminate their units) at the same time
        runner.ask_to_finish()
    for runner in runners:
        runner.close()


_STOPPING = threading.Event()  # set by a stop signal: runners start no new child and run no further point


def allow_point_children() -> None:
    """Undo :func:`kill_point_children_now`'s stop for this process (a program that goes on after a study)."""
    _STOPPING.clear()


def kill_point_children_now() -> None:
    """Kill every point child of this process at once, without waiting (the study is being stopped).

    Called from the client's stop-signal handler: a point may take minutes, and waiting for it
    kept a stopped sweep alive long past a job scheduler's grace period.  The points these
    children were running are not finished, so no row of theirs is lost; the worker threads
    waiting on them see the child gone and return at once.
    """
    _STOPPING.set()  # first: a batch's next point must not start a fresh child
    for runner in list(_LIVE) + list(_SPARES):
        proc = runner._proc
        if proc is not None and proc.poll() is None:
            try:
                proc.kill()
            except OSError:
                pass


_SPARES: list["IsolatedRunner"] = []  # children started ahead of their payload (start_spare_children)
_SPARES_LOCK = threading.Lock()


def start_spare_children(count: int) -> None:
    """Start ``count`` point children now, before any payload exists, for this process's next IsolatedRunners.

    A child's start (a Python, and cosim's modules imported: about 0.15 s of
    CPU) then overlaps what this process does meanwhile -- for ``cosim sweep``
    on a local cluster, whose workers run in this process, its own imports and
    the spec check -- instead of delaying the first points.  A spare child is
    an ordinary child waiting for its payload: an IsolatedRunner takes one
    started with the same limits (cosim.util.limits, read from this
    process's environment now) or starts its own; spares never taken are
    stopped at exit with every other child.
    """
    from cosim.util.limits import settings

    limits = settings()
    for _ in range(count):
        spare = IsolatedRunner({"key": None, "limits": limits})
        spare._spawn(limits)
        with _SPARES_LOCK:
            _SPARES.append(spare)


def preload_spare_children(payload: dict[str, Any]) -> None:
    """Send ``payload`` to the spare children that have none yet: they load it (the units' imports, the unit
    files written out) while this process goes on, and the runners of this payload that take them only wait
    for them to be ready."""
    with _SPARES_LOCK:
        for spare in _SPARES:
            if spare._loading is None and spare._limits == payload.get("limits", {}):
                try:
                    spare._outbox.send(("load", payload))
                except OSError:
                    continue  # gone: the runner that takes it finds it dead and starts its own
                spare._loading = payload["key"]


def stop_spare_children() -> None:
    """Stop the spare children no runner took (the sweep runs elsewhere after all)."""
    with _SPARES_LOCK:
        spares = list(_SPARES)
        _SPARES.clear()
    for spare in spares:
        spare.close(force=True)


def _is_row_of(body: Any, point_id: str) -> bool:
    """Whether a "row" message's body is (PointRow of ``point_id``, recycle reason or None)."""
    return (isinstance(body, tuple) and len(body) == 2 and isinstance(body[0], PointRow)
            and body[0].point_id == point_id and (body[1] is None or isinstance(body[1], str)))


class IsolatedRunner:
    """Runs batches of points of one payload in a child process with a watchdog (module docstring)."""

    def __init__(self, payload: dict[str, Any]):
        self.payload = payload
        self.key = payload["key"]
        self._proc: subprocess.Popen | None = None
        self._inbox: Connection | None = None
        self._outbox: Connection | None = None
        self._folder: str | None = None
        self._channel: _Channel | None = None
        self._limits: dict[str, str] = {}  # the limits the child was started with
        self._loading: str | None = None  # a spare child's: the key of the payload sent to it ahead of its runner
        self.cut_by_stop: set[str] = set()  # points of the last run() ended by a stop (see run)

    def _start(self) -> str | None:
        """Start a child (or take a spare one) and load the payload; None when ready, else why it failed."""
        limits = self.payload.get("limits", {})
        loading = self._adopt_spare(limits)  # None: no spare; else whether it is loading this payload already
        if loading is None:
            self._spawn(limits)
        if not loading:
            try:
                self._outbox.send(("load", self.payload))
            except OSError:
                pass  # the child is already gone: the channel says so below
        message = self._channel.get(LOAD_TIMEOUT)
        if message is None:
            self.close(force=True)
            return f"the worker's child process did not load the system within {LOAD_TIMEOUT:g} s"
        kind, body = message
        if kind == "ready":
            return None
        if kind == "error":
            self.close()
            return str(body)
        why = f"died ({self._exit_text_now()})" if kind == "eof" else f"wrote junk on its channel ({body})"
        self.close(force=True)
        return f"the worker's child process {why} while loading the system"

    def _spawn(self, limits: dict[str, str]) -> None:
        """Start a child process that waits for its payload, with ``limits`` (cosim.util.limits) in its
        environment."""
        to_child_r, to_child_w = os.pipe()
        from_child_r, from_child_w = os.pipe()
        # The child's temporary files (payload, extracted FMUs) go into a folder this
        # process owns and removes, also when the child had to be killed.
        global _leftovers_removed
        if not _leftovers_removed:  # those of a cosim killed with its whole process group (kill -9): issue 38.8
            _leftovers_removed = True
            remove_leftovers()
        self._folder = tempfile.mkdtemp(prefix="cosim_worker_")
        mark(self._folder)  # whose it is: removed by a later start if this process is killed
        env = dict(os.environ, TMPDIR=self._folder)
        for setting in LIMITS.values():  # the limits of the client that made the payload, not this worker's
            env.pop(setting.env, None)
        env.update(limits)
        root = str(Path(__file__).resolve().parents[2])  # the folder holding the cosim package (src/ in a checkout)
        env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")  # works from a source checkout too
        self._proc = subprocess.Popen(
            # gc.freeze once child_main is done: the interpreter's final collections over the units' modules
            # would only delay the exit the worker waits for
            # SIGINT ignored first: the terminal's Ctrl-C reaches this child too, and the client decides
            [sys.executable, "-c", "import signal; signal.signal(signal.SIGINT, signal.SIG_IGN); "
             "import sys; from cosim.parallel.isolation import child_main; "
             "child_main(*map(int, sys.argv[1:])); import gc; gc.freeze()",
             str(to_child_r), str(from_child_w), str(os.getpid())],
            pass_fds=(to_child_r, from_child_w), env=env, stdin=subprocess.DEVNULL)
        os.close(to_child_r)
        os.close(from_child_w)
        self._outbox = Connection(to_child_w, readable=False)
        self._inbox = Connection(from_child_r, writable=False)
        self._channel = _Channel(self._inbox)
        self._limits = dict(limits)
        if not _kill_children_registered:
            _register_exit_hook()
        _LIVE.add(self)
        self._kill_if_stopping()

    def _kill_if_stopping(self) -> None:
        """Kill this runner's child when a stop began: one started (or taken) while kill_point_children_now went
        through _LIVE was not in it yet, and would run its point to the end (the flag is set before that pass,
        the runner is in _LIVE before this check: one of the two sees the other)."""
        if _STOPPING.is_set() and self._proc is not None and self._proc.poll() is None:
            try:
                self._proc.kill()
            except OSError:
                pass

    def _adopt_spare(self, limits: dict[str, str]) -> bool | None:
        """Take over a live spare child started with the same ``limits`` and loading nothing or this payload.

        Returns None when there is none, else whether the child is loading this payload already
        (:func:`preload_spare_children`).
        """
        def fits(spare: IsolatedRunner) -> bool:
            return spare._limits == limits and spare._loading in (None, self.key)

        while True:
            with _SPARES_LOCK:
                found = next((i for i, spare in enumerate(_SPARES) if fits(spare)), None)
                if found is None:
                    return None
                spare = _SPARES.pop(found)
            if spare._proc is not None and spare._proc.poll() is None:
                break
            spare.close()  # died waiting (killed from outside): try the next one
        self._proc, self._inbox, self._outbox = spare._proc, spare._inbox, spare._outbox
        self._folder, self._channel, self._limits = spare._folder, spare._channel, spare._limits
        spare._proc = spare._inbox = spare._outbox = spare._folder = spare._channel = None
        _LIVE.discard(spare)
        _LIVE.add(self)
        self._kill_if_stopping()
        return spare._loading == self.key

    def run(self, points: Sequence[tuple[str, dict[str, Any]]], timeout: float | None = None,
            on_row: Callable[[PointRow], None] | None = None, prune: Any = None) -> list[PointRow]:
        """One row per point, in order; statuses ok, failed, timeout or crashed (and pruned with ``prune``, a
        :class:`~cosim.execution.prune.PruneOrder`: each point then runs alone, never in a lock-step group).

        Without ``timeout`` a point may run for the ``timeout_first_seconds``
        limit (COSIM_TIMEOUT_FIRST): no read of a child waits forever.
        ``on_row`` is called with each row as soon as its point is done.  Once a stop began
        (:func:`kill_point_children_now`), the rows this runner makes up for points it could not finish
        (``timeout``, ``crashed``, ``failed`` not run) are not passed to ``on_row``, and their ids are in
        :attr:`cut_by_stop` after the call: the stop, not the point, ended them.
        """
        deadline = timeout if timeout is not None else float(limit("timeout_first_seconds"))
        rows: list[PointRow] = []
        self.cut_by_stop = set()

        def keep(*new: PointRow, made_here: bool = False) -> None:
            """Rows of points that finished, or (``made_here``) that this runner gave up on."""
            rows.extend(new)
            if made_here and _STOPPING.is_set():  # a stop killed the child or ended the batch: not finished
                self.cut_by_stop.update(row.point_id for row in new)
                return
            for row in new if on_row is not None else ():
                on_row(row)

        remaining = list(points)
        mode = "run"  # after a crash or timeout the rest runs one point at a time (no lock-step groups)
        if prune is not None:
            mode = "prune"
        while remaining:
            if _STOPPING.is_set():  # the study is being stopped: the rest of the batch does not run
                keep(*(_row(pid, "failed", "not run: the study was stopped", time.perf_counter())
                       for pid, _ in remaining), made_here=True)
                break
            if self._proc is None or self._proc.poll() is not None:
                self.close()
                problem = self._start()
                if problem is not None:
                    self.close()
                    keep(*(_row(pid, "failed", problem, time.perf_counter()) for pid, _ in remaining), made_here=True)
                    break
            try:
                self._outbox.send((mode, (remaining, prune) if mode == "prune" else remaining))
            except OSError:
                self.close()
                continue
            done = grouped = 0  # grouped: rows still to come from a lock-step group the child announced
            while done < len(remaining):
                point_id = remaining[done][0]
                started = time.perf_counter()
                received = self._channel.get(deadline)
                if received is None:
                    self.close(force=True)
                    mode = "prune" if prune is not None else "run_each"
                    if grouped:  # not this point's fault for sure: the group's points run again one by one
                        break
                    keep(_row(point_id, "timeout", f"no result within the timeout of {deadline:g} s; "
                                                   "the run was stopped", started), made_here=True)
                    done += 1
                    break
                kind, body = received
                if kind == "eof":
                    mode = "prune" if prune is not None else "run_each"
                    if grouped:  # as for a timeout: which point of the group killed the child is found alone
                        self.close()
                        break
                    keep(_row(point_id, "crashed", f"the process running this point died "
                                                   f"({self._exit_text()})", started), made_here=True)
                    self.close()
                    done += 1
                    break
                if kind == "group" and isinstance(body, int) and body > 0 and not grouped:
                    grouped = body  # the next `body` rows come from one lock-step run (cosim.execution.lockstep)
                    continue
                if kind != "row" or not _is_row_of(body, point_id):
                    why = body if kind == "junk" else "a message that is not this point's row"
                    self.close(force=True)  # its channel is out of step: trust nothing more from it
                    mode = "prune" if prune is not None else "run_each"
                    if grouped:  # written by some point of the group: found when they run one by one
                        break
                    keep(_row(point_id, "crashed", "the process running this point wrote something "
                                                   f"other than a result on its channel ({why}); it was "
                                                   "replaced", started), made_here=True)
                    done += 1
                    break
                row, recycle = body
                keep(row)
                done += 1
                grouped = max(0, grouped - 1)
                if recycle:  # the child ended itself (memory or point count): a fresh one goes on
                    self.close()
                    break
            remaining = remaining[done:]
        return rows

    def warm_up(self, timeout: float) -> tuple[Any, Any]:
        """(the warm state, None) made by the child, or (None, why not): a UserError of the warm-up, or a
        message when the child cannot load the system, dies, hangs beyond ``timeout`` seconds or writes junk."""
        if self._proc is None or self._proc.poll() is not None:
            self.close()
            problem = self._start()
            if problem is not None:
                self.close()
                return None, problem
        try:
            self._outbox.send(("warm", None))
        except OSError:
            pass  # gone: the channel says so below
        received = self._channel.get(timeout)
        if received is None:
            self.close(force=True)
            return None, f"it did not finish within {timeout:g} s (COSIM_TIMEOUT_FIRST); it was stopped"
        kind, body = received
        if kind == "eof":
            why = f"the process running it died ({self._exit_text()})"
            self.close()
            return None, why
        if kind != "warm" or not (isinstance(body, tuple) and len(body) == 2):
            self.close(force=True)
            return None, f"the process running it wrote something other than a result on its channel ({body})"
        return body

    def _exit_text_now(self) -> str:
        if self._proc is not None and self._proc.poll() is None:
            try:
                self._proc.wait(timeout=1)
            except subprocess.TimeoutExpired:
                return "still running"
        return self._exit_text()

    def _exit_text(self) -> str:
        if self._proc is None:
            return "unknown cause"
        try:
            code = self._proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            return "still running"
        if code < 0:
            try:
                return f"killed by signal {signal.Signals(-code).name}"
            except ValueError:
                return f"killed by signal {-code}"
        return f"exit code {code}"

    def ask_to_finish(self) -> None:
        """Tell the child to finish (EOF on its inbox) without waiting for it; :meth:`close` still has to follow."""
        outbox, self._outbox = self._outbox, None
        if outbox is not None:
            try:
                outbox.close()
            except OSError:
                pass

    def close(self, force: bool = False) -> None:
        """Stop the child and release its pipes and files.

        The child is first asked to finish (it terminates its units); it is
        killed when ``force`` is true or it does not exit within 2 s.
        """
        proc, self._proc = self._proc, None
        self.ask_to_finish()
        # the pipe from the child is closed by its reader thread at EOF, once the child is gone (see _Channel)
        self._inbox = None
        if proc is not None and proc.poll() is None:
            if not force:
                try:
                    proc.wait(timeout=2)
                except subprocess.TimeoutExpired:
                    pass
            if proc.poll() is None:
                proc.kill()
                try:
                    proc.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    pass
        if self._folder is not None:
            shutil.rmtree(self._folder, ignore_errors=True)
            self._folder = None
        _LIVE.discard(self)

