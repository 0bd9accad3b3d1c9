"""Issue 28.15: a finished study leaves no `.cosim.lock` in its folder, and the lock still admits one holder.

The lock file is removed by its holder on release; a lock taken on a file that was removed meanwhile does not
count (see cosim.results.lock).  Real processes contend for one folder many times over: at no moment do two
hold it, which a marker file created exclusively inside the critical section would show.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

from cosim.results.lock import LOCK_NAME, FolderLock
from tests.helpers.paths import REPO
from tests.studies.test_hostile_sweeps import _scale_spec


def _cosim(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cosim.cli.main", *args], capture_output=True, text=True,
                          timeout=300, env=dict(os.environ, PYTHONPATH=str(REPO / "src")))


def test_a_finished_sweep_and_optimisation_leave_no_lock_file(tmp_path):
    spec = _scale_spec(tmp_path, 2.0)
    done = _cosim("sweep", str(spec), "--out", str(tmp_path / "s"), "--workers", "1")
    assert done.returncode == 0, done.stderr
    assert not (tmp_path / "s" / LOCK_NAME).exists()
    assert (tmp_path / "s" / "results.parquet").exists()
    # a resume takes the folder again and leaves it as clean
    done = _cosim("sweep", str(spec), "--out", str(tmp_path / "s"), "--workers", "1", "--resume")
    assert done.returncode == 0 and not (tmp_path / "s" / LOCK_NAME).exists(), done.stderr


def test_a_killed_holder_leaves_the_file_unlocked_and_the_next_study_removes_it(tmp_path):
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import time
        from cosim.results.lock import FolderLock
        lock = FolderLock({str(tmp_path)!r})
        lock.acquire("cosim sweep")
        print("locked", flush=True)
        time.sleep(600)
    """)], stdout=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONPATH=str(REPO / "src")))
    assert holder.stdout.readline().strip() == "locked"
    holder.send_signal(signal.SIGKILL)
    holder.wait(timeout=10)
    assert (tmp_path / LOCK_NAME).exists()  # kill -9: nobody could remove it, but the kernel released the lock
    lock = FolderLock(tmp_path)
    lock.acquire()
    lock.release()
    assert not (tmp_path / LOCK_NAME).exists()


CONTENDER = """
import os, sys, time
from cosim.errors import FolderInUse
from cosim.results.lock import FolderLock

folder, marker = sys.argv[1], os.path.join(sys.argv[1], "inside")
held, deadline = 0, time.monotonic() + float(sys.argv[2])
while time.monotonic() < deadline:
    lock = FolderLock(folder)
    try:
        lock.acquire()
    except FolderInUse:
        continue
    fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)  # FileExistsError: two holders at once
    os.close(fd)
    os.unlink(marker)
    lock.release()
    held += 1
print(held)
"""


def test_removing_the_file_on_release_keeps_one_holder_at_a_time(tmp_path):
    script = tmp_path / "contend.py"
    script.write_text(CONTENDER)
    folder = tmp_path / "folder"
    folder.mkdir()
    procs = [subprocess.Popen([sys.executable, str(script), str(folder), "3"], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONPATH=str(REPO / "src")))
             for _ in range(4)]
    results = [p.communicate(timeout=120) for p in procs]
    for proc, (out, err) in zip(procs, results):
        assert proc.returncode == 0, err  # no FileExistsError: never two holders
    held = [int(out) for out, _ in results]
    assert sum(held) > 100 and all(h > 0 for h in held), held  # they really contended, each got its turns
    assert not (folder / LOCK_NAME).exists() and not (folder / "inside").exists()
