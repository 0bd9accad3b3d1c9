"""cosim sweep on real Dask: a LocalCluster, `dask scheduler` + `dask worker` processes, the CLI, resume."""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

import cosim
from cosim.cli.main import main
from cosim.cli.sweep import DRY_RUN_SAMPLES
from cosim.spec.design import DesignSpace
from cosim.spec.loader import load_spec
from cosim.studies.sweep import Sweep, SweepError
from tests.helpers.paths import HELPERS
from tests.helpers.tools import python_unit

STOP = 0.5


def ode_spec(fmu: str = "builtin:linear_ode_fmi3", step: float = 0.01, **design) -> dict:
    """x' = a x from x0 (u = 0): y(STOP) = x0 exp(a STOP) exactly, a check for every row."""
    return {
        "name": "ode_sweep",
        "units": {"ode": {"fmu": fmu}},
        "experiment": {"stop": STOP, "step": step},
        "objectives": {"y_end": {"signal": "ode.y", "reduce": "final"},
                       "y_max": {"signal": "ode.y", "reduce": "max"}},
        "design": design or {"parameters": {"ode.a": {"min": -2.0, "max": 0.0, "step": 0.5},
                                            "ode.x0": {"values": [1.0, 2.0]}}},
    }


def assert_exact(df: pd.DataFrame) -> None:
    assert (df["status"] == "ok").all(), df[df["status"] != "ok"][["status", "message"]]
    expected = df["ode.x0"] * (df["ode.a"] * STOP).map(math.exp)
    assert (df["y_end"] - expected).abs().max() < 1e-9
    assert (df["y_max"] - df["ode.x0"]).abs().max() < 1e-12  # a <= 0: the start is the maximum


def test_api_on_default_local_cluster_returns_every_point(write_spec, tmp_path):
    spec_path = write_spec(ode_spec())
    df = cosim.sweep(str(spec_path), workers=2, out=tmp_path / "out")
    ids = [p.id for p in DesignSpace.from_spec(load_spec(spec_path))]
    assert list(df["point_id"]) == ids  # every point once, in design order
    assert list(df.columns) == ["point_id", "ode.a", "ode.x0", "y_end", "y_max", "status", "message", "run_time",
                                "worker"]
    assert_exact(df)
    assert df["worker"].nunique() == 2 and (df["run_time"] > 0).all()
    stored = pd.read_parquet(tmp_path / "out" / "results.parquet")
    pd.testing.assert_frame_equal(stored, df)
    meta = json.loads((tmp_path / "out" / "metadata.json").read_text())
    assert meta["spec_digest"] == load_spec(spec_path).digest and meta["points"] == 10
    assert meta["counts"] == {"ok": 10, "failed": 0, "timeout": 0, "crashed": 0}
    assert len(meta["fmu_checksums"]["ode"]) == 64 and meta["packages"]["distributed"]
    assert meta["started"] <= meta["ended"]


def test_array_parameter_and_python_unit_on_local_cluster(write_spec, local_cluster):
    spec = {
        "units": {"clock": {"python": f"{HELPERS / 'units_for_tests.py'}:Clock"},
                  "gain": {"python": f"{HELPERS / 'units_for_tests.py'}:Gain"}},
        "connections": [{"from": "clock.time", "to": "gain.u"}],
        "experiment": {"stop": 1.0, "step": 0.1},
        "objectives": {"out": {"signal": "gain.y", "reduce": "final"}},
        "design": {"parameters": {"gain.k": {"min": 0.5, "max": 2.0, "step": 0.5}}, "constraint": "k != 1.5"},
    }
    df = cosim.sweep(str(write_spec(spec)), scheduler=local_cluster, batch_size=1)
    assert list(df["gain.k"]) == [0.5, 1.0, 2.0]
    assert (df["status"] == "ok").all() and list(df["out"]) == pytest.approx([0.5, 1.0, 2.0])


