"""Fixtures for the sweep tests: a real LocalCluster, real `dask scheduler` / `dask worker` processes."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Iterator

import pytest


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


@pytest.fixture(scope="module")
def local_cluster():
    """A real distributed.LocalCluster: 2 worker processes, 1 thread each, on 127.0.0.1."""
    from distributed import LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address="127.0.0.1:0", silence_logs=40)
    yield cluster.scheduler_address
    cluster.close()


@contextlib.contextmanager
def worker_process_cluster() -> Iterator[str]:
    """The address of a fresh distributed.LocalCluster of 2 worker processes (1 thread each, 127.0.0.1) whose
    scheduler lets a task lose one worker, as on the clusters cosim starts: for tests that kill a worker
    process (cosim's own local cluster runs its workers in the client's process, cosim.parallel.evaluator).
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


@pytest.fixture
def worker_processes():
    """A fresh worker_process_cluster for one test."""
    with worker_process_cluster() as address:
        yield address


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


@pytest.fixture(scope="module")
def dask_processes(tmp_path_factory):
    """`dask scheduler` and `dask worker` (2 processes) started as commands, workers in their own folder.

    Yields (scheduler address, worker folder).
    """
    # `python -m dask` of this interpreter, not whatever `dask` is first on PATH: scheduler, workers and the
    # client must be the same dask version (the minimum-versions run has another dask on PATH)
    dask = [sys.executable, "-m", "dask"]
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    worker_dir = tmp_path_factory.mktemp("worker_cwd")
    scheduler = subprocess.Popen([*dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    workers = subprocess.Popen([*dask, "worker", address, "--nworkers", "2", "--nthreads", "1", "--no-dashboard",
                                "--host", "127.0.0.1", "--local-directory", str(worker_dir)],
                               cwd=worker_dir, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               start_new_session=True)
    try:
        wait_for_workers(address, 2, seconds=60)
        yield address, Path(worker_dir)
    finally:
        kill_group(workers)
        kill_group(scheduler)
