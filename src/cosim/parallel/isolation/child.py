"""The child process that runs a study's points: it loads the payload once, then answers with one row per point.

It is started by :class:`~cosim.parallel.isolation.runner.IsolatedRunner` (``python -c ...child_main``) with two
pipes (:mod:`.channel`), ignores Ctrl-C (the parent decides), removes its temporary folder however it ends, and
exits when its parent is gone.
"""

from __future__ import annotations

import os
import shutil
import signal
import tempfile
import threading
import time
from multiprocessing.connection import Connection
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator

from cosim.parallel.isolation.limits import limit_memory, recycle_reason
from cosim.parallel.isolation.payload import load_payload, named_for_the_user
from cosim.parallel.isolation.point_runner import PointRunner
from cosim.units.python import import_guard
from cosim.util.limits import limit

if TYPE_CHECKING:  # a type only: the child imports what it runs when it runs it
    from cosim.execution.point_row import PointRow


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


def child_main(read_fd: int, write_fd: int, parent: int) -> None:
    """The child's loop: load the payload, then answer 'run' messages with one row per point."""
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True).start()
    signal.signal(signal.SIGTERM, _remove_own_folder_and_exit)  # a group SIGTERM reaches this child too
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole group: the parent decides, quietly
    import_guard.CHECK_IN_CHILD = False  # this child is the isolation: a unit killing it costs a crashed point
    inbox, outbox = Connection(read_fd, writable=False), Connection(write_fd, readable=False)
    folder = tempfile.mkdtemp(prefix="payload_")  # under the TMPDIR the parent made for this child
    limit_memory(int(limit("child_memory_mb")) << 20)
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
            if kind not in ("run", "run_each", "prune", "prune_each"):
                return
            order = None
            if kind in ("prune", "prune_each"):  # each point with the front that came with the batch
                points, order = points  # (cosim.studies.pruning)
            if kind in ("run", "prune"):  # lock-step groups where the system allows (cosim.execution.lockstep)
                from cosim.execution.lockstep import LockstepRunner

                grouped = grouped or LockstepRunner(runner)
                rows: Iterator[PointRow] = grouped.rows(points, announce=lambda n: outbox.send(("group", n)),
                                                        prune=order)
            else:  # after a crash or timeout: one by one, so the row names the point that caused it
                rows = (runner.run(point_id, values, prune=order) for point_id, values in points)
            for row in rows:
                row = named_for_the_user(row, origins)
                served += 1
                reason = recycle_reason(served)  # not None: the parent starts a fresh child for the rest
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
