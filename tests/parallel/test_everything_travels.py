"""Everything a point needs travels with it: workers in another folder, with another HOME, without the spec's folder.

Real `dask scheduler` / `dask worker` processes started in a temporary folder
(their working directory and HOME), with only cosim on their PYTHONPATH; the
spec's folder is moved away after the sweep is prepared, so nothing can be read
from it by path. The specs use Python units named by *module* from the spec's
folder (shipped as source), a player of a CSV table and data files a unit
declares (``data_files``: JSON tables named in the spec and in the design).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from cosim.studies.sweep import Sweep
from tests.helpers.paths import REPO
from tests.helpers.sweep_fixtures import free_port, kill_group, wait_for_workers
from tests.helpers.units_for_cluster import TABLE_GAIN_SOURCE

ROOT = REPO

UNIT_SOURCE = '''
from cosim import PythonUnit, Variable


class Scale(PythonUnit):
    """y = k * u, u from the player."""

    variables = (Variable("k", "parameter", start=1.0), Variable("u", "input", start=0.0),
                 Variable("y", "output", start=0.0))
    feedthrough = {"y": ["u"]}

    def compute_outputs(self):
        self.y = self.k * self.u

    def do_step(self, t, h):
        self.compute_outputs()
'''


@pytest.fixture
def foreign_workers(tmp_path_factory):
    """A scheduler and two workers whose cwd and HOME are a fresh folder and whose PYTHONPATH is cosim only."""
    home = tmp_path_factory.mktemp("foreign_home")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "HOME", "PWD")}
    env.update(HOME=str(home), PYTHONPATH=str(ROOT))
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    scheduler = subprocess.Popen(dask + ["--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], cwd=home,
                                 env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    workers = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nworkers", "2",
                                "--nthreads", "1", "--no-dashboard", "--host", "127.0.0.1"], cwd=home, env=env,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        from distributed import Client

        wait_for_workers(address, 2, seconds=90)
        with Client(address, timeout=5) as client:
            homes = set(client.run(lambda: os.environ["HOME"] + "|" + os.getcwd()).values())
        assert homes == {f"{home}|{home}"}
        yield address
    finally:
        kill_group(workers)
        kill_group(scheduler)


def test_module_unit_and_played_table_travel_to_foreign_workers(tmp_path, foreign_workers):
    folder = tmp_path / "project"
    folder.mkdir()
    (folder / "my_scaling_units.py").write_text(UNIT_SOURCE)
    (folder / "drive.csv").write_text("time,u\n0,1.0\n0.5,2.0\n1.0,3.0\n")
    spec = {
        "name": "travels",
        "units": {"play": {"player": "drive.csv"},
                  "scale": {"python": "my_scaling_units:Scale"}},
        "connections": [{"from": "play.u", "to": "scale.u"}],
        "experiment": {"stop": 1.0, "step": 0.5},
        "objectives": {"y_end": {"signal": "scale.y", "reduce": "final"},
                       "y_sum": {"signal": "scale.y", "reduce": "mean"}},
        "design": {"parameters": {"scale.k": {"values": [1.0, 2.0, 5.0]}}},
    }
    import json

    (folder / "spec.json").write_text(json.dumps(spec))
    sweep = Sweep(folder / "spec.json", out=tmp_path / "out", scheduler=foreign_workers, quiet=True)
    shutil.move(folder, tmp_path / "moved_away")  # nothing of the spec's folder is there any more
    sys.modules.pop("my_scaling_units", None)
    df = sweep.run()
    assert (df["status"] == "ok").all(), list(df["message"])
    assert list(df["y_end"]) == [3.0, 6.0, 15.0]
    assert list(df["y_sum"]) == [2.0, 4.0, 10.0]


def test_declared_data_files_travel_to_foreign_workers(tmp_path, foreign_workers):
    """A unit's data files (named by its declared String parameters, in the spec and in the design) travel too."""
    import json

    folder = tmp_path / "project"
    (folder / "tables").mkdir(parents=True)
    (folder / "my_table_units.py").write_text(TABLE_GAIN_SOURCE)
    gains = {"tables/slow.json": 2.0, "tables/fast.json": 7.0, "default.json": 3.0}
    for name, gain in gains.items():
        (folder / name).write_text(json.dumps({"gain": gain}))
    spec = {
        "name": "data_travels",
        "units": {"g": {"python": "my_table_units:TableGain", "parameters": {"table": "default.json"}}},
        "experiment": {"stop": 0.2, "step": 0.1},
        "objectives": {"y_end": {"signal": "g.y", "reduce": "final"}},
        "design": {"parameters": {"g.table": {"values": ["tables/slow.json", "tables/fast.json"]},
                                  "g.k": {"values": [1.0, 10.0]}}},
    }
    (folder / "spec.json").write_text(json.dumps(spec))
    sweep = Sweep(folder / "spec.json", out=tmp_path / "out", scheduler=foreign_workers, quiet=True)
    shutil.move(folder, tmp_path / "moved_away")  # the workers cannot read the tables by path, nor can the client
    sys.modules.pop("my_table_units", None)
    df = sweep.run()
    assert (df["status"] == "ok").all(), list(df["message"])
    expected = [gains[table] * k for table in ("tables/slow.json", "tables/fast.json") for k in (1.0, 10.0)]
    assert sorted(df["y_end"]) == sorted(expected)
    for _, row in df.iterrows():
        assert row["y_end"] == gains[row["g.table"]] * row["g.k"]


