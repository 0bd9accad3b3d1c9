"""The payload of a study (its system and unit files) on every Dask worker, scattered anew when lost."""

from __future__ import annotations

import time
from typing import Any

from cosim.errors import ClusterError
from cosim.parallel.dashboard.task_keys import payload_key

SCATTER_TRIES = 5  # sending the payload to the workers, when workers die meanwhile
WORKER_WAIT = 120.0  # seconds to wait for a worker when all died (a loaded machine restarts them slowly)


class ScatteredPayload:
    """The payload scattered to every worker; scattered anew when the workers holding it are all gone.

    Scattered data lives only on workers: when every worker that held it
    dies (a cluster of two both killed, a lost node), its tasks are cancelled.
    The payload travels as one piece of data under one key that names it for people
    (:func:`~cosim.parallel.dashboard.task_keys.payload_key`, e.g. ``cosim sweep NAME system and unit
    files-<unique>``): scattered as a dict, Dask would have made one key per entry, and the dashboard showed
    them as "key", "system", "files" and "limits".
    """

    def __init__(self, client: Any, payload: dict[str, Any], key: str | None = None):
        """``key``: the Dask key of the scattered payload (default: a unique one naming no study)."""
        self.client, self.payload, self._future = client, payload, None
        self.key = key or payload_key("", "")

    def future(self) -> Any:
        """The payload's future; scattered anew if it is lost (the workers holding it all died).

        The payload is lost when every worker holding it died, and then there
        may be no worker for a while (their nannies restart them): it waits up
        to WORKER_WAIT seconds for one, then raises ClusterError.  A worker that dies while the payload
        is being sent to it fails the scatter (CommClosedError, an OSError, or
        a ValueError from the broadcast): it is tried again, at most
        SCATTER_TRIES times.
        """
        if self._future is None or not _alive(self._future):
            for attempt in range(SCATTER_TRIES):
                try:
                    self._wait_for_a_worker()
                    self._future = self.client.scatter({self.key: self.payload}, broadcast=True)[self.key]
                    break
                # OSError, also TimeoutError: "No valid workers found" when the last one just died; ValueError: "Can
                # not use replicate to delete data" when the workers changed while the payload was sent to them all
                except (OSError, ValueError):
                    if attempt == SCATTER_TRIES - 1:
                        raise
                    time.sleep(1.0)  # the scheduler removes the dead worker meanwhile
        return self._future

    def release(self) -> None:
        """Let go of the scattered payload; call it before the client closes.

        A future still alive when the interpreter exits is released by its
        ``__del__`` after the modules are torn down, which distributed 2024.1
        (the declared floor) reports as "Exception ignored in Future.__del__"
        tracebacks; a released future's ``__del__`` does nothing.
        """
        release_futures(self._future.values() if isinstance(self._future, dict) else [self._future])
        self._future = None

    def _wait_for_a_worker(self) -> None:
        """Raises ClusterError when no worker is there within WORKER_WAIT seconds (all died, none came back)."""
        try:
            self.client.wait_for_workers(1, timeout=WORKER_WAIT)
        except TimeoutError:
            raise ClusterError(f"every Dask worker died and none came back within {WORKER_WAIT:g} s (a Dask nanny "
                               "does not restart a worker killed while it starts); the rows so far are kept: start "
                               "workers, then resume the study to finish it") from None


def release_futures(futures: Any) -> None:
    """Release every future of ``futures`` (None entries skipped); see :meth:`ScatteredPayload.release`."""
    for future in futures:
        if future is not None:
            future.release()


def _alive(scattered: Any) -> bool:
    """Whether every future of a scattered object (a dict is scattered value by value) still holds its data."""
    futures = scattered.values() if isinstance(scattered, dict) else [scattered]
    return all(f.status == "finished" for f in futures)
