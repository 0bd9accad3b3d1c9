"""The ``cosim_worker_*`` folders of a killed cosim are removed at the next start, and nobody else's (issue 38.8).

Real folders in a TMPDIR of the test's own: one left by a process that is gone (removed), one of a process that
still runs, one without cosim's marker, one with a marker that is not ours and a symbolic link named like
ours (all kept); then a real sweep started with that TMPDIR removes the dead one when its first point child
starts.
"""

from __future__ import annotations

import os
import subprocess
import sys

from cosim.parallel.isolation.leftovers import MARKER, mark, remove_leftovers, start_time
from tests.helpers.paths import REPO
from tests.helpers.triple_study import assert_triples_exact, triple_spec


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def _folders(tmp):
    """(folder: expected to be removed) in ``tmp``."""
    dead = tmp / "cosim_worker_dead"
    dead.mkdir()
    (dead / MARKER).write_text(f"cosim worker folder of {_dead_pid()} 12345\n")
    (dead / "payload.bin").write_bytes(b"x" * 1000)
    alive = tmp / "cosim_worker_alive"
    alive.mkdir()
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    (alive / MARKER).write_text(f"cosim worker folder of {sleeper.pid} {start_time(sleeper.pid)}\n")
    unmarked = tmp / "cosim_worker_someone_elses"
    unmarked.mkdir()
    (unmarked / "keep.txt").write_text("not cosim's")
    foreign = tmp / "cosim_worker_foreign"
    foreign.mkdir()
    (foreign / MARKER).write_text("something else entirely\n")
    precious = tmp / "precious"
    precious.mkdir()
    (precious / MARKER).write_text(f"cosim worker folder of {_dead_pid()} 1\n")
    (tmp / "cosim_worker_link").symlink_to(precious)
    return sleeper, {dead: True, alive: False, unmarked: False, foreign: False, precious: False,
                     tmp / "cosim_worker_link": False}


def test_only_folders_of_owners_that_are_gone_are_removed(tmp_path):
    sleeper, expected = _folders(tmp_path)
    try:
        assert remove_leftovers(tmp_path) == [tmp_path / "cosim_worker_dead"]
        assert {f: not f.exists() for f in expected} == expected
        mine = tmp_path / "cosim_worker_mine"
        mine.mkdir()
        mark(mine)
        assert remove_leftovers(tmp_path) == [] and mine.exists()  # this process runs: its folder stays
    finally:
        sleeper.kill()
        sleeper.wait()


def test_a_sweep_removes_the_leftovers_of_a_killed_one_when_it_starts(tmp_path):
    sleeper, expected = _folders(tmp_path)
    try:
        spec = triple_spec(tmp_path, 4)
        done = subprocess.run([sys.executable, "-m", "cosim.cli.main", "sweep", str(spec), "--out",
                               str(tmp_path / "out"), "--workers", "1"], capture_output=True, text=True, timeout=300,
                              env=dict(os.environ, TMPDIR=str(tmp_path), PYTHONPATH=str(REPO / "src")))
        assert done.returncode == 0, done.stderr
        import pandas as pd

        assert_triples_exact(pd.read_parquet(tmp_path / "out" / "results.parquet"), 4)
        assert {f: not f.exists() for f in expected} == expected
        assert not [p for p in tmp_path.glob("cosim_worker_*") if p not in expected]  # its own removed too
    finally:
        sleeper.kill()
        sleeper.wait()
