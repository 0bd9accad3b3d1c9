"""Careless use of sweeps: changed units on resume, two sweeps on one folder, units that exit or hang
at import, nonsense timeouts."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
import zipfile
from pathlib import Path

import pytest

from cosim.results.lock import FolderInUse, FolderLock
from cosim.studies.sweep import Sweep, SweepError
from tests.helpers.paths import REPO

SCALE_UNIT = """
from cosim import PythonUnit, Variable

class Scale(PythonUnit):
    variables = (Variable("k", "parameter", start=1.0), Variable("y", "output", start=0.0))

    def do_step(self, t, h):
        self.y = {factor} * self.k
"""


def _cosim(*args: str, env: dict | None = None, timeout: float = 120, cwd: Path | None = None):
    full_env = dict(os.environ, PYTHONPATH=str(REPO), **(env or {}))
    return subprocess.run([sys.executable, "-m", "cosim.cli.main", *args], capture_output=True, text=True,
                          env=full_env, timeout=timeout, cwd=cwd)


def _scale_spec(tmp_path: Path, factor: float) -> Path:
    (tmp_path / "scale.py").write_text(SCALE_UNIT.format(factor=factor))
    spec = {"units": {"s": {"python": "scale.py:Scale"}}, "experiment": {"stop": 0.2, "step": 0.1},
            "objectives": {"y": {"signal": "s.y", "reduce": "final"}},
            "design": {"parameters": {"s.k": {"values": [1.0, 2.0, 3.0, 4.0]}}}}
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(spec))
    return path


def test_resume_refuses_a_changed_python_unit_file_and_recompute_runs_all_again(tmp_path, local_cluster):
    spec = _scale_spec(tmp_path, 10.0)
    out = tmp_path / "out"
    first = Sweep(spec, out=out, scheduler=local_cluster, quiet=True).run()
    assert sorted(first["y"]) == [10.0, 20.0, 30.0, 40.0]
    meta = json.loads((out / "metadata.json").read_text())
    assert set(meta["unit_checksums"]) == {"s"}
    Sweep(spec, out=out, scheduler=local_cluster, resume=True, quiet=True)  # unchanged: accepted
    _scale_spec(tmp_path, 100.0)  # same spec text, another model
    with pytest.raises(SweepError, match=r"holds results of other unit files .*unit 's': .*would mix two models"):
        Sweep(spec, out=out, scheduler=local_cluster, resume=True, quiet=True)
    again = Sweep(spec, out=out, scheduler=local_cluster, resume=True, recompute=True, quiet=True).run()
    assert sorted(again["y"]) == [100.0, 200.0, 300.0, 400.0] and len(again) == 4


def test_resume_refuses_a_changed_fmu_through_the_command_line(tmp_path, built_fmu, local_cluster):
    fmu = tmp_path / "model.fmu"
    fmu.write_bytes(built_fmu("linear_ode", 3).read_bytes())
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"units": {"o": {"fmu": "model.fmu"}}, "experiment": {"stop": 0.2, "step": 0.1},
                                "objectives": {"y": {"signal": "o.y", "reduce": "final"}},
                                "design": {"parameters": {"o.a": {"values": [-1.0, -2.0]}}}}))
    out = tmp_path / "out"
    done = _cosim("sweep", str(spec), "--out", str(out), "--scheduler", local_cluster)
    assert done.returncode == 0, done.stderr
    with zipfile.ZipFile(fmu, "a") as zf:  # re-exported in place: same spec, different bytes
        zf.writestr("resources/note.txt", "rebuilt")
    done = _cosim("sweep", str(spec), "--out", str(out), "--scheduler", local_cluster, "--resume")
    assert done.returncode == 2 and "unit 'o'" in done.stderr and "--recompute" in done.stderr
    assert "Traceback" not in done.stderr


def test_a_second_sweep_on_the_same_folder_sees_the_lock(tmp_path):
    spec = _scale_spec(tmp_path, 1.0)
    out = tmp_path / "out"
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import sys, time
        from cosim.results.lock import FolderLock
        lock = FolderLock({str(out)!r})
        lock.acquire()
        print("locked", flush=True)
        time.sleep(600)
    """)], stdout=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONPATH=str(REPO)))
    try:
        assert holder.stdout.readline().strip() == "locked"
        done = _cosim("sweep", str(spec), "--out", str(out), "--workers", "1")
        assert done.returncode == 2, done.stderr
        assert f"is in use by another cosim sweep (pid {holder.pid}" in done.stderr
        with pytest.raises(FolderInUse):
            FolderLock(out).acquire()
    finally:
        holder.send_signal(signal.SIGKILL)  # a killed holder leaves nothing stuck
        holder.wait(timeout=10)
    lock = FolderLock(out)
    lock.acquire()
    lock.release()


