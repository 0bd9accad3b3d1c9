"""Everyday command-line use that once ended in a traceback: a closed pipe, a bad scheduler address, --version."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from cosim import __version__
from cosim.cli.main import main
from tests.helpers.paths import REPO


def cosim(*args: str, **kwargs) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    return subprocess.Popen([sys.executable, "-m", "cosim.cli.main", *args], env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kwargs)


def test_version_prints_the_package_version(capsys):
    try:
        main(["--version"])
    except SystemExit as exc:
        assert exc.code == 0
    assert capsys.readouterr().out.strip() == f"cosim {__version__}"


def test_output_into_a_pipe_closed_early_is_not_an_error(tmp_path):
    """`cosim pareto ... | head -1`: the reader leaves after one line; cosim stops quietly with exit 0."""
    n = 20_000  # a front of 20 000 rows: far more than a pipe's buffer
    x = np.linspace(0.0, 1.0, n)
    pd.DataFrame({"point_id": [f"p{i:06d}" for i in range(n)], "a": x, "b": 1.0 - x,
                  "status": "ok"}).to_parquet(tmp_path / "t.parquet")
    proc = cosim("pareto", str(tmp_path / "t.parquet"), "--min", "a", "--min", "b")
    first = proc.stdout.readline()
    proc.stdout.close()  # what `head -1` does after its line
    stderr = proc.stderr.read()
    assert proc.wait(timeout=120) == 0, stderr
    assert first.startswith("Pareto front") and stderr == ""


def test_a_malformed_scheduler_address_is_a_usage_error_naming_the_form(tmp_path, capsys):
    spec = REPO / "examples" / "drive_energy" / "spec.json"
    for address in ("nonsense", "tcp://host-without-port", "foo://x:1"):
        assert main(["sweep", str(spec), "--out", str(tmp_path / "out"), "--scheduler", address]) == 2
        err = capsys.readouterr().err
        assert f"--scheduler '{address}' is not a Dask scheduler address" in err and "tcp://HOST:PORT" in err
        assert "Traceback" not in err
    assert not (tmp_path / "out").exists()  # refused before anything was written


def test_run_point_finds_the_sweep_written_with_out(tmp_path, monkeypatch, capsys, local_cluster):  # noqa: F811
    """The README's `cosim sweep SPEC --out results/<any name>`, then `cosim run SPEC --point ID`: no --results."""
    import json

    spec = tmp_path / "study" / "spec.json"
    spec.parent.mkdir()
    spec.write_text(json.dumps({
        "name": "not_the_folder_name", "units": {"ode": {"fmu": "builtin:linear_ode_fmi3"}},
        "experiment": {"stop": 0.5, "step": 0.1}, "objectives": {"y_end": {"signal": "ode.y", "reduce": "final"}},
        "design": {"parameters": {"ode.a": {"values": [-1.0, -2.0]}}}}))
    monkeypatch.chdir(tmp_path)
    assert main(["sweep", str(spec), "--out", "results/my_run", "--scheduler", local_cluster]) == 0
    table = pd.read_parquet(tmp_path / "results" / "my_run" / "results.parquet")
    point = table.loc[table["ode.a"] == -2.0, "point_id"].item()
    capsys.readouterr()
    assert main(["run", str(spec), "--point", point]) == 0
    out = capsys.readouterr().out
    assert f"point {point}: ode.a=-2.0" in out
    assert (tmp_path / "results" / "my_run" / "points" / f"{point}.parquet").exists()
    y_end = float(next(line.split()[1] for line in out.splitlines() if line.startswith("y_end")))
    assert y_end == pytest.approx(table.loc[table["point_id"] == point, "y_end"].item(), rel=1e-5)  # printed %g


def test_the_committed_full_study_is_a_sweep_folder_that_opens_without_spec(capsys):
    from cosim.analysis.rerun import load_rerun_spec
    from cosim.analysis.table import load_results
    from cosim.spec.loader import load_spec

    study = REPO / "examples" / "pick_and_place" / "study"
    table = load_results(study)
    assert len(table.df) == 17061 and table.spec is not None
    assert table.label("e_total") == "e_total [J]" and table.objective_senses() == {"e_total": "min"}
    # the metadata is the spec the table was made with, and still the committed spec.json
    assert table.metadata["spec_digest"] == load_spec(study.parent / "spec.json").digest
    assert load_rerun_spec(table, None).digest == table.metadata["spec_digest"]  # re-runs (explore) need no --spec
    assert main(["pareto", str(study), "--min", "e_total", "--min", "duration"]) == 0
    assert "Pareto front (min e_total, min duration): 1 of 17061 rows" in capsys.readouterr().out


def test_quiet_and_verbose_anywhere_on_the_command_line(write_spec, tmp_path, capsys, local_cluster):  # noqa: F811
    import logging

    from tests.helpers.tools import python_unit

    spec = str(write_spec({
        "name": "gain", "units": {"g": {"python": python_unit("LinearOde")}},
        "experiment": {"stop": 0.1, "step": 0.05},
        "objectives": {"y_end": {"signal": "g.y", "reduce": "final"}},
        "design": {"parameters": {"g.a": {"values": [-1.0, -2.0, -3.0]}}}}))
    assert main(["sweep", spec, "--out", str(tmp_path / "loud"), "--scheduler", local_cluster]) == 0
    loud = capsys.readouterr()
    assert "cosim sweep" in loud.err and "3 points" in loud.out  # the header line and the summary
    assert main(["sweep", spec, "--out", str(tmp_path / "quiet"), "--scheduler", local_cluster, "-q"]) == 0
    quiet = capsys.readouterr()
    assert quiet.err == "" and "3 points: 3 ok" in quiet.out  # the result, and nothing else
    assert pd.read_parquet(tmp_path / "quiet" / "results.parquet")["y_end"].tolist() == \
        pytest.approx([np.exp(a * 0.1) for a in (-1.0, -2.0, -3.0)], rel=1e-12)
    root = logging.getLogger().level
    try:
        assert main(["validate", spec, "-vv"]) == 0 and logging.getLogger("cosim").level == logging.DEBUG
        assert main(["--log-level", "info", "validate", spec]) == 0 and logging.getLogger("cosim").level == logging.INFO
    finally:
        logging.getLogger().setLevel(root)
        logging.getLogger("cosim").setLevel(logging.NOTSET)
    with pytest.raises(SystemExit) as exited:  # argparse: not allowed with each other
        main(["validate", spec, "-q", "-v"])
    assert exited.value.code == 2 and "not allowed with argument" in capsys.readouterr().err