def test_remote_scheduler_and_workers_get_the_fmu_bytes(dask_processes, tmp_path, built_fmu):
    address, worker_dir = dask_processes
    study = tmp_path / "study"
    study.mkdir()
    shutil.copy(built_fmu("linear_ode", 2), study / "ode.fmu")
    shutil.copy(HELPERS / "units_for_tests.py", study / "my_units.py")
    spec = ode_spec(fmu="ode.fmu")
    spec["units"]["g"] = {"python": "my_units.py:Gain", "parameters": {"k": 3.0}}
    spec["connections"] = [{"from": "ode.y", "to": "g.u"}]
    spec["objectives"]["g_end"] = {"signal": "g.y", "reduce": "final"}
    spec_path = study / "spec.json"
    spec_path.write_text(json.dumps(spec))
    sweep = Sweep(spec_path, scheduler=address, out=tmp_path / "out", quiet=True)
    shutil.rmtree(study)  # from here on no process can read the FMU or unit file from the client's disk
    df = sweep.run()
    assert len(df) == 10 and df["worker"].nunique() == 2
    assert all(w.startswith("tcp://127.0.0.1:") and w != address for w in df["worker"])
    assert_exact(df)
    assert (df["g_end"] - 3.0 * df["y_end"]).abs().max() < 1e-12
    assert not list(worker_dir.glob("*.fmu"))  # the workers' folder got no copy by path either


def test_cli_exit_codes_and_dry_run(write_spec, tmp_path, capsys, local_cluster):
    spec_path = str(write_spec(ode_spec()))
    out = str(tmp_path / "cli_out")
    assert main(["sweep", spec_path, "--out", out, "--scheduler", local_cluster, "--csv"]) == 0
    assert len(pd.read_csv(Path(out) / "results.csv")) == 10
    assert main(["sweep", spec_path, "--out", out, "--scheduler", local_cluster]) == 2  # folder in use
    assert "--resume" in capsys.readouterr().err
    assert main(["sweep", spec_path, "--out", out, "--resume"]) == 0  # nothing left: no cluster needed
    assert main(["sweep", spec_path, "--dry-run"]) == 0
    text = capsys.readouterr().out
    assert "10 points" in text and "ode.a=-2.0, ode.x0=1.0" in text and "estimate:" in text
    # the sample runs are stratified over the space (issue 39; tests/spec/test_design.py checks the strata); a
    # space of 10 points has fewer than DRY_RUN_SAMPLES, so every point is a sample
    space = Sweep(spec_path, out=tmp_path / "z", quiet=True).space
    sampled = [line.split()[1].rstrip(":") for line in text.splitlines() if line.startswith("sample ")]
    assert sampled == [p.id for p in space.stratified(DRY_RUN_SAMPLES)] == [p.id for p in space]
    assert "range" in text.split("estimate: ")[1]
    assert main(["sweep", spec_path, "--out", str(tmp_path / "x"), "--timeout", "-1"]) == 2
    bad = write_spec({**ode_spec(), "design": {"parameters": {"ode.nope": {"values": [1]}}}}, "bad.json")
    assert main(["sweep", str(bad), "--out", str(tmp_path / "y")]) == 2
    assert "ode.nope" in capsys.readouterr().err


def test_resume_of_another_spec_is_refused(write_spec, tmp_path, local_cluster):
    out = tmp_path / "out"
    cosim.sweep(str(write_spec(ode_spec())), scheduler=local_cluster, out=out, quiet=True)
    other = write_spec(ode_spec(step=0.02), "other.json")
    with pytest.raises(SweepError, match="different spec"):
        Sweep(other, out=out, resume=True)


