"""`cosim run SPEC --point ID`: re-running a design point of a sweep with traces; the analysis on a real sweep."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from cosim.analysis.rerun import point_values
from cosim.analysis.table import load_results
from cosim.cli.main import main
from tests.analysis.test_analysis_explorer import linear_ode_sweep
from tests.helpers.tools import python_unit


def objectives_printed(out: str) -> dict[str, float]:
    """The objective table `cosim run` prints (values with 6 significant digits)."""
    lines = out.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("objective"))
    rows = {}
    for line in lines[start + 1:]:
        if line.startswith("status"):
            break
        parts = line.split()
        rows[parts[0]] = float(parts[1])
    return rows


def test_run_point_from_a_table_records_every_output(tmp_path, write_spec, capsys):
    table = linear_ode_sweep(tmp_path / "decay", write_spec)
    spec = tmp_path / "spec.json"
    assert main(["run", str(spec), "--point", "pb", "--results", str(table)]) == 0
    out = capsys.readouterr().out
    assert "point pb: ode.a=-1.0" in out
    assert objectives_printed(out)["y_end"] == pytest.approx(np.exp(-1.0), rel=1e-5)
    traces = pd.read_parquet(tmp_path / "decay" / "points" / "pb.parquet")
    assert list(traces.columns) == ["time", "ode.y"] and len(traces) == 101
    assert traces["ode.y"].iloc[-1] == pytest.approx(np.exp(-1.0), rel=1e-9)
    # --set still wins over the point's value; --out chooses the file
    assert main(["run", str(spec), "--point", "pa", "--results", str(table.parent), "--set", "ode.x0=2",
                 "--out", str(tmp_path / "pa.csv")]) == 0
    assert objectives_printed(capsys.readouterr().out)["y_end"] == pytest.approx(2 * np.exp(-2.0), rel=1e-5)
    assert pd.read_csv(tmp_path / "pa.csv")["ode.y"].iloc[0] == pytest.approx(2.0)


def test_run_point_finds_the_default_results_folder(tmp_path, write_spec, capsys, monkeypatch):
    linear_ode_sweep(tmp_path / "results" / "decay", write_spec)
    monkeypatch.chdir(tmp_path)
    assert main(["run", "spec.json", "--point", "pc"]) == 0
    assert objectives_printed(capsys.readouterr().out)["y_end"] == pytest.approx(np.exp(-0.5), rel=1e-5)
    assert (tmp_path / "results" / "decay" / "points" / "pc.parquet").exists()


def test_run_point_mistakes_exit_2(tmp_path, write_spec, capsys, monkeypatch):
    table = linear_ode_sweep(tmp_path / "decay", write_spec)
    spec = str(tmp_path / "spec.json")
    assert main(["run", spec, "--point", "pz", "--results", str(table)]) == 2
    assert "no point 'pz'" in capsys.readouterr().err
    monkeypatch.chdir(tmp_path / "decay")
    assert main(["run", spec, "--point", "pa"]) == 2
    err = capsys.readouterr().err
    assert "no results table found" in err and "--results" in err and "Traceback" not in err


def test_point_values_reassemble_array_parameters(tmp_path):
    path = tmp_path / "t.parquet"
    pd.DataFrame({"point_id": ["a"], "traj.q[1]": [1.0], "traj.q[3]": [3.0], "traj.q[2]": [2.0], "k": [np.int64(4)],
                  "flag": [True]}).to_parquet(path)
    values = point_values(load_results(path), 0, ["traj.q", "k", "flag"])
    assert values == {"traj.q": [1.0, 2.0, 3.0], "k": 4, "flag": True}
    assert type(values["k"]) is int


def test_analysis_of_a_real_sweep(tmp_path, write_spec, capsys):
    """A real `cosim sweep` table: pareto, report and run --point agree with it."""
    import cosim

    spec = {"name": "decay2", "units": {"ode": {"python": python_unit("LinearOde")}},
            "experiment": {"start": 0.0, "stop": 1.0, "step": 0.05}, "record": ["ode.y"],
            "objectives": {"y_end": {"signal": "ode.y", "reduce": "final", "unit": "V", "sense": "minimize"},
                           "y_mean": {"signal": "ode.y", "reduce": "mean", "unit": "V", "sense": "maximize"}},
            "design": {"parameters": {"ode.a": {"min": -2.0, "max": 0.0, "step": 0.5, "unit": "1/s"},
                                      "ode.x0": {"values": [1.0, 2.0]}}}}
    spec_path = write_spec(spec)
    out = tmp_path / "sweep"
    df = cosim.sweep(str(spec_path), workers=1, out=out, quiet=True)
    assert len(df) == 10 and (df["status"] == "ok").all()
    table = load_results(out)
    assert table.label("ode.a") == "ode.a [1/s]" and table.objective_senses() == {"y_end": "min", "y_mean": "max"}
    # minimizing y_end = x0 exp(a) and maximizing its mean conflict along a; x0 = 1 vs 2 also trades off
    assert main(["pareto", str(out)]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    front_size = int(first.split(": ")[1].split(" of ")[0])
    assert first.endswith("of 10 rows") and 2 <= front_size <= 10
    row = df.iloc[3]
    assert main(["run", str(spec_path), "--point", row["point_id"], "--results", str(out)]) == 0
    printed = objectives_printed(capsys.readouterr().out)
    assert printed["y_end"] == pytest.approx(row["y_end"], rel=1e-5)
    assert main(["report", str(out), "-o", str(tmp_path / "r.html")]) == 0
    text = (tmp_path / "r.html").read_text()
    assert f"{front_size} non-dominated of 10 ok rows" in text
    assert json.loads((out / "metadata.json").read_text())["spec_path"]


def test_spec_option_stands_in_for_missing_metadata(tmp_path, write_spec, capsys):
    from cosim.analysis.rerun import rerun

    table_path = linear_ode_sweep(tmp_path / "decay", write_spec)
    (tmp_path / "decay" / "metadata.json").unlink()
    spec = str(tmp_path / "spec.json")
    assert load_results(table_path).objective_senses() == {}
    table = load_results(table_path, spec)
    assert table.objective_senses() == {"y_end": "min"} and table.label("y_end") == "y_end [1]"
    result, values = rerun(table, 2)
    assert values == {"ode.a": -0.5} and result.traces["ode.y"].iloc[-1] == pytest.approx(np.exp(-0.5), rel=1e-9)
    assert main(["pareto", str(table_path), "--spec", spec]) == 0
    assert "Pareto front (min y_end): 1 of 3 rows" in capsys.readouterr().out
    # a plot of the front needs two objectives: said before any work is done
    assert main(["pareto", str(table_path), "--spec", spec, "--plot", str(tmp_path / "f.png")]) == 2
    assert "needs at least two objectives" in capsys.readouterr().err and not (tmp_path / "f.png").exists()
    assert main(["plot", str(table_path), "--spec", str(tmp_path / "nope.json"), "--x", "ode.a", "--y", "y_end",
                 "-o", str(tmp_path / "g.png")]) == 2
    assert "file not found" in capsys.readouterr().err


def test_run_point_loads_the_spec_once_and_builds_the_system_once(tmp_path, write_spec, capsys, monkeypatch):
    import cosim.spec.loader
    import cosim.system.builder
    import cosim.system.validate

    table = linear_ode_sweep(tmp_path / "decay", write_spec)
    calls = {"load": 0, "build": 0, "describe": 0}

    def counted(name, fn):
        def wrapper(*args, **kwargs):
            calls[name] += 1
            return fn(*args, **kwargs)
        return wrapper

    load, build = counted("load", cosim.spec.loader.load_spec), counted("build", cosim.system.builder.build_system)
    for module in (cosim.spec.loader, cosim.system.validate):
        monkeypatch.setattr(module, "load_spec", load)
    for module in (cosim.system.builder, cosim.system.validate):
        monkeypatch.setattr(module, "build_system", build)
    from cosim.units.python.unit import PythonUnitType

    monkeypatch.setattr(PythonUnitType, "describe", counted("describe", PythonUnitType.describe))
    assert main(["run", str(tmp_path / "spec.json"), "--point", "pb", "--results", str(table)]) == 0
    assert calls == {"load": 1, "build": 1, "describe": 1}
    assert objectives_printed(capsys.readouterr().out)["y_end"] == pytest.approx(np.exp(-1.0), rel=1e-5)


def test_every_caller_runs_a_point_through_run_point(tmp_path, write_spec, monkeypatch):
    """cosim.run, cosim run (with --set and --point), the re-run of a row and the sweep's child: one pipeline."""
    import cosim
    import cosim.execution.point
    from cosim.analysis.rerun import rerun
    from cosim.parallel.isolation.point_runner import PointRunner
    from cosim.system.validate import check_spec

    table_path = linear_ode_sweep(tmp_path / "decay", write_spec)
    spec = str(tmp_path / "spec.json")
    seen = []
    real = cosim.execution.point.run_point

    def spy(system, values=None, **kwargs):
        seen.append(dict(values or {}))
        return real(system, values, **kwargs)

    monkeypatch.setattr(cosim.execution.point, "run_point", spy)
    assert cosim.run(spec, {"ode.a": -2.0}).objectives["y_end"] == pytest.approx(np.exp(-2.0), rel=1e-5)
    assert main(["run", spec, "--set", "ode.a=-0.5"]) == 0
    assert main(["run", spec, "--point", "pb", "--results", str(table_path)]) == 0
    result, _ = rerun(load_results(table_path), 0)
    assert result.ok and list(result.traces.columns) == ["time", "ode.y"]
    row = PointRunner(check_spec(spec)).run("p", {"ode.a": -1.5})
    assert row.status == "ok" and row.objectives["y_end"] == pytest.approx(np.exp(-1.5), rel=1e-5)
    assert seen == [{"ode.a": -2.0}, {"ode.a": -0.5}, {"ode.a": -1.0}, {"ode.a": -2.0}, {"ode.a": -1.5}]
