"""``cosim run SPEC --point ID`` when several sweeps of the spec hold the point: refused, listing them
(issue 28, item 15); before, the newest folder was picked silently."""

from __future__ import annotations

import cosim
from cosim.cli.main import main
from tests.helpers.triple_study import triple_spec


def test_run_point_refuses_to_guess_between_sweeps_holding_the_point(tmp_path, monkeypatch, capsys,
                                                                    local_cluster):  # noqa: F811
    monkeypatch.chdir(tmp_path)
    spec = triple_spec(tmp_path, 3)
    first = cosim.sweep(str(spec), out="results/first", scheduler=local_cluster, quiet=True)
    cosim.sweep(str(spec), out="results/second", scheduler=local_cluster, quiet=True)
    point = first.loc[first["s.k"] == 2, "point_id"].item()
    assert main(["run", str(spec), "--point", point]) == 2
    err = capsys.readouterr().err
    assert f"--point {point}: 2 sweeps of this spec hold the point" in err
    assert "results/first" in err and "results/second" in err and "--results DIR" in err
    assert main(["run", str(spec), "--point", point, "--results", "results/second"]) == 0
    out = capsys.readouterr().out
    assert "s.k=2" in out and "6" in out  # y = 3 k
    assert main(["run", str(spec), "--point", "0000000000000000"]) == 2
    assert "none of the 2 sweeps of this spec holds the point" in capsys.readouterr().err


def test_metadata_records_the_versions_that_change_results(tmp_path, local_cluster):  # noqa: F811
    """Issue 28, item 15: cosim's own version (distribution fmi-cosim) and the physics and code generation of
    the built-in units (pin, exudyn, casadi) were missing from metadata.json."""
    import importlib.metadata
    import json

    import casadi
    import exudyn
    import numpy
    import pinocchio

    cosim.sweep(str(triple_spec(tmp_path, 2)), out=str(tmp_path / "out"), scheduler=local_cluster, quiet=True)
    packages = json.loads((tmp_path / "out" / "metadata.json").read_text())["packages"]
    assert packages["fmi-cosim"] == cosim.__version__
    assert packages["casadi"] == casadi.__version__ and packages["pin"] == pinocchio.__version__
    assert packages["exudyn"] == exudyn.__version__ and packages["numpy"] == numpy.__version__
    assert packages["SALib"] == importlib.metadata.version("SALib")
    assert "cosim" not in packages  # another project's name on the package index
