"""A results folder that cannot be written (read-only, full, also during the final merge), and a sweep
stopped by Ctrl-C or kill: a clear message, exit code 2 (130 when stopped), no traceback, and nothing lost:
--resume afterwards gives the exact table."""

from __future__ import annotations

import contextlib
import os
import resource
import signal
import subprocess
import sys
import time

import pytest

from cosim.errors import OutputError
from cosim.studies.sweep import Sweep
from tests.helpers.paths import REPO
from tests.helpers.triple_study import assert_triples_exact, read_only_folder, run_cosim, triple_spec


def test_a_read_only_out_folder_is_a_clear_message(tmp_path):
    spec = triple_spec(tmp_path, 4)
    with read_only_folder(tmp_path / "ro") as folder:
        done = run_cosim("sweep", str(spec), "--out", str(folder / "results"), "--workers", "1")
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
    spec = triple_spec(tmp_path, 300)
    out = tmp_path / "out"
    with _largest_file(9000), pytest.raises(OutputError, match="cannot write the results into .*File too large"):
        Sweep(spec, out=out, scheduler=local_cluster, batch_size=1, quiet=True).run_to_disk()
    assert list((out / "parts").glob("part-*.parquet")) and not (out / "results.parquet").exists()
    assert not list(out.glob("*.tmp"))
    table = Sweep(spec, out=out, scheduler=local_cluster, resume=True, quiet=True).run()
    assert_triples_exact(table, 300)


@pytest.mark.skipif(os.geteuid() != 0, reason="mounting a small tmpfs needs root; the RLIMIT test above "
                                              "covers the same code path unprivileged")
def test_a_full_filesystem_mid_sweep_then_resume_after_freeing_space(tmp_path):
    spec = triple_spec(tmp_path, 200)
    disk = tmp_path / "disk"
    disk.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=96k", "tmpfs", str(disk)], check=True)
    try:
        done = run_cosim("sweep", str(spec), "--out", str(disk / "out"), "--workers", "2", "--batch-size", "1")
        assert done.returncode == 2, done.stderr
        assert "No space left on device" in done.stderr and "Traceback" not in done.stderr
        subprocess.run(["mount", "-o", "remount,size=8m", str(disk)], check=True)  # space freed
        done = run_cosim("sweep", str(spec), "--out", str(disk / "out"), "--workers", "2", "--resume")
        assert done.returncode == 0, done.stderr
        import pandas as pd

        assert_triples_exact(pd.read_parquet(disk / "out" / "results.parquet"), 200)
    finally:
        subprocess.run(["umount", str(disk)], check=True)


@pytest.mark.parametrize("how", ["ctrl-c", "kill"])
def test_ctrl_c_and_kill_print_no_traceback_and_resume_is_exact(tmp_path, how):
    spec = triple_spec(tmp_path, 40, pause=0.05)
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
    done = run_cosim("sweep", str(spec), "--out", str(out), "--workers", "2", "--resume")
    assert done.returncode == 0, done.stderr
    import pandas as pd

    assert_triples_exact(pd.read_parquet(out / "results.parquet"), 40)