def test_a_data_file_path_is_read_from_the_spec_folder_whatever_the_working_directory(tmp_path, monkeypatch):
    import json

    from cosim import run

    folder = tmp_path / "project"
    folder.mkdir()
    (folder / "my_table_units_local.py").write_text(TABLE_GAIN_SOURCE)
    (folder / "gain.json").write_text(json.dumps({"gain": 4.0}))
    spec = {"name": "data_local",
            "units": {"g": {"python": "my_table_units_local:TableGain", "parameters": {"table": "gain.json", "k": 2.5}}},
            "experiment": {"stop": 0.2, "step": 0.1},
            "objectives": {"y_end": {"signal": "g.y", "reduce": "final"}}}
    (folder / "spec.json").write_text(json.dumps(spec))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    result = run(str(folder / "spec.json"))
    assert result.ok, result.message
    assert result.objectives["y_end"] == 10.0


def test_data_files_must_name_string_parameters(write_spec, tmp_path):
    from cosim.errors import SpecError
    from cosim.system.validate import check_spec

    (tmp_path / "bad_units.py").write_text(TABLE_GAIN_SOURCE.replace('data_files = ("table",)', 'data_files = ("k",)'))
    spec = write_spec({"name": "bad", "units": {"g": {"python": "bad_units.py:TableGain"}},
                       "experiment": {"stop": 0.1, "step": 0.1}})
    with pytest.raises(SpecError) as info:
        check_spec(spec)
    assert "data_files must list names of its String parameters" in str(info.value)
    assert "['k']" in str(info.value)


def test_the_readme_data_files_unit_reads_its_table_from_the_spec_folder(tmp_path, monkeypatch):
    import json
    import re

    from cosim import run

    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    (block,) = [b for b in re.findall(r"```python\n(.*?)```", readme, re.S) if "class TableGain" in b]
    folder = tmp_path / "project"
    (folder / "tables").mkdir(parents=True)
    (folder / "readme_table_unit.py").write_text(block)
    (folder / "tables" / "gain.json").write_text(json.dumps({"gain": 6.5}))
    (folder / "spec.json").write_text(json.dumps({
        "name": "readme_data_files",
        "units": {"g": {"python": "readme_table_unit.py:TableGain", "parameters": {"table": "tables/gain.json"}}},
        "experiment": {"stop": 0.2, "step": 0.1}, "objectives": {"y_end": {"signal": "g.y", "reduce": "final"}}}))
    monkeypatch.chdir(tmp_path)
    result = run(str(folder / "spec.json"))
    assert result.ok, result.message
    assert result.objectives["y_end"] == 6.5


