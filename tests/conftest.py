"""Shared fixtures: real FMUs built from the project's C sources, spec writers, Dask clusters and processes.

Plain helper functions and paths are in tests/helpers/ (imported by name)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers.paths import REPO
from tests.helpers.sweep_fixtures import free_port, kill_group, wait_for_workers, worker_process_cluster
from tests.helpers.tools import require_tool


@pytest.fixture(scope="session")
def built_fmu():
    """A function (name, fmi_version) -> path of the FMU built from fmus/<name> (cached)."""
    from cosim.fmus.build import ensure_built

    return lambda name, version: Path(ensure_built(name, version))


@pytest.fixture
def write_spec(tmp_path):
    """A function (dict, name='spec.json') -> path of the spec written into a fresh folder."""

    def write(content: dict, name: str = "spec.json") -> Path:
        path = tmp_path / name
        path.write_text(json.dumps(content, indent=2))
        return path

    return write


@pytest.fixture
def panda_viewer():
    """The Panda trace viewer, registered as its entry point in pyproject.toml names it (as an install does)."""
    import importlib
    import re

    from cosim.analysis.viewers import register_viewer, unregister_viewer

    text = (REPO / "pyproject.toml").read_text()
    module, _, name = re.search(r'^panda = "([^"]+)"', text, re.M).group(1).partition(":")
    viewer = register_viewer(getattr(importlib.import_module(module), name))
    yield viewer
    unregister_viewer(viewer.name)


# -- Dask clusters and processes shared by the sweep, study and room tests (helpers in sweep_fixtures.py) --------


@pytest.fixture(scope="module")
def local_cluster():
    """A real distributed.LocalCluster: 2 worker processes, 1 thread each, on 127.0.0.1."""
    from distributed import LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address="127.0.0.1:0", silence_logs=40)
    yield cluster.scheduler_address
    cluster.close()


@pytest.fixture
def worker_processes():
    """A fresh worker_process_cluster for one test."""
    with worker_process_cluster() as address:
        yield address


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


@pytest.fixture(autouse=True)
def _native_runs_twinned_on_the_python_master(request, monkeypatch):
    """In the modules of kernel_twins.TWIN_MODULES every run on the native kernel is repeated on the Python
    master and must give the same bits (kernel_twins.py)."""
    from tests.helpers import kernel_twins

    if request.module.__name__.rsplit(".", 1)[-1] in kernel_twins.TWIN_MODULES:
        from cosim.execution.run import Execution

        monkeypatch.setattr(Execution, "run", kernel_twins.twinned_run(Execution.run, request.node.nodeid))
    yield


def pytest_terminal_summary(terminalreporter):
    from tests.helpers import kernel_twins

    if kernel_twins.compared:
        terminalreporter.write_line(f"native kernel: {len(kernel_twins.compared)} runs of "
                                    f"{len(set(kernel_twins.compared))} tests repeated on the Python master, equal")


# -- the browser of the decision room and dashboard tests ----------------------------------------------------


@pytest.fixture(scope="module")
def browser():
    """Debian's chromium driven by selenium (chromium-driver), one a module; a missing one fails under CI=true."""
    from cosim.analysis.room import browser as B

    require_tool("chromium", "chromium")
    require_tool("chromedriver", "chromium-driver")
    try:
        import selenium  # noqa: F401
    except ImportError:
        if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
            pytest.fail("selenium is not installed (the test extra of pyproject.toml); CI=true, so this test "
                        "must run")
        pytest.skip("selenium is not installed (pip install -e .[test])")
    driver = B.chromium()
    yield driver
    driver.quit()


@pytest.fixture
def no_console_errors(request):
    """Every test that drives the browser ends with no error in chromium's console (an uncaught exception in
    bokeh's scripts, a failed request): the page may look right and still have failed to draw a view.
    A module asks for it with ``pytestmark = pytest.mark.usefixtures("no_console_errors")``."""
    from cosim.analysis.room import browser as B

    if "browser" not in request.fixturenames:
        yield
        return
    driver = request.getfixturevalue("browser")
    B.console_errors(driver)  # a previous test's, reported there
    yield
    assert B.console_errors(driver) == []
