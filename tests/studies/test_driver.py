"""The results-folder rules every driver shares (src/cosim/studies/driver.py), through the real Sweep and Optimization.

No Dask runs here: both drivers check their folder when they are made.
"""

from __future__ import annotations

import re

import pytest

from cosim.cli.main import main
from cosim.results.store import ResultsStore
from cosim.studies.optimize import Optimization, OptimizeError
from cosim.studies.sweep import Sweep, SweepError
from cosim.system.validate import check_spec
from tests.studies.test_optimize import bowls_spec


@pytest.fixture
def spec(write_spec):
    raw = bowls_spec()
    for parameter in raw["design"]["parameters"].values():
        parameter["step"] = 1.0  # a grid too, so that the same spec makes a Sweep
    return write_spec(raw)


def folder_with_rows(path, digest: str, **metadata) -> ResultsStore:
    store = ResultsStore(path)
    store.append([{"point_id": "p0", "b.x": 0.0, "b.y": 0.0, "f1": 0.0, "f2": 4.0, "status": "ok", "message": "",
                   "run_time": 0.1, "worker": "w"}])
    store.write_metadata({"spec_digest": digest, **metadata})
    return store


def test_a_folder_with_rows_is_refused_without_resume_by_both_drivers(spec, tmp_path, capsys):
    digest = check_spec(spec).spec.digest
    folder_with_rows(tmp_path / "out", digest)
    # said to each caller in its own words: the Python argument from Python (the library names no command-line
    # option), the command's option from the command line
    with pytest.raises(SweepError, match=re.escape("already holds results; add resume=True to finish that sweep, "
                                                   "or choose another out folder")):
        Sweep(spec, out=tmp_path / "out", quiet=True)
    with pytest.raises(OptimizeError, match=re.escape("already holds results; add resume=True to continue that "
                                                      "optimisation")):
        Optimization(spec, tmp_path / "out", quiet=True)
    for command, to_resume in (("sweep", "finish that sweep"), ("optimize", "continue that optimisation")):
        assert main([command, str(spec), "--out", str(tmp_path / "out"), "-q"]) == 2
        err = capsys.readouterr().err
        assert f"already holds results; add --resume to {to_resume}, or choose another --out" in err, err
        assert "resume=True" not in err and "Traceback" not in err


def test_resume_needs_the_same_spec_and_the_same_kind_of_study(spec, tmp_path):
    digest = check_spec(spec).spec.digest
    folder_with_rows(tmp_path / "other", "0" * 64)
    for make, error in ((lambda out: Sweep(spec, out=out, resume=True, quiet=True), SweepError),
                        (lambda out: Optimization(spec, out, resume=True, quiet=True), OptimizeError)):
        with pytest.raises(error, match=r"holds results of a different spec \(digest 000000000000…, this one "
                                        + digest[:12]):
            make(tmp_path / "other")
    folder_with_rows(tmp_path / "swept", digest)  # a sweep writes no kind
    with pytest.raises(OptimizeError, match="holds sweep results, not optimization results"):
        Optimization(spec, tmp_path / "swept", resume=True, quiet=True)
    assert Sweep(spec, out=tmp_path / "swept", resume=True, quiet=True).resume
    folder_with_rows(tmp_path / "optimised", digest, kind="optimization", optimize={"seed": 3})
    with pytest.raises(SweepError, match="holds optimization results, not sweep results"):
        Sweep(spec, out=tmp_path / "optimised", resume=True, quiet=True)
    assert Optimization(spec, tmp_path / "optimised", resume=True, quiet=True).settings.seed == 3
