"""Which Dask cluster a study runs on: decided here, once, and nowhere else.

In order of precedence:

1. a cluster file (YAML or JSON, :mod:`cosim.parallel.cluster.cluster_file`): cosim starts the cluster it
   names (Slurm, PBS, Kubernetes, a LocalCluster ...) and closes it after the study;
2. the address of a running scheduler, given;
3. Dask's own configuration: ``scheduler-address`` (also set by the environment variable
   ``DASK_SCHEDULER_ADDRESS``), see :func:`configured_scheduler`;
4. otherwise a local cluster whose workers run in cosim's process, each running its points in a child process
   (:func:`cosim.parallel.cluster.local.local_cluster`).

:func:`choose_cluster` checks what it is given (a cluster file is read and checked, an address must have the
form of one) and returns a :class:`ClusterChoice`; :func:`cosim.parallel.cluster.client.dask_client` connects
to what it names.  The messages name no command-line option: the command line adds its own words.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from cosim.errors import ClusterError, SchedulerAddressError

if TYPE_CHECKING:
    from cosim.parallel.cluster.cluster_file import ClusterFile

CONFIGURED = "DASK_SCHEDULER_ADDRESS (or Dask's scheduler-address setting)"  # where a configured address comes from


@dataclass(frozen=True)
class ClusterChoice:
    """The cluster a study runs on: ``kind`` is ``file``, ``address`` or ``local``.

    ``workers``: the worker count of a local cluster; ``address``: the scheduler's (given, or ``configured``
    in Dask's configuration); ``file``: the checked cluster file.
    """

    kind: Literal["file", "address", "local"]
    workers: int
    address: str | None = None
    file: ClusterFile | None = None
    configured: bool = False

    @property
    def local(self) -> bool:
        """Whether cosim starts a local cluster in this process (its workers' point children are this process's)."""
        return self.kind == "local"

    @property
    def started_here(self) -> bool:
        """Whether cosim starts the cluster and closes it (and its dashboard) when the study ends."""
        return self.kind != "address"

    def describe(self) -> str:
        """Where the cluster comes from, for messages: the address and, when configured, from where."""
        if self.kind == "file":
            return f"the cluster of {self.file.path if self.file else '?'}"
        if self.kind == "address":
            return f"{self.address}" + (f" (from {CONFIGURED})" if self.configured else "")
        return f"a local cluster of {self.workers} worker(s)"


def choose_cluster(workers: int, scheduler: str | None = None, cluster_file: str | Path | None = None
                   ) -> ClusterChoice:
    """The cluster of a study (module docstring), checked before any work.

    Raises ClusterError when both a cluster file and a scheduler address are given, SchedulerAddressError
    (a ClusterError) for an address that does not have the form of one, ClusterFileError for a bad cluster
    file (every mistake at once).
    """
    from cosim.parallel.cluster.cluster_file import read_cluster_file

    if cluster_file is not None and scheduler is not None:
        raise ClusterError("give either a cluster file or a scheduler address, not both")
    if cluster_file is not None:
        return ClusterChoice("file", workers, file=read_cluster_file(cluster_file))
    if scheduler is not None:
        check_scheduler_address(scheduler)
        return ClusterChoice("address", workers, address=scheduler)
    configured = configured_scheduler()
    if configured is not None:
        return ClusterChoice("address", workers, address=configured, configured=True)
    return ClusterChoice("local", workers)


def named_local(scheduler: str | None, cluster_file: str | Path | None) -> bool:
    """Whether a study given this is most likely on a local cluster, without reading Dask's configuration
    (importing Dask costs 0.1 s): the guess a command makes before it has imported anything, to start the
    local workers' point children early (:func:`cosim.parallel.isolation.runner.start_spare_children`;
    they are stopped if :func:`choose_cluster` decides otherwise)."""
    return scheduler is None and cluster_file is None


def check_scheduler_address(address: str) -> None:
    """Raise SchedulerAddressError unless ``address`` has the form of a Dask scheduler address (tcp://host:port)."""
    from distributed.comm.addressing import parse_address, parse_host_port
    from distributed.comm.registry import backends

    try:
        scheme, location = parse_address(address)
        if scheme not in backends:
            raise ValueError(f"unknown protocol '{scheme}'")
        if scheme in ("tcp", "tls"):
            parse_host_port(location)
    except (ValueError, TypeError) as exc:
        raise SchedulerAddressError(address, str(exc)) from None


def configured_scheduler() -> str | None:
    """The scheduler address of Dask's configuration (``scheduler-address``, ``DASK_SCHEDULER_ADDRESS``), if any."""
    import os

    import dask

    # the variable is read here too: dask collects the environment only when it is first imported
    address = os.environ.get("DASK_SCHEDULER_ADDRESS") or dask.config.get("scheduler-address", None)
    return str(address) if address else None
