""".ci/minimum_requirements.py: the floors of every dependency (caps dropped), exact pins kept, cosim[EXTRA]
expanded."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from tests.helpers.paths import REPO

SCRIPT = REPO / ".ci" / "minimum_requirements.py"

PYPROJECT = """
[project]
name = "cosim"
dependencies = ["numpy>=2.2", "dask[distributed]>=2024.1", "fmpy>=0.3.32,<0.4"]
[project.optional-dependencies]
gp = ["torch==2.13.0", "greenlet>=3.5.6"]
test = ["cosim[gp]", "pytest>=7"]
"""


def pinned(tmp_path: Path, text: str) -> subprocess.CompletedProcess:
    (tmp_path / "pyproject.toml").write_text(text)
    return subprocess.run([sys.executable, str(SCRIPT), str(tmp_path / "pyproject.toml")], capture_output=True,
                          text=True, timeout=60)


def test_floors_pinned_exact_pins_kept_and_own_extras_expanded(tmp_path):
    done = pinned(tmp_path, PYPROJECT)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["numpy==2.2", "dask[distributed]==2024.1", "fmpy==0.3.32", "torch==2.13.0", "greenlet==3.5.6",
                                   "pytest==7"]


def test_a_requirement_without_one_floor_or_pin_is_refused(tmp_path):
    for bad in ('"scipy<2"', '"scipy>=1.15,>=1.16"', '"scipy"', '"scipy~=1.15"',
                '"scipy>=1.15; python_version < \\"3.12\\""'):
        done = pinned(tmp_path, PYPROJECT.replace('"pytest>=7"', bad))
        assert done.returncode == 1 and "cannot pin it" in done.stderr, (bad, done.stderr)


def test_the_projects_own_requirements_pin_torch_exactly():
    done = subprocess.run([sys.executable, str(SCRIPT)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "torch==2.13.0" in done.stdout.split()
