"""Packaging: one name per module, data through importlib.resources, and a wheel that works from any folder.

The wheel installs the repository's models/, fmus/ and specs/ as cosim.models, cosim.fmus and cosim.specs
(pyproject.toml); these tests check that nothing generic is installed, that the source checkout and the wheel
load each module once under that name, and that the built wheel runs a spec from an empty folder.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest
import setuptools

from tests.helpers.paths import REPO
from tests.helpers.tools import venv_seeing_this_interpreter

GENERIC_IMPORT = re.compile(r"^\s*(from|import)\s+(models|fmus)(\.|\s|$)", re.MULTILINE)


def _clean_env(**extra: str) -> dict[str, str]:
    """The environment without PYTHONPATH (a subprocess sees only what is installed), plus ``extra``."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update(extra)
    return env


def test_no_code_imports_the_generic_top_level_names():
    """Every import of the built-in units and FMU sources goes through cosim.models / cosim.fmus."""
    offenders = []
    for folder in ("src", "tests", "examples", "benchmarks"):
        for path in (REPO / folder).rglob("*.py"):
            for match in GENERIC_IMPORT.finditer(path.read_text(encoding="utf-8")):
                line = path.read_text(encoding="utf-8")[:match.start()].count("\n") + 2
                offenders.append(f"{path.relative_to(REPO)}:{line}")
    assert offenders == [], f"import cosim.models / cosim.fmus instead of models / fmus at {offenders}"


def test_every_folder_of_python_code_is_a_package_the_wheel_finds():
    """setuptools finds packages by their __init__.py: a folder of modules without one would be left out."""
    find = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]["find"]
    found = set(setuptools.find_packages(str(REPO / find["where"][0]), include=find["include"]))
    folders = {".".join(p.parent.relative_to(REPO / "src").parts) for p in (REPO / "src").rglob("*.py")
               if "__pycache__" not in p.parts}
    assert folders - found == set(), "add an __init__.py to these folders"
    assert {"cosim", "cosim.units.fmu", "cosim.models", "cosim.fmus.conformance", "orchestrator"} <= found


