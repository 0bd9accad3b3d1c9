"""Spare point children: started before the payload exists, taken by the next runners of the same limits.

`cosim sweep` on a local cluster starts one child per worker as its first act, sends them the payload as soon
as it is made, and the workers (in the same process) take them instead of starting their own: a child's start
and the system's load then overlap the client's imports and spec check (cosim.parallel.isolation).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import psutil
import pytest

from cosim.parallel.isolation import children
from cosim.parallel.isolation.children import preload_spare_children, stop_spare_children
from cosim.parallel.isolation.payload import make_payload
from cosim.parallel.isolation.runner import IsolatedRunner, start_spare_children
from cosim.system.validate import check_spec

UNIT = """
import os
from cosim import PythonUnit, Variable

class Pid(PythonUnit):
    variables = (Variable("k", "parameter", start=1.0), Variable("pid", "output", start=0.0),
                 Variable("y", "output", start=0.0))

    def do_step(self, t, h):
        self.pid = float(os.getpid())
        self.y = 2.0 * self.k
"""


def payload_of(tmp_path: Path, name: str = "pid") -> dict:
    (tmp_path / "pid_unit.py").write_text(UNIT)
    spec = {"name": name, "units": {"u": {"python": "pid_unit.py:Pid"}}, "experiment": {"stop": 0.1, "step": 0.1},
            "objectives": {"y": {"signal": "u.y", "reduce": "final"}, "pid": {"signal": "u.pid", "reduce": "final"}},
            "design": {"parameters": {"u.k": {"values": [1.0, 2.0]}}}}
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(spec))
    return make_payload(check_spec(path))


@pytest.fixture(autouse=True)
def no_spares_left():
    yield
    stop_spare_children()


def spare_pids() -> list[int]:
    return [spare._proc.pid for spare in children.SPARES]


def test_a_runner_takes_a_spare_child_and_runs_its_points_there(tmp_path):
    start_spare_children(2)
    pids = spare_pids()
    runner = IsolatedRunner(payload_of(tmp_path))
    try:
        rows = runner.run([("a", {"u.k": 1.5}), ("b", {"u.k": -3.0})])
    finally:
        runner.close()
    assert [r.objectives["y"] for r in rows] == [3.0, -6.0]
    assert rows[0].objectives["pid"] == rows[1].objectives["pid"] == float(pids[0])  # the first spare
    assert spare_pids() == pids[1:]  # the other one still waits


def test_a_preloaded_spare_serves_its_payload_only(tmp_path):
    start_spare_children(1)
    [pid] = spare_pids()
    first, other = payload_of(tmp_path, "first"), payload_of(tmp_path, "other")
    assert first["key"] != other["key"]
    preload_spare_children(first)
    stranger = IsolatedRunner(other)  # another payload: starts its own child, leaves the loading spare alone
    owner = IsolatedRunner(first)
    try:
        [row] = stranger.run([("x", {"u.k": 1.0})])
        assert row.objectives["pid"] != pid and spare_pids() == [pid]
        [row] = owner.run([("y", {"u.k": 4.0})])
        assert row.objectives == {"y": 8.0, "pid": float(pid)} and spare_pids() == []
    finally:
        stranger.close()
        owner.close()


def test_a_spare_started_under_other_limits_is_not_taken(tmp_path, monkeypatch):
    start_spare_children(1)
    [pid] = spare_pids()
    monkeypatch.setenv("COSIM_CHILD_POINTS", "1")  # the payload made now carries other limits than the spare's
    runner = IsolatedRunner(payload_of(tmp_path))
    try:
        rows = runner.run([("a", {"u.k": 1.0}), ("b", {"u.k": 2.0})])
    finally:
        runner.close()
    used = {r.objectives["pid"] for r in rows}
    assert len(used) == 2 and float(pid) not in used  # a child per point (the limit), none of them the spare
    assert spare_pids() == [pid]


def test_stopping_the_spares_ends_their_processes_and_removes_their_folders():
    start_spare_children(2)
    processes = [psutil.Process(pid) for pid in spare_pids()]
    folders = [Path(spare._folder) for spare in children.SPARES]
    assert all(folder.is_dir() for folder in folders)
    stop_spare_children()
    gone, alive = psutil.wait_procs(processes, timeout=5)
    assert not alive and not children.SPARES
    assert not any(folder.exists() for folder in folders)


def test_a_sweep_refused_after_starting_its_spares_leaves_no_child_and_no_folder(tmp_path, write_spec):
    spec = write_spec({"units": {"u": {"python": "nowhere.py:Missing"}}, "experiment": {"stop": 0.1, "step": 0.1},
                       "design": {"parameters": {"u.k": {"values": [1.0]}}}})
    temp = tmp_path / "tmp"
    temp.mkdir()
    done = subprocess.run([sys.executable, "-m", "cosim.cli.main", "sweep", str(spec), "--out", str(tmp_path / "o")],
                          capture_output=True, text=True, env={**__import__("os").environ, "TMPDIR": str(temp)})
    assert done.returncode == 2, done.stderr
    assert "nowhere.py" in done.stderr and "Traceback" not in done.stderr
    assert not list(temp.glob("cosim_worker_*"))  # the spares' folders: removed with the spares


def test_a_spare_whose_parent_ends_before_its_payload_ends_quietly(capfd):
    """A sweep refused for its spec's problems ends before its spares get a payload: their channel closes,
    and they end without a traceback on the terminal after the problems (exit 0)."""
    start_spare_children(1)
    [spare] = children.SPARES
    capfd.readouterr()
    spare._outbox.close()  # what the parent's exit does to the child's end of the channel
    assert spare._proc.wait(timeout=60) == 0
    assert capfd.readouterr().err == ""
