"""A small sweep whose every row is known: the Triple unit (y = 3 k, an optional pause a step), the spec that
sweeps k = 1..points, the check that a table holds exactly those rows, and the cosim command in a process of its
own.  The hostile-files, stop, interrupt and leftover tests stop, kill and resume this sweep."""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
from pathlib import Path

from tests.helpers.paths import REPO

TRIPLE_UNIT = """
import time
from cosim import PythonUnit, Variable

class Triple(PythonUnit):
    variables = (Variable("k", "parameter", start=1.0), Variable("pause", "parameter", start=0.0),
                 Variable("y", "output", start=0.0))

    def do_step(self, t, h):
        time.sleep(self.pause)
        self.y = 3.0 * self.k
"""


def triple_spec(folder: Path, points: int, pause: float = 0.0) -> Path:
    """spec.json in ``folder`` (and triple.py beside it): a sweep of k = 1..points, objective y = 3 k."""
    (folder / "triple.py").write_text(TRIPLE_UNIT)
    spec = {"units": {"s": {"python": "triple.py:Triple", "parameters": {"pause": pause}}},
            "experiment": {"stop": 0.1, "step": 0.1}, "objectives": {"y": {"signal": "s.y", "reduce": "final"}},
            "design": {"parameters": {"s.k": {"min": 1, "max": points, "step": 1}}}}
    path = folder / "spec.json"
    path.write_text(json.dumps(spec))
    return path


def assert_triples_exact(table, points: int) -> None:
    """Every point once, in design order, with the value computed independently (y = 3 k)."""
    assert list(table["s.k"]) == list(range(1, points + 1))
    assert list(table["y"]) == [3.0 * k for k in range(1, points + 1)]
    assert set(table["status"]) == {"ok"}


def run_cosim(*args: str, timeout: float = 180, **popen) -> subprocess.CompletedProcess:
    """``python -m cosim.cli.main ARGS`` in a process of its own, on this tree's sources; output captured."""
    return subprocess.run([sys.executable, "-m", "cosim.cli.main", *args], capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=str(REPO / "src")), timeout=timeout, **popen)


@contextlib.contextmanager
def read_only_folder(folder: Path):
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
