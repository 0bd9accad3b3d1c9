"""A results folder that cannot be written (read-only, full, also during the final merge), and a sweep
stopped by Ctrl-C or kill: a clear message, exit code 2 (130 when stopped), no traceback, and nothing lost:
--resume afterwards gives the exact table."""

from __future__ import annotations

import contextlib
import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cosim.errors import OutputError
from cosim.studies.sweep import Sweep
from tests.helpers.paths import REPO

UNIT = """
import time
from cosim import PythonUnit, Variable

class Triple(PythonUnit):
    variables = (Variable("k", "parameter", start=1.0), Variable("pause", "parameter", start=0.0),
                 Variable("y", "output", start=0.0))

    def do_step(self, t, h):
        time.sleep(self.pause)
        self.y = 3.0 * self.k
"""


def _spec(folder: Path, points: int, pause: float = 0.0) -> Path:
    (folder / "triple.py").write_text(UNIT)
    spec = {"units": {"s": {"python": "triple.py:Triple", "parameters": {"pause": pause}}},
            "experiment": {"stop": 0.1, "step": 0.1}, "objectives": {"y": {"signal": "s.y", "reduce": "final"}},
            "design": {"parameters": {"s.k": {"min": 1, "max": points, "step": 1}}}}
    path = folder / "spec.json"
    path.write_text(json.dumps(spec))
    return path


def _exact(table, points: int) -> None:
    """Every point once, in design order, with the value computed independently (y = 3 k)."""
    assert list(table["s.k"]) == list(range(1, points + 1))
    assert list(table["y"]) == [3.0 * k for k in range(1, points + 1)]
    assert set(table["status"]) == {"ok"}


def _cosim(*args: str, timeout: float = 180, **popen) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cosim.cli.main", *args], capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=str(REPO / "src")), timeout=timeout, **popen)


@contextlib.contextmanager
def _read_only_folder(folder: Path):
    """A real read-only folder: a read-only tmpfs when we are root (root ignores permissions), else mode 555."""
    folder.mkdir()
    if os.geteuid() == 0:
        subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(folder)], check=True)
        try:
            yield folder
        finally:
            subprocess.run(["umount", str(folder)], check=True)
    else:
        folder.chmod(0o555)
        try:
            yield folder
        finally:
            folder.chmod(0o755)


def test_a_read_only_out_folder_is_a_clear_message(tmp_path):
    spec = _spec(tmp_path, 4)
    with _read_only_folder(tmp_path / "ro") as folder:
        done = _cosim("sweep", str(spec), "--out", str(folder / "results"), "--workers", "1")
    assert done.returncode == 2, done.stderr
    assert f"cannot write the results into {folder / 'results'}" in done.stderr
    assert ("Read-only file system" in done.stderr or "Permission denied" in done.stderr)
    # nothing could be written, so there is nothing to resume: the fix is to run the same command again
    assert "then run the same command again" in done.stderr and "--resume" not in done.stderr
    assert "Traceback" not in done.stderr


@contextlib.contextmanager
def _largest_file(size: int):
    """Files this process writes may not exceed ``size`` bytes (EFBIG, as from a full disk)."""
    old_limit = resource.getrlimit(resource.RLIMIT_FSIZE)
    old_handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write fails instead of killing us
    resource.setrlimit(resource.RLIMIT_FSIZE, (size, old_limit[1]))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, old_limit)
        signal.signal(signal.SIGXFSZ, old_handler)


def test_a_write_failing_during_the_final_merge_loses_nothing(tmp_path, local_cluster):
    """Parts (a few kB each) fit, the merged table (about 13 kB) does not: the merge fails cleanly,
    the parts stay, and a resume once writing works again gives the exact table."""
    spec = _spec(tmp_path, 300)
    out = tmp_path / "out"
    with _largest_file(9000), pytest.raises(OutputError, match="cannot write the results into .*File too large"):
        Sweep(spec, out=out, scheduler=local_cluster, batch_size=1, quiet=True).run_to_disk()
    assert list((out / "parts").glob("part-*.parquet")) and not (out / "results.parquet").exists()
    assert not list(out.glob("*.tmp"))
    table = Sweep(spec, out=out, scheduler=local_cluster, resume=True, quiet=True).run()
    _exact(table, 300)


@pytest.mark.skipif(os.geteuid() != 0, reason="mounting a small tmpfs needs root; the RLIMIT test above "
                                              "covers the same code path unprivileged")
def test_a_full_filesystem_mid_sweep_then_resume_after_freeing_space(tmp_path):
    spec = _spec(tmp_path, 200)
    disk = tmp_path / "disk"
    disk.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=96k", "tmpfs", str(disk)], check=True)
    try:
        done = _cosim("sweep", str(spec), "--out", str(disk / "out"), "--workers", "2", "--batch-size", "1")
        assert done.returncode == 2, done.stderr
        assert "No space left on device" in done.stderr and "Traceback" not in done.stderr
        subprocess.run(["mount", "-o", "remount,size=8m", str(disk)], check=True)  # space freed
        done = _cosim("sweep", str(spec), "--out", str(disk / "out"), "--workers", "2", "--resume")
        assert done.returncode == 0, done.stderr
        import pandas as pd

        _exact(pd.read_parquet(disk / "out" / "results.parquet"), 200)
    finally:
        subprocess.run(["umount", str(disk)], check=True)


@pytest.mark.parametrize("how", ["ctrl-c", "kill"])
def test_ctrl_c_and_kill_print_no_traceback_and_resume_is_exact(tmp_path, how):
    spec = _spec(tmp_path, 40, pause=0.05)
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "cosim.cli.main", "sweep", str(spec), "--out", str(out),
                             "--workers", "2", "--batch-size", "2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=dict(os.environ, PYTHONPATH=str(REPO / "src")), start_new_session=True)
    deadline = time.monotonic() + 120
    while not list((out / "parts").glob("part-*.parquet")) and time.monotonic() < deadline:
        time.sleep(0.2)  # stop it once some rows are written
    if how == "ctrl-c":
        os.killpg(proc.pid, signal.SIGINT)  # a terminal's Ctrl-C reaches the whole process group
    else:
        proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "cosim: interrupted" in err and "Traceback" not in err and "Error" not in err, err
    done = _cosim("sweep", str(spec), "--out", str(out), "--workers", "2", "--resume")
    assert done.returncode == 0, done.stderr
    import pandas as pd

    _exact(pd.read_parquet(out / "results.parquet"), 40)
