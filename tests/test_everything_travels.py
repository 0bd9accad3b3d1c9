"""Everything a point needs travels with it: workers in another folder, with another HOME, without the spec's folder.

Real `dask scheduler` / `dask worker` processes started in a temporary folder
(their working directory and HOME), with only cosim on their PYTHONPATH; the
spec's folder is moved away after the sweep is prepared, so nothing can be read
from it by path. The spec uses a Python unit named by *module* from the spec's
folder (shipped as source) and a player of a CSV table.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from orchestrator.sweep import Sweep

from .sweep_fixtures import free_port, kill_group

ROOT = Path(__file__).resolve().parent.parent

UNIT_SOURCE = '''
from orchestrator import PythonUnit, Variable


class Scale(PythonUnit):
    """y = k * u, u from the player."""

    variables = (Variable("k", "parameter", start=1.0), Variable("u", "input", start=0.0),
                 Variable("y", "output", start=0.0))
    feedthrough = {"y": ["u"]}

    def compute_outputs(self):
        self.y = self.k * self.u

    def do_step(self, t, h):
        self.compute_outputs()
'''


@pytest.fixture
def foreign_workers(tmp_path_factory):
    """A scheduler and two workers whose cwd and HOME are a fresh folder and whose PYTHONPATH is cosim only."""
    home = tmp_path_factory.mktemp("foreign_home")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "HOME", "PWD")}
    env.update(HOME=str(home), PYTHONPATH=str(ROOT))
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    scheduler = subprocess.Popen(dask + ["--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], cwd=home,
                                 env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    workers = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nworkers", "2",
                                "--nthreads", "1", "--no-dashboard", "--host", "127.0.0.1"], cwd=home, env=env,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        from distributed import Client

        deadline = time.monotonic() + 90
        while True:
            try:
                with Client(address, timeout=5) as client:
                    client.wait_for_workers(2, timeout=max(1, deadline - time.monotonic()))
                    homes = set(client.run(lambda: os.environ["HOME"] + "|" + os.getcwd()).values())
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)
        assert homes == {f"{home}|{home}"}
        yield address
    finally:
        kill_group(workers)
        kill_group(scheduler)


def test_module_unit_and_played_table_travel_to_foreign_workers(tmp_path, foreign_workers):
    folder = tmp_path / "project"
    folder.mkdir()
    (folder / "my_scaling_units.py").write_text(UNIT_SOURCE)
    (folder / "drive.csv").write_text("time,u\n0,1.0\n0.5,2.0\n1.0,3.0\n")
    spec = {
        "name": "travels",
        "units": {"play": {"player": "drive.csv"},
                  "scale": {"python": "my_scaling_units:Scale"}},
        "connections": [{"from": "play.u", "to": "scale.u"}],
        "experiment": {"stop": 1.0, "step": 0.5},
        "objectives": {"y_end": {"signal": "scale.y", "reduce": "final"},
                       "y_sum": {"signal": "scale.y", "reduce": "mean"}},
        "design": {"parameters": {"scale.k": {"values": [1.0, 2.0, 5.0]}}},
    }
    import json

    (folder / "spec.json").write_text(json.dumps(spec))
    sweep = Sweep(folder / "spec.json", out=tmp_path / "out", scheduler=foreign_workers, quiet=True)
    shutil.move(folder, tmp_path / "moved_away")  # nothing of the spec's folder is there any more
    sys.modules.pop("my_scaling_units", None)
    df = sweep.run()
    assert (df["status"] == "ok").all(), list(df["message"])
    assert list(df["y_end"]) == [3.0, 6.0, 15.0]
    assert list(df["y_sum"]) == [2.0, 4.0, 10.0]
