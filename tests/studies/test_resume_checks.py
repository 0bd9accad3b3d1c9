"""A resume refuses a results folder made with other unit or data files: sweeps and optimisations alike.

Real sweeps and optimisations on a real LocalCluster write their folders; then
a file the study depends on is edited in place (the spec's text unchanged) and
the resume is asked for through the command line: exit 2, one message naming
the file and the fix, no traceback.  Values are recomputed from the files.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from cosim.cli.main import main
from cosim.studies.optimize import Optimization
from cosim.util.digest import file_digest, path_digest
from tests.helpers.units_for_cluster import TABLE_GAIN_SOURCE


def _table_study(folder: Path, gain: float, optimize: bool = False) -> Path:
    folder.mkdir(exist_ok=True)
    (folder / "table_units.py").write_text(TABLE_GAIN_SOURCE)
    (folder / "tables").mkdir(exist_ok=True)
    (folder / "tables" / "gain.json").write_text(json.dumps({"gain": gain}))
    spec = {"name": "table", "units": {"g": {"python": "table_units.py:TableGain",
                                             "parameters": {"table": "tables/gain.json"}}},
            "experiment": {"stop": 0.2, "step": 0.1},
            "objectives": {"y": {"signal": "g.y", "reduce": "final", "sense": "minimize"}},
            "design": {"parameters": {"g.k": {"min": 1.0, "max": 2.0} if optimize else {"values": [1.0, 2.0, 3.0]}}}}
    if optimize:
        spec["optimize"] = {"budget": 4, "batch": 2, "seed": 5, "sampler": "random"}
    (folder / "spec.json").write_text(json.dumps(spec))
    return folder / "spec.json"


def test_the_file_digest_helper_hashes_files_and_folders_by_content(tmp_path):
    import hashlib

    (tmp_path / "a.txt").write_bytes(b"abc")
    assert file_digest(tmp_path / "a.txt") == hashlib.sha256(b"abc").hexdigest() == path_digest(tmp_path / "a.txt")
    for name in ("one", "two"):
        (tmp_path / name / "meshes").mkdir(parents=True)
        (tmp_path / name / "robot.urdf").write_text("<robot/>")
        (tmp_path / name / "meshes" / "link.stl").write_bytes(b"\0" * 10)
    assert path_digest(tmp_path / "one") == path_digest(tmp_path / "two")  # content, not place
    (tmp_path / "two" / "meshes" / "link.stl").write_bytes(b"\0" * 11)
    assert path_digest(tmp_path / "one") != path_digest(tmp_path / "two")
    (tmp_path / "two" / "meshes" / "link.stl").write_bytes(b"\0" * 10)
    (tmp_path / "two" / "meshes" / "link.stl").rename(tmp_path / "two" / "meshes" / "other.stl")
    assert path_digest(tmp_path / "one") != path_digest(tmp_path / "two")  # a renamed file counts


def test_a_sweep_resume_refuses_a_changed_data_file_naming_it(tmp_path, local_cluster, capsys):
    spec = _table_study(tmp_path / "project", gain=2.0)
    out = tmp_path / "out"
    assert main(["sweep", str(spec), "--out", str(out), "--scheduler", local_cluster]) == 0
    assert sorted(pd.read_parquet(out / "results.parquet")["y"]) == [2.0, 4.0, 6.0]
    meta = json.loads((out / "metadata.json").read_text())
    table = tmp_path / "project" / "tables" / "gain.json"
    assert meta["data_file_checksums"] == {"g": {"tables/gain.json": file_digest(table)}}
    assert main(["sweep", str(spec), "--out", str(out), "--scheduler", local_cluster, "--resume"]) == 0
    capsys.readouterr()

    table.write_text(json.dumps({"gain": 5.0}))  # same spec text, another gain
    assert main(["sweep", str(spec), "--out", str(out), "--scheduler", local_cluster, "--resume"]) == 2
    err = capsys.readouterr().err
    assert f"data file {table} (unit 'g')" in err and "--recompute" in err and "restore the files" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1

    table.unlink()  # gone: also a change, named
    assert main(["sweep", str(spec), "--out", str(out), "--scheduler", local_cluster, "--resume"]) == 2
    assert f"data file {table} (unit 'g')" in capsys.readouterr().err

    table.write_text(json.dumps({"gain": 5.0}))
    assert main(["sweep", str(spec), "--out", str(out), "--scheduler", local_cluster, "--resume",
                 "--recompute"]) == 0
    assert sorted(pd.read_parquet(out / "results.parquet")["y"]) == [5.0, 10.0, 15.0]


def test_an_optimize_resume_refuses_changed_unit_and_data_files(tmp_path, local_cluster, capsys):
    spec = _table_study(tmp_path / "project", gain=2.0, optimize=True)
    out = tmp_path / "out"
    Optimization(spec, out, scheduler=local_cluster, quiet=True).run()
    df = pd.read_parquet(out / "results.parquet")
    assert len(df) == 4 and list(df["y"]) == [2.0 * k for k in df["g.k"]]
    meta = json.loads((out / "metadata.json").read_text())
    unit_file = tmp_path / "project" / "table_units.py"
    assert meta["unit_checksums"] == {"g": file_digest(unit_file)}
    resume = ["optimize", str(spec), "--out", str(out), "--scheduler", local_cluster, "--resume", "--budget", "6"]
    Optimization(spec, out, scheduler=local_cluster, resume=True, quiet=True)  # unchanged: accepted

    table = tmp_path / "project" / "tables" / "gain.json"
    table.write_text(json.dumps({"gain": 3.0}))
    assert main(resume) == 2
    err = capsys.readouterr().err
    assert f"data file {table} (unit 'g')" in err and "start afresh in another --out" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    table.write_text(json.dumps({"gain": 2.0}))  # restored: accepted again

    unit_file.write_text(TABLE_GAIN_SOURCE.replace("self.gain * self.k", "2 * self.gain * self.k"))
    assert main(resume) == 2
    err = capsys.readouterr().err
    assert "unit 'g'" in err and "holds trials of other unit files" in err and "Traceback" not in err

    unit_file.write_text(TABLE_GAIN_SOURCE)
    assert main(resume) == 0
    assert len(pd.read_parquet(out / "results.parquet")) == 6
