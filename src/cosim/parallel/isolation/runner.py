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

The child's side is :mod:`.child`, its channel :mod:`.channel`, its limits :mod:`.limits`, what it is sent
:mod:`.payload`, and every child of this process is known to :mod:`.children`.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any, Callable, Sequence

from cosim.execution.point_row import PointRow
from cosim.parallel.isolation.channel import Channel, too_long_message
from cosim.parallel.isolation.children import LIVE, SPARES, SPARES_LOCK, STOPPING, register_exit_hook
from cosim.parallel.isolation.leftovers import mark, remove_leftovers
from cosim.parallel.isolation.point_runner import row_without_result
from cosim.util.limits import LIMITS, limit

LOAD_TIMEOUT = 300.0  # seconds a fresh child may take to import, unpack and load the system

_leftovers_removed = False  # whether this process removed the cosim_worker_* folders killed ones left


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
        self._channel: Channel | None = None
        self._limits: dict[str, str] = {}  # the limits the child was started with
        self._loading: str | None = None  # a spare child's: the key of the payload sent to it ahead of its runner
        self.cut_by_stop: set[str] = set()  # points of the last run() ended by a stop (see run)

    def _pipes(self) -> tuple[Connection, Channel]:
        """The started child's pipe to it and channel from it (set by _spawn or a taken spare, before any use)."""
        assert self._outbox is not None and self._channel is not None, "no child started"
        return self._outbox, self._channel

    def _start(self) -> str | None:
        """Start a child (or take a spare one) and load the payload; None when ready, else why it failed."""
        limits = self.payload.get("limits", {})
        loading = self._adopt_spare(limits)  # None: no spare; else whether it is loading this payload already
        if loading is None:
            self._spawn(limits)
        outbox, channel = self._pipes()
        if not loading:
            try:
                outbox.send(("load", self.payload))
            except OSError:
                pass  # the child is already gone: the channel says so below
        message = channel.get(LOAD_TIMEOUT)
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
            # SIGINT ignored first: the terminal's Ctrl-C reaches this child too, and the client decides.  Ignored
            # from the exec on (sh's `trap "" INT`, inherited by the interpreter, which then keeps it ignored): a
            # Ctrl-C during the interpreter's own start-up (site, ~0.1 s) printed "Fatal Python error:
            # init_import_site" with a traceback on the user's terminal (issue 38)
            ["/bin/sh", "-c", 'trap "" INT; exec "$0" "$@"',
             sys.executable, "-c", "import signal; signal.signal(signal.SIGINT, signal.SIG_IGN); "
             "import sys; from cosim.parallel.isolation.child import child_main; "
             "child_main(*map(int, sys.argv[1:])); import gc; gc.freeze()",
             str(to_child_r), str(from_child_w), str(os.getpid())],
            pass_fds=(to_child_r, from_child_w), env=env, stdin=subprocess.DEVNULL)
        os.close(to_child_r)
        os.close(from_child_w)
        self._outbox = Connection(to_child_w, readable=False)
        self._inbox = Connection(from_child_r, writable=False)
        self._channel = Channel(self._inbox)
        self._limits = dict(limits)
        register_exit_hook()
        LIVE.add(self)
        self._kill_if_stopping()

    def _kill_if_stopping(self) -> None:
        """Kill this runner's child when a stop began: one started (or taken) while kill_point_children_now went
        through LIVE was not in it yet, and would run its point to the end (the flag is set before that pass,
        the runner is in LIVE before this check: one of the two sees the other)."""
        if STOPPING.is_set() and self._proc is not None and self._proc.poll() is None:
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
            with SPARES_LOCK:
                found = next((i for i, spare in enumerate(SPARES) if fits(spare)), None)
                if found is None:
                    return None
                spare = SPARES.pop(found)
            if spare._proc is not None and spare._proc.poll() is None:
                break
            spare.close()  # died waiting (killed from outside): try the next one
        self._proc, self._inbox, self._outbox = spare._proc, spare._inbox, spare._outbox
        self._folder, self._channel, self._limits = spare._folder, spare._channel, spare._limits
        spare._proc = spare._inbox = spare._outbox = spare._folder = spare._channel = None
        LIVE.discard(spare)
        LIVE.add(self)
        self._kill_if_stopping()
        return spare._loading == self.key

    def run(self, points: Sequence[tuple[str, dict[str, Any]]], timeout: float | None = None,
            on_row: Callable[[PointRow], None] | None = None, prune: Any = None) -> list[PointRow]:
        """One row per point, in order; statuses ok, failed, timeout or crashed (and pruned with ``prune``, a
        :class:`~cosim.execution.prune.PruneOrder`: a point alone or a row of a lock-step group stops once
        proven off its front).

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
            if made_here and STOPPING.is_set():  # a stop killed the child or ended the batch: not finished
                self.cut_by_stop.update(row.point_id for row in new)
                return
            if on_row is not None:
                for row in new:
                    on_row(row)

        remaining = list(points)
        mode = "run" if prune is None else "prune"  # after a crash or timeout: *_each, one point at a time
        while remaining:
            if STOPPING.is_set():  # the study is being stopped: the rest of the batch does not run
                keep(*(row_without_result(pid, "failed", "not run: the study was stopped", time.perf_counter())
                       for pid, _ in remaining), made_here=True)
                break
            if self._proc is None or self._proc.poll() is not None:
                self.close()
                problem = self._start()
                if problem is not None:
                    self.close()
                    keep(*(row_without_result(pid, "failed", problem, time.perf_counter()) for pid, _ in remaining),
                         made_here=True)
                    break
            outbox, channel = self._pipes()
            try:
                outbox.send((mode, (remaining, prune) if prune is not None else remaining))
            except OSError:
                self.close()
                continue
            done = grouped = 0  # grouped: rows still to come from a lock-step group the child announced
            while done < len(remaining):
                point_id = remaining[done][0]
                started = time.perf_counter()
                received = channel.get(deadline)
                if received is None:
                    self.close(force=True)
                    mode = "prune_each" if prune is not None else "run_each"
                    if grouped:  # not this point's fault for sure: the group's points run again one by one
                        break
                    keep(row_without_result(point_id, "timeout", f"no result within the timeout of {deadline:g} s; "
                                                   "the run was stopped", started), made_here=True)
                    done += 1
                    break
                kind, body = received
                if kind == "eof":
                    mode = "prune_each" if prune is not None else "run_each"
                    if grouped:  # as for a timeout: which point of the group killed the child is found alone
                        self.close()
                        break
                    keep(row_without_result(point_id, "crashed", f"the process running this point died "
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
                    mode = "prune_each" if prune is not None else "run_each"
                    if grouped:  # written by some point of the group: found when they run one by one
                        break
                    told = (f"its row is {why}" if why == too_long_message() else "the process running this point "
                            f"wrote something other than a result on its channel ({why})")
                    keep(row_without_result(point_id, "crashed", f"{told}; it was replaced", started),
                         made_here=True)
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

    def warm_up(self, timeout: float, timeout_from: str = "COSIM_TIMEOUT_FIRST") -> tuple[Any, Any]:
        """(the warm state, None) made by the child, or (None, why not): a UserError of the warm-up, or a
        message when the child cannot load the system, dies, hangs beyond ``timeout`` seconds (given by
        ``timeout_from``, named in the message) or writes junk."""
        if self._proc is None or self._proc.poll() is not None:
            self.close()
            problem = self._start()
            if problem is not None:
                self.close()
                return None, problem
        outbox, channel = self._pipes()
        try:
            outbox.send(("warm", None))
        except OSError:
            pass  # gone: the channel says so below
        received = channel.get(timeout)
        if received is None:
            self.close(force=True)
            return None, f"it did not finish within {timeout:g} s ({timeout_from}); it was stopped"
        kind, body = received
        if kind == "eof":
            why = f"the process running it died ({self._exit_text()})"
            self.close()
            return None, why
        if kind == "junk" and body == too_long_message():
            self.close(force=True)
            return None, f"its state is {body}"
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
        LIVE.discard(self)


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
        with SPARES_LOCK:
            SPARES.append(spare)
