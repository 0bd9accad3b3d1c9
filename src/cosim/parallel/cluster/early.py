"""The default local Dask cluster, started in the background while a sweep is being prepared.

Starting the local cluster takes about a second of wall time (each worker
process starts a Python and imports Dask), and preparing a sweep after its
spec is checked (pandas and pyarrow for the results, the results folder, the
payload with the unit files) takes about half a second; neither needs the
other.  ``cosim sweep`` therefore starts the cluster first
(:class:`EarlyCluster`) and prepares the rest meanwhile;
:func:`cosim.parallel.cluster.client.dask_client` then takes the started cluster
instead of starting one.
"""

from __future__ import annotations

import threading
from typing import Any


class EarlyCluster:
    """:func:`cosim.parallel.cluster.local.local_cluster` of ``workers`` processes, started in a background thread.

    :meth:`take` waits for it and hands it over (the taker closes it);
    :meth:`close` closes it unless it was taken.  One of the two must be
    called: the cluster's processes live until then.
    """

    def __init__(self, workers: int):
        # Dask is imported here, not in the thread: the caller goes on importing modules that import parts of
        # Dask (cosim.parallel.dashboard.points), and two threads importing one package with circular imports can
        # see it half initialised (ImportError "partially initialized module 'distributed...'").
        import distributed  # noqa: F401

        self._cluster: Any = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._start, args=(workers,), name="cosim-early-cluster",
                                        daemon=True)
        self._thread.start()

    def _start(self, workers: int) -> None:
        from cosim.parallel.cluster.local import local_cluster

        try:
            self._cluster = local_cluster(workers)
        except BaseException as exc:  # handed to the thread that takes the cluster
            self._error = exc

    def take(self) -> Any:
        """The started cluster, now the caller's to close; raises what starting it raised."""
        self._thread.join()
        if self._error is not None:
            raise self._error
        cluster, self._cluster = self._cluster, None
        return cluster

    def close(self) -> None:
        """Close the cluster if it was not taken (after its start has ended)."""
        self._thread.join()
        cluster, self._cluster = self._cluster, None
        if cluster is not None:
            cluster.close()
