"""Helpers many test files use: a system tool or fail under CI, a venv that sees this interpreter's packages,
the spec reference of a test unit."""

from __future__ import annotations

import os
import shutil
import site
import subprocess
import sys
import venv
from pathlib import Path

import pytest

from tests.helpers.paths import HELPERS


def require_tool(program: str, package: str) -> str:
    """The path of ``program``; without it the test is skipped, or FAILS under ``CI=true`` (.ci/run sets it).

    A skip would let CI pass without ever running the test, so CI must install ``package``.
    """
    path = shutil.which(program)
    if path is None:
        why = f"{program} is not installed (Debian package '{package}'; .ci/run installs it)"
        if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
            pytest.fail(f"{why}; CI=true, so this test must run")
        pytest.skip(why)
    return path


def venv_seeing_this_interpreter(venv_dir: Path, *, with_pip: bool = True) -> Path:
    """A new venv at ``venv_dir`` that sees this interpreter's packages behind its own; its ``python``.

    ``--system-site-packages`` links a venv to the *base* interpreter (venv builds from ``sys._base_executable``;
    venvs do not chain), so a venv made from the venv pytest runs in saw the base interpreter's site-packages and
    none of this one's (issue 28: after ``pip install -e ".[test]"`` into a fresh venv, ``No module named
    'lxml'``). When this interpreter is a venv, a ``.pth`` file in the new one adds this one's site-packages with
    ``site.addsitedir`` (so their own ``.pth`` files run too: cmeel's for pin, the editable install's finder),
    after the new venv's own and before the base's. Outside a venv this is ``venv --system-site-packages``.
    """
    venv.create(venv_dir, system_site_packages=True, with_pip=with_pip, symlinks=os.name != "nt")
    python = venv_dir / "bin" / "python"
    if sys.prefix != sys.base_prefix:
        purelib = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                                 capture_output=True, text=True, check=True).stdout.strip()
        line = "; ".join(["import site"] + [f"site.addsitedir({d!r})" for d in dict.fromkeys(site.getsitepackages())])
        (Path(purelib) / "_cosim_tests_parent_site.pth").write_text(line + "\n")
    return python


def python_unit(cls: str) -> str:
    """The spec reference of a test unit in tests/helpers/units_for_tests.py."""
    return f"{HELPERS / 'units_for_tests.py'}:{cls}"