def test_a_running_sweep_holds_the_lock_and_releases_it(tmp_path, local_cluster):
    spec = _scale_spec(tmp_path, 1.0)
    out = tmp_path / "out"
    sweep = Sweep(spec, out=out, scheduler=local_cluster, quiet=True)
    sweep.folder.lock.acquire()  # as run() does, before the cluster starts
    with pytest.raises(FolderInUse, match="in use by another cosim sweep"):
        Sweep(spec, out=out, scheduler=local_cluster, resume=True, quiet=True)
    sweep.folder.lock.release()
    assert len(sweep.run()) == 4
    Sweep(spec, out=out, scheduler=local_cluster, resume=True, quiet=True)  # released after the run


@pytest.mark.parametrize("body, expected", [
    ("import sys\nsys.exit(0)\n", "called sys.exit(0) while being imported"),
    ("raise SystemExit('bye')\n", "called sys.exit('bye') while being imported"),
    ("import time\ntime.sleep(3600)\n", "took longer than 2 s"),
    ("while True:\n    pass\n", "took longer than 2 s"),
])
def test_a_unit_module_that_exits_or_hangs_at_import_is_reported_by_validate(tmp_path, body, expected):
    (tmp_path / "bad.py").write_text(body + SCALE_UNIT.format(factor=1.0))
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"units": {"s": {"python": "bad.py:Scale"}}, "experiment": {"stop": 0.2, "step": 0.1}}))
    started = time.monotonic()
    done = _cosim("validate", str(spec), env={"COSIM_IMPORT_SECONDS": "2"}, timeout=60)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert "$.units.s.python" in done.stderr and expected in done.stderr and "Traceback" not in done.stderr
    assert time.monotonic() - started < 50  # did not wait for the sleep


def test_a_module_unit_that_exits_at_import_is_reported(tmp_path):
    (tmp_path / "exiting_module.py").write_text("import sys\nsys.exit(3)\n")
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"units": {"s": {"python": "exiting_module:Scale"}},
                                "experiment": {"stop": 0.2, "step": 0.1}}))
    done = _cosim("validate", str(spec), timeout=60)
    assert done.returncode == 2 and "module 'exiting_module' called sys.exit(3)" in done.stderr


NATIVE_LOOP = "void spin_forever(void) { for (volatile int i = 0;; i = 0) {} }\n"  # never returns to Python


@pytest.mark.parametrize("body, expected", [
    ("import os\nos._exit(0)\n", "ended the process (exit code 0"),
    ("import os\nos._exit(7)\n", "ended the process (exit code 7"),
    ("import ctypes\nctypes.string_at(0)\n", "ended the process (killed by signal SIGSEGV"),
    ("import ctypes, pathlib\nctypes.CDLL(str(pathlib.Path(__file__).with_name('spin.so'))).spin_forever()\n",
     "took longer than 2 s"),
])
def test_a_unit_module_that_ends_or_blocks_the_process_at_import_is_reported_by_validate(tmp_path, body, expected):
    """os._exit(), a native crash or a native loop at import: the import runs in a child process first, so
    validate names the file instead of ending with exit 0, dying or hanging (a timer signal cannot interrupt
    native code that never returns to Python)."""
    (tmp_path / "spin.c").write_text(NATIVE_LOOP)
    subprocess.run(["gcc", "-shared", "-fPIC", "-O0", "-o", str(tmp_path / "spin.so"), str(tmp_path / "spin.c")],
                   check=True)
    (tmp_path / "bad.py").write_text(body + SCALE_UNIT.format(factor=1.0))
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"units": {"s": {"python": "bad.py:Scale"}}, "experiment": {"stop": 0.2, "step": 0.1}}))
    started = time.monotonic()
    done = _cosim("validate", str(spec), env={"COSIM_IMPORT_SECONDS": "2"}, timeout=60)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert "$.units.s.python" in done.stderr and str(tmp_path / "bad.py") in done.stderr
    assert expected in done.stderr and "Traceback" not in done.stderr, done.stderr
    assert time.monotonic() - started < 50


def test_a_module_unit_that_ends_the_process_at_import_is_reported(tmp_path):
    (tmp_path / "ending_module.py").write_text("import os\nos._exit(0)\n")
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"units": {"s": {"python": "ending_module:Scale"}},
                                "experiment": {"stop": 0.2, "step": 0.1}}))
    done = _cosim("validate", str(spec), timeout=60)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert "importing module 'ending_module' ended the process (exit code 0" in done.stderr


@pytest.mark.parametrize("command", ["sweep", "optimize", "sensitivity"])
@pytest.mark.parametrize("value", ["nan", "inf", "-1", "0"])
def test_nonsense_timeouts_are_refused(tmp_path, capsys, command, value):
    """Every driver refuses a timeout that would crash every point or never stop one, before any work."""
    from cosim.cli.main import main

    spec = _scale_spec(tmp_path, 1.0)
    code = main([command, str(spec), "--out", str(tmp_path / "out"), f"--timeout={value}"])
    err = capsys.readouterr().err
    assert code == 2 and f"the timeout must be a positive number of seconds, got {float(value)}" in err, err
    assert "Traceback" not in err and not (tmp_path / "out").exists()