def test_resume_after_kill_9_of_the_client_runs_only_missing_points(write_spec, tmp_path):
    design = {"parameters": {"ode.a": {"min": -3.0, "max": 0.0, "step": 0.1}, "ode.x0": {"values": [1.0, 2.0]}}}
    spec_path = write_spec(ode_spec(step=0.0002, **design))  # 2500 steps a point: a sweep of a few seconds
    total = len(DesignSpace.from_spec(load_spec(spec_path)))
    out = tmp_path / "out"
    command = [sys.executable, "-m", "cosim.cli.main", "sweep", str(spec_path), "--out", str(out),
               "--workers", "2", "--batch-size", "2"]
    client = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.monotonic() + 60
    while len(list((out / "parts").glob("part-*.parquet"))) < 4:
        assert client.poll() is None, "the sweep ended before it could be killed"
        assert time.monotonic() < deadline
        time.sleep(0.05)
    os.kill(client.pid, signal.SIGKILL)  # kill -9 of the client itself...
    client.wait()
    time.sleep(0.5)
    try:
        os.killpg(client.pid, signal.SIGTERM)  # ...then its orphaned local cluster
    except ProcessLookupError:
        pass
    from cosim.results.store import ResultsStore

    before = ResultsStore(out).read()
    assert 0 < len(before) < total
    result = subprocess.run(command + ["--resume"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert f"({total - len(before)} to run)" in result.stderr
    df = pd.read_parquet(out / "results.parquet")
    ids = [p.id for p in DesignSpace.from_spec(load_spec(spec_path))]
    assert list(df["point_id"]) == ids  # no gaps, no duplicates, design order
    assert_exact(df)
    kept = df.set_index("point_id").loc[before["point_id"], "run_time"]
    assert list(kept) == list(before["run_time"])  # rows from before the kill were not recomputed
    assert len(json.loads((out / "metadata.json").read_text())["runs"]) == 2


def test_dry_run_estimate_counts_the_few_slow_points(write_spec, capsys):
    # 16 points of 10 steps each: the last 4 sleep 10x longer per step than the others. The median of the
    # samples would say 10 fast steps a point; the work is 12 fast and 4 slow points, 3.25x that. The 12
    # samples are stratified over s.delay (4 values: each value three times), so the slow value is sampled too
    fast, slow, steps = 0.004, 0.04, 10
    spec = write_spec({
        "name": "uneven",
        "units": {"s": {"python": python_unit("Sleeper")}},
        "experiment": {"stop": 1.0, "step": 1.0 / steps},
        "objectives": {"y_end": {"signal": "s.y", "reduce": "final"}},
        "design": {"parameters": {"s.delay": {"values": [fast, fast + 1e-4, fast + 2e-4, slow]},
                                  "s.gain": {"values": [1.0, 2.0, 3.0, 4.0]}}}})
    assert main(["sweep", str(spec), "--dry-run", "--workers", "1"]) == 0
    text = capsys.readouterr().out
    samples = [float(line.split(" in ")[1].split()[0]) for line in text.splitlines() if line.startswith("sample ")]
    per_point = float(text.split("estimate: ")[1].split()[0])
    # the mean of the samples (the warm-up run before them, which also loads the units, is not shown)
    assert len(samples) == 12 and per_point == pytest.approx(sum(samples) / 12, abs=1.5e-3)
    true_total = steps * (12 * fast + 4 * slow)  # the sleeps alone (the 1e-4 apart: each value once)
    assert 0.9 * true_total <= 16 * per_point <= 2.0 * true_total, (per_point, text)
    assert "about" in text and "on 1 worker(s)" in text and "differ more than 3x" in text


def test_a_spec_without_a_design_space_says_it_sweeps_one_point(write_spec, tmp_path, capsys, local_cluster):
    """Issue 39: a spec with no 'design' swept one point without a word; the sweep and its dry run say so."""
    spec = {key: value for key, value in ode_spec().items() if key != "design"}
    path = str(write_spec(spec, "single.json"))
    assert main(["sweep", path, "--out", str(tmp_path / "single"), "--scheduler", local_cluster]) == 0
    captured = capsys.readouterr()
    assert "1 points: 1 ok" in captured.out
    assert ("the spec has no design space (no 'design.parameters'): the sweep runs one point, the spec's values as "
            "written") in captured.err
    assert main(["sweep", path, "--dry-run"]) == 0
    assert capsys.readouterr().out.startswith("ode_sweep: 1 point: the spec has no design space")
    # a spec with a design space says nothing of the kind
    assert main(["sweep", str(write_spec(ode_spec(), "ten.json")), "--dry-run"]) == 0
    assert "no design space" not in capsys.readouterr().out


def test_sweep_takes_set_like_run(write_spec, tmp_path, capsys, local_cluster):
    """Issue 39: `cosim sweep --set UNIT.PARAM=VALUE` fixes a parameter for every point, as `cosim run --set`
    does for one: here x0 (a design parameter of 2 values) is set to 3, leaving the 5 values of a."""
    path = str(write_spec(ode_spec()))
    out = tmp_path / "set"
    assert main(["sweep", path, "--out", str(out), "--scheduler", local_cluster, "--set", "ode.x0=3", "-q"]) == 0
    table = pd.read_parquet(out / "results.parquet")
    assert len(table) == 5 and (table["status"] == "ok").all() and (table["ode.x0"] == 3.0).all()
    expected = [3.0 * math.exp(a * STOP) for a in table["ode.a"]]
    assert table["y_end"].tolist() == pytest.approx(expected, rel=1e-3)
    assert main(["sweep", path, "--set", "ode.x0=3", "--dry-run"]) == 0
    assert "5 points" in capsys.readouterr().out
    # a bad assignment is the user's mistake: exit 2, the fix named, no traceback
    assert main(["sweep", path, "--out", str(tmp_path / "bad"), "--set", "x0"]) == 2
    err = capsys.readouterr().err
    assert "--set 'x0': write UNIT.PARAM=VALUE" in err and "Traceback" not in err
