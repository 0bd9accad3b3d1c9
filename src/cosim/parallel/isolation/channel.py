"""The pipe from a point child to its parent, read by a thread so that every wait of the parent has a deadline."""

from __future__ import annotations

import pickle
import queue
import threading
from multiprocessing.connection import Connection
from typing import Any

from cosim.util.limits import limit, raise_hint


def max_message() -> int:
    """Bytes of one message from a child (a row is a few kB): the ``child_message_mb`` limit."""
    return int(limit("child_message_mb") * (1 << 20))


def too_long_message() -> str:
    """What a message over :func:`max_message` is called, with the limit, its unit and the way to raise it."""
    return (f"a message larger than the limit of {limit('child_message_mb'):g} MB for one message from a child "
            f"process; {raise_hint('child_message_mb')}")


# "row": (PointRow, why the child ends itself after it or None); "group": n rows of one lock-step run follow
# (cosim.execution.lockstep); "warm": (the warm state or None, why not) for a study's warm-up
KINDS = ("ready", "error", "row", "group", "warm")


class Channel:
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
                data = conn.recv_bytes(max_message())
            except EOFError:
                self._queue.put(("eof", None))
                return
            except OSError as exc:  # a length over max_message(), or the pipe closed under us
                # multiprocessing says only "bad message length" for one too long: name the limit instead
                self._queue.put(("junk", too_long_message() if "bad message length" in str(exc) else f"{exc}"))
                return
            except Exception as exc:  # a malformed length header
                self._queue.put(("junk", f"{type(exc).__name__}: {exc}"))
                return
            try:
                message = pickle.loads(data)
            except Exception as exc:
                self._queue.put(("junk", f"undecodable bytes ({type(exc).__name__})"))
                return
            if not (isinstance(message, tuple) and len(message) == 2 and message[0] in KINDS):
                self._queue.put(("junk", "a message of unknown form"))
                return
            self._queue.put(message)

    def get(self, timeout: float) -> tuple[str, Any] | None:
        """The next message, or None when none came within ``timeout`` seconds."""
        try:
            return self._queue.get(timeout=timeout)
        except queue.Empty:
            return None