ROBOT_UNIT_SOURCE = '''
import re
from pathlib import Path

from cosim import PythonUnit, Variable


class RobotMass(PythonUnit):
    """y = k * scale * (bytes of the mesh), read from the folder named by 'model': robot.urdf names its mesh
    by a path relative to the folder (as a URDF with its meshes does)."""

    variables = (Variable("model", "parameter", type="String", start=""), Variable("k", "parameter", start=1.0),
                 Variable("y", "output", start=0.0))
    data_files = ("model",)

    def initialize(self):
        urdf = (Path(self.model) / "robot.urdf").read_text()
        mesh, scale = re.search(r'<mesh filename="([^"]+)" scale="([^"]+)"', urdf).groups()
        self.mass = float(scale) * len((Path(self.model) / mesh).read_bytes())

    def do_step(self, t, h):
        self.y = self.k * self.mass
'''


def _robot_folder(folder: Path, scale: float, mesh_bytes: int) -> None:
    (folder / "meshes").mkdir(parents=True)
    (folder / "robot.urdf").write_text(f'<robot><link><mesh filename="meshes/link.stl" scale="{scale}"/></link></robot>')
    (folder / "meshes" / "link.stl").write_bytes(b"\x01" * mesh_bytes)


def test_a_data_folder_travels_whole_to_foreign_workers(tmp_path, foreign_workers):
    """A data-file parameter naming a folder (a URDF and its meshes): the folder travels whole, relative paths work."""
    import json

    folder = tmp_path / "project"
    folder.mkdir()
    (folder / "my_robot_units.py").write_text(ROBOT_UNIT_SOURCE)
    _robot_folder(folder / "robots" / "small", scale=0.5, mesh_bytes=100)
    _robot_folder(folder / "robots" / "big", scale=2.0, mesh_bytes=3000)
    spec = {"name": "folder_travels", "units": {"r": {"python": "my_robot_units:RobotMass"}},
            "experiment": {"stop": 0.2, "step": 0.1}, "objectives": {"y": {"signal": "r.y", "reduce": "final"}},
            "design": {"parameters": {"r.model": {"values": ["robots/small", "robots/big"]},
                                      "r.k": {"values": [1.0, 3.0]}}}}
    (folder / "spec.json").write_text(json.dumps(spec))
    sweep = Sweep(folder / "spec.json", out=tmp_path / "out", scheduler=foreign_workers, quiet=True)
    shutil.move(folder, tmp_path / "moved_away")  # neither the workers nor the client can read the folders by path
    sys.modules.pop("my_robot_units", None)
    df = sweep.run()
    assert (df["status"] == "ok").all(), list(df["message"])
    mass = {"robots/small": 0.5 * 100, "robots/big": 2.0 * 3000}
    assert sorted(zip(df["r.model"], df["r.k"], df["y"])) == sorted(
        (m, k, k * mass[m]) for m in mass for k in (1.0, 3.0))


def test_a_data_folder_above_the_size_limit_is_refused_naming_it_and_the_fix(tmp_path, monkeypatch, capsys):
    import json

    from cosim.cli.main import main

    folder = tmp_path / "project"
    folder.mkdir()
    (folder / "robot_units.py").write_text(ROBOT_UNIT_SOURCE)
    _robot_folder(folder / "robot", scale=1.0, mesh_bytes=1_500_000)
    (folder / "spec.json").write_text(json.dumps({
        "name": "big_folder", "units": {"r": {"python": "robot_units.py:RobotMass", "parameters": {"model": "robot"}}},
        "experiment": {"stop": 0.2, "step": 0.1}, "objectives": {"y": {"signal": "r.y", "reduce": "final"}}}))
    monkeypatch.setenv("COSIM_DATA_MB", "1")
    assert main(["sweep", str(folder / "spec.json"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert f"data file value 'robot' names the folder {folder / 'robot'} (2 files) of 1.5 MB" in err
    assert "$.units.r" in err and "COSIM_DATA_MB" in err and "Traceback" not in err
    monkeypatch.setenv("COSIM_DATA_MB", "2")  # raised on purpose: it runs
    assert main(["run", str(folder / "spec.json")]) == 0