def test_a_spec_reference_to_a_builtin_unit_loads_the_one_canonical_module(tmp_path):
    """``models.NAME:Class`` in a spec and ``cosim.models.NAME`` in code are the same class object."""
    code = (
        "import sys, json\n"
        "import cosim\n"
        "from cosim.models.motor_gear_energy import MotorGearEnergy\n"
        "cosim.build_system(cosim.load_spec(sys.argv[1]))  # loads the spec's unit class\n"
        "from cosim.units.python.unit import PythonUnitType\n"
        "loaded = PythonUnitType('models.motor_gear_energy:MotorGearEnergy').load_class()\n"
        "print(json.dumps({'same': loaded is MotorGearEnergy,\n"
        "                  'generic': sorted(m for m in sys.modules if m.split('.')[0] in ('models', 'fmus'))}))\n"
    )
    spec = tmp_path / "spec.json"
    spec.write_text('{"units": {"energy": {"python": "models.motor_gear_energy:MotorGearEnergy"}},'
                    ' "experiment": {"stop": 0.01, "step": 0.01}}')
    out = subprocess.run([sys.executable, "-c", code, str(spec)], cwd=REPO, capture_output=True, text=True,
                         env=_clean_env(PYTHONPATH=str(REPO)), timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == '{"same": true, "generic": []}'


def test_schema_and_plant_are_read_as_package_data():
    import importlib.resources

    from cosim.models.plant import DEFAULT_PLANT

    schema = importlib.resources.files("cosim.spec").joinpath("spec.schema.json")
    assert schema.is_file() and Path(DEFAULT_PLANT).is_file()
    assert Path(DEFAULT_PLANT).parent == REPO / "src" / "cosim" / "models"


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel built from this checkout (no network: the installed setuptools builds it)."""
    out = tmp_path_factory.mktemp("wheel")
    # built from a copy: setuptools writes build/ and *.egg-info into the tree it builds
    source = out / "source"
    anywhere = shutil.ignore_patterns(".git", "build", "*.egg-info", "__pycache__", ".pytest_cache")

    def ignore(folder, names):  # results/ and examples/ only at the top: src/cosim/results is the package's
        top = {"results", "examples"} if Path(folder) == REPO else set()
        return anywhere(folder, names) | (top & set(names))
    shutil.copytree(REPO, source, ignore=ignore)
    result = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                             "-w", str(out), str(source)], capture_output=True, text=True, timeout=300,
                            cwd=out)
    assert result.returncode == 0, result.stderr
    (path,) = out.glob("fmi_cosim-*.whl")
    return path


def test_the_wheel_installs_nothing_generic_and_ships_its_data(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    top_level = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert top_level == {"orchestrator", "cosim"}
    for data in ("cosim/spec/spec.schema.json", "cosim/models/bin_picking_plant.json",
                 "cosim/models/panda_rows_c/panda_rows.c", "cosim/models/panda_rows_c/panda_rows_casadi.h",
                 "cosim/fmus/motor_gear_energy/model.json", "cosim/fmus/common/fmi3.c",
                 "cosim/fmus/conformance/fmi3_runtime.c", "cosim/results/store.py", "cosim/fmus/conformance/stair/modelDescription2.xml"):
        assert data in names, data


def test_the_installed_wheel_runs_a_spec_from_an_empty_folder(wheel, tmp_path):
    """A venv holding only the wheel (its dependencies come from this interpreter's site-packages).

    .ci/run does the same in a venv of its own, with the dependencies installed by pip.
    """
    env_dir = tmp_path / "venv"
    python = venv_seeing_this_interpreter(env_dir, with_pip=False)
    site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                          capture_output=True, text=True, check=True).stdout.strip()
    install = subprocess.run([str(python), "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)],
                             capture_output=True, text=True, timeout=300, env=_clean_env())
    assert install.returncode == 0, install.stderr
    empty = tmp_path / "empty"
    empty.mkdir()
    spec = REPO / "examples" / "drive_energy" / "spec.json"
    env = _clean_env(COSIM_FMU_CACHE=str(tmp_path / "fmu_cache"))
    where = subprocess.run([str(python), "-c", "import cosim, cosim.models, cosim.fmus.build as b; "
                            "print(cosim.__file__); print(b.FMUS_DIR)"],
                           cwd=empty, env=env, capture_output=True, text=True, timeout=60)
    assert where.returncode == 0, where.stderr
    assert all(line.startswith(site) for line in where.stdout.split()), where.stdout
    run = subprocess.run([str(env_dir / "bin" / "cosim"), "run", str(spec), "--set", "energy.gear_ratio=120"],
                         cwd=empty, env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "energy" in run.stdout
    assert list(empty.iterdir()) == []  # nothing written into the working folder


def test_a_missing_tool_fails_under_ci_and_skips_elsewhere(monkeypatch):
    from tests.helpers.tools import require_tool

    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="CI=true, so this test must run"):
        require_tool("no-such-program-cosim", "no-such-package")
    monkeypatch.setenv("CI", "")
    with pytest.raises(pytest.skip.Exception, match="Debian package 'no-such-package'"):
        require_tool("no-such-program-cosim", "no-such-package")
    assert require_tool("sh", "dash").endswith("/sh")


def test_a_venv_made_inside_a_venv_sees_the_outer_venvs_packages(tmp_path):
    """Issue 28: after ``pip install -e ".[test]"`` into a fresh venv, the tests that build a venv of their own
    with ``--system-site-packages`` saw the base interpreter's packages, not the venv's (``No module named
    'lxml'``). Here an outer venv holds a module the base interpreter lacks; a venv made inside it by the suite's
    helper imports it (a plain ``venv --system-site-packages`` from the outer venv does not)."""
    outer = venv_seeing_this_interpreter(tmp_path / "outer", with_pip=False)  # sees pytest, as the suite's venv
    outer_site = subprocess.run([str(outer), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                                capture_output=True, text=True, check=True).stdout.strip()
    Path(outer_site, "issue28_only_in_the_outer_venv.py").write_text("WHERE = 'outer venv'\n")
    make_inner = (f"import sys; sys.path.insert(0, {str(REPO)!r}); from pathlib import Path; "
                  "from tests.helpers.tools import venv_seeing_this_interpreter as make; "
                  f"print(make(Path({str(tmp_path / 'inner')!r}), with_pip=False))")
    made = subprocess.run([str(outer), "-c", make_inner], capture_output=True, text=True, timeout=120, env=_clean_env())
    assert made.returncode == 0, made.stderr
    probe = "import issue28_only_in_the_outer_venv as m; print(m.WHERE)"
    inner = subprocess.run([made.stdout.strip(), "-c", probe], capture_output=True, text=True, timeout=60,
                           env=_clean_env(), cwd=tmp_path)
    assert inner.returncode == 0 and inner.stdout.strip() == "outer venv", inner.stderr
    plain = tmp_path / "plain"
    subprocess.run([str(outer), "-m", "venv", "--without-pip", "--system-site-packages", str(plain)], check=True)
    alone = subprocess.run([str(plain / "bin" / "python"), "-c", probe], capture_output=True, text=True,
                           timeout=60, env=_clean_env(), cwd=tmp_path)
    assert "No module named 'issue28_only_in_the_outer_venv'" in alone.stderr  # the failure the helper avoids
