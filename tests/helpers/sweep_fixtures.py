"""Helpers for the sweep tests: real Dask clusters and processes (the fixtures that use them are in conftest.py)."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import time
from typing import Iterator


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def kill_group(proc: subprocess.Popen) -> None:
    """SIGKILL a process started with start_new_session=True and everything it started."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait(timeout=10)


@contextlib.contextmanager
def worker_process_cluster() -> Iterator[str]:
    """The address of a fresh distributed.LocalCluster of 2 worker processes (1 thread each, 127.0.0.1) whose
    scheduler lets a task lose one worker, as on the clusters cosim starts: for tests that kill a worker
    process (cosim's own local cluster runs its workers in the client's process, cosim.parallel.cluster.client).
    The workers get this process's environment as it is now."""
    import dask
    from distributed import LocalCluster

    with dask.config.set({"distributed.scheduler.allowed-failures": 1}):
        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address="127.0.0.1:0", silence_logs=40)
    try:
        yield cluster.scheduler_address
    finally:
        cluster.close()


def wait_for_workers(address: str, count: int, seconds: float) -> None:
    """Block until the scheduler at ``address`` has ``count`` workers; retries while it is still starting,
    raises OSError/TimeoutError after ``seconds``."""
    from distributed import Client

    deadline = time.monotonic() + seconds
    while True:
        try:
            with Client(address, timeout=5) as client:
                client.wait_for_workers(count, timeout=max(1, deadline - time.monotonic()))
            return
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.5)
