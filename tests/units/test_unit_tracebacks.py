"""A Python unit that raises shows its own traceback where the user looks (issue 28, item 2).

Before, every place said only "do_step raised ZeroDivisionError: division by zero": `cosim run`, a sweep's row,
the API's result. Now the unit's frames (file, line, function, source line) follow that line, bounded for a row;
``--debug`` keeps the whole traceback, cosim's frames included.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import cosim
from cosim.errors import UNIT_TRACEBACK_CHARS, UNIT_TRACEBACK_FRAMES, UnitError, unit_traceback
from tests.helpers.paths import REPO

UNIT_SOURCE = '''\
from cosim import PythonUnit, Variable


def share(total, parts):
    return total / parts


class Splitter(PythonUnit):
    variables = (Variable("parts", "parameter", start=1.0), Variable("y", "output", start=0.0))

    def do_step(self, t, h):
        if t >= 0.25:
            self.y = share(1.0, self.parts)
'''


def _study(folder: Path) -> Path:
    (folder / "splitter.py").write_text(UNIT_SOURCE)
    spec = {"units": {"split": {"python": "splitter.py:Splitter"}},
            "experiment": {"stop": 0.5, "step": 0.1},
            "objectives": {"y": {"signal": "split.y", "reduce": "final"}},
            "design": {"parameters": {"split.parts": {"values": [0, 2]}}}}
    path = folder / "spec.json"
    path.write_text(json.dumps(spec))
    return path


def _cosim(*args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO / "src"), os.environ.get("PYTHONPATH", "")]))
    env.pop("COSIM_DEBUG", None)
    return subprocess.run([sys.executable, "-m", "cosim.cli.main", *args], env=env, text=True,
                          capture_output=True, timeout=300)


def _assert_the_units_frames(text: str, folder: Path | None) -> None:
    """``folder``: where the unit's file is; None in a sweep, whose tasks carry the file to the worker."""
    assert "unit 'split' at t=0.3: do_step raised ZeroDivisionError: float division by zero" in text
    unit_file = str(folder / "splitter.py") if folder else "splitter.py"
    opening = 'File "' if folder else "/"
    assert f'{opening}{unit_file}", line 13, in do_step\n    self.y = share(1.0, self.parts)' in text
    assert f'{opening}{unit_file}", line 5, in share\n    return total / parts' in text
    assert text.rstrip().endswith("ZeroDivisionError: float division by zero")


def test_cosim_run_prints_the_units_traceback(tmp_path):
    spec = _study(tmp_path)
    done = _cosim("run", str(spec), "--set", "split.parts=0")
    assert done.returncode == 1, done.stderr
    _assert_the_units_frames(done.stderr, tmp_path)
    assert "algorithms.py" not in done.stderr and "execution" not in done.stderr  # cosim's frames left out
    assert "status: failed" in done.stdout


def test_debug_keeps_cosims_frames_too(tmp_path):
    spec = _study(tmp_path)
    for argv in (["--debug", "run", str(spec), "--set", "split.parts=0"],
                 ["run", str(spec), "--set", "split.parts=0", "--debug"]):
        done = _cosim(*argv)
        assert done.returncode == 1, done.stderr
        _assert_the_units_frames(done.stderr, tmp_path)
        assert "cosim/master/contract.py" in done.stderr and "in step_unit" in done.stderr or \
            "in step\n" in done.stderr, done.stderr


def test_debug_shows_the_traceback_behind_a_users_mistake(tmp_path):
    missing = tmp_path / "nowhere.json"
    plain, debug = _cosim("validate", str(missing)), _cosim("--debug", "validate", str(missing))
    assert plain.returncode == debug.returncode == 2
    assert "Traceback" not in plain.stderr
    assert debug.stderr.startswith(plain.stderr) and "Traceback (most recent call last)" in debug.stderr


def test_a_sweep_row_keeps_the_units_frames(tmp_path, local_cluster):  # noqa: F811
    spec = _study(tmp_path)
    df = cosim.sweep(str(spec), out=str(tmp_path / "out"), scheduler=local_cluster, quiet=True)
    rows = {row["split.parts"]: row for _, row in df.iterrows()}
    assert rows[2]["status"] == "ok" and rows[2]["y"] == 0.5
    assert rows[0]["status"] == "failed"
    # issue 39: the frames name the user's file, not the worker's temporary copy of it
    _assert_the_units_frames(rows[0]["message"], tmp_path.resolve())
    assert "cosim_worker_" not in rows[0]["message"] and "payload_" not in rows[0]["message"]
    stored = cosim.read_results(tmp_path / "out")  # the table on disk, as report and explore read it
    assert stored.set_index("split.parts").loc[0, "message"] == rows[0]["message"]


def test_a_rows_traceback_is_bounded():
    """A unit that recursed without end: the innermost frames and the exception, within the bounds."""
    def down(n):
        return down(n + 1)
    try:
        down(0)
    except RecursionError as exc:
        error = UnitError.raised("deep", "do_step", exc, 0.5)
    text = error.with_traceback_text()
    assert text.startswith("unit 'deep' at t=0.5: do_step raised RecursionError: maximum recursion depth")
    assert len(error.traceback) <= UNIT_TRACEBACK_CHARS + 60
    assert 0 < error.traceback.count("  File ") <= UNIT_TRACEBACK_FRAMES  # the innermost ones
    assert "outer frames left out" in error.traceback
    assert error.traceback.endswith("RecursionError: maximum recursion depth exceeded")


def test_an_error_from_cosim_itself_has_no_unit_traceback():
    try:
        UnitError.raised  # noqa: B018 - only to have a frame of this file below
        raise ValueError("x")
    except ValueError as exc:
        assert unit_traceback(exc).startswith("Traceback")  # this test file is not cosim's: its frame is kept
    assert UnitError("u", "m", 1.0).with_traceback_text() == "unit 'u' at t=1: m"
