"""Issue 28.16: the API reference of `import cosim` (docs/api.md) is generated from the docstrings and kept so.

Every public name (``cosim.__all__``) and every public method or property of a public class has a docstring, and
docs/api.md is exactly what ``python docs/api_reference.py`` writes from them: a docstring changed without
regenerating the page, or a public name added without one, fails here.
"""

from __future__ import annotations

import importlib.util
import inspect
import subprocess
import sys

import cosim
from tests.helpers.paths import REPO

ROOT = REPO
SCRIPT = ROOT / "docs" / "api_reference.py"


def generator():
    spec = importlib.util.spec_from_file_location("api_reference", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_public_name_and_method_has_a_docstring():
    reference = generator()
    names = reference.public_names()
    assert set(names) == set(cosim.__all__) - {"__version__"} and len(names) >= 20
    missing = []
    for name in names:
        obj = getattr(cosim, name)
        if not (inspect.getdoc(obj) or "").strip():
            missing.append(name)
        if inspect.isclass(obj):
            missing += [f"{name}.{member}" for member, value in reference.members(obj)
                        if member != "__init__" and not (inspect.getdoc(value) or "").strip()]
    assert missing == []


def test_docs_api_md_is_generated_from_the_docstrings():
    reference = generator()
    text = reference.reference()
    assert (ROOT / "docs" / "api.md").read_text(encoding="utf-8") == text, \
        "docs/api.md is stale: run python docs/api_reference.py"
    # each public name has its section with its docstring's first line, and signatures are the real ones
    for name in reference.public_names():
        obj = getattr(cosim, name)
        heading = f"### class `{name}`" if inspect.isclass(obj) else f"### `{name}("
        assert heading in text, name
        assert inspect.getdoc(obj).splitlines()[0] in text, name
    assert f"### `sweep{inspect.signature(cosim.sweep)}`" in text
    assert "#### `PythonUnit.do_step(t: 'float', h: 'float') -> 'None'`" in text  # self left out


def test_the_check_mode_fails_on_a_stale_page(tmp_path):
    """`python docs/api_reference.py --check` (what a CI step or a pre-commit hook runs): 0 now, 1 when stale."""
    done = subprocess.run([sys.executable, str(SCRIPT), "--check"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    stale = tmp_path / "docs"
    stale.mkdir()
    (stale / "api_reference.py").write_text(SCRIPT.read_text(encoding="utf-8"))
    (stale / "api.md").write_text((ROOT / "docs" / "api.md").read_text(encoding="utf-8").replace("Pareto", "Parreto"))
    done = subprocess.run([sys.executable, str(stale / "api_reference.py"), "--check"], capture_output=True, text=True)
    assert done.returncode == 1 and "is not up to date: run python docs/api_reference.py" in done.stderr
