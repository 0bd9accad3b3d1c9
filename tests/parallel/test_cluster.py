"""`--cluster FILE`: any Dask cluster class by configuration; DASK_SCHEDULER_ADDRESS; clear cluster-file errors.

Real clusters only: distributed.LocalCluster, a SpecCluster of separately
started worker processes (distributed's SubprocessCluster) and dask-jobqueue's
own test mode (real job scripts run by bash instead of a batch system).
"""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys

import pandas as pd
import pytest

import cosim
from cosim.cli.main import main
from cosim.errors import ClusterFileError
from cosim.parallel.cluster.cluster_file import read_cluster_file
from cosim.studies.sweep import SweepError
from tests.helpers.paths import REPO

STOP = 0.5


def ode_spec() -> dict:
    """x' = a x from x0 = 1: y(STOP) = exp(a STOP), checked for every row."""
    return {
        "name": "ode_cluster",
        "units": {"ode": {"fmu": "builtin:linear_ode_fmi3"}},
        "experiment": {"stop": STOP, "step": 0.01},
        "objectives": {"y_end": {"signal": "ode.y", "reduce": "final"}},
        "design": {"parameters": {"ode.a": {"values": [-2.0, -1.0, -0.5, 0.0]}}},
    }


def assert_exact(df: pd.DataFrame) -> None:
    assert len(df) == 4 and df["point_id"].is_unique
    assert (df["status"] == "ok").all(), df[["status", "message"]]
    assert (df["y_end"] - (df["ode.a"] * STOP).map(math.exp)).abs().max() < 1e-9


def readme_cluster_file(name: str) -> str:
    """The README's cluster-file example whose first line is ``# NAME: ...``."""
    blocks = re.findall(r"```yaml\n(.*?)```", (REPO / "README.md").read_text(encoding="utf-8"), re.S)
    (block,) = [b for b in blocks if b.startswith(f"# {name}:")]
    return block


def write(tmp_path, name: str, text: str):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_cluster_file_with_local_cluster_through_the_cli(write_spec, tmp_path, capsys):
    spec = write_spec(ode_spec())
    cluster = write(tmp_path, "cluster.yaml", "type: distributed.LocalCluster\n"
                    "kwargs: {n_workers: 2, threads_per_worker: 1, host: 127.0.0.1, dashboard_address: ':0'}\n")
    out = tmp_path / "out"
    assert main(["sweep", str(spec), "--out", str(out), "--cluster", str(cluster)]) == 0
    df = pd.read_parquet(out / "results.parquet")
    assert_exact(df)
    run = json.loads((out / "metadata.json").read_text())["runs"][-1]
    assert run["workers"] == 2 and run["scheduler"].startswith("tcp://127.0.0.1:")


def test_spec_cluster_of_separate_worker_processes_json_file(write_spec, tmp_path):
    spec = write_spec(ode_spec())
    cluster = write(tmp_path, "cluster.json", json.dumps({
        "type": "distributed.deploy.subprocess.SubprocessCluster",
        "kwargs": {"n_workers": 0, "threads_per_worker": 1, "dashboard_address": None},
        "scale": {"n": 2}}))
    df = cosim.sweep(str(spec), cluster=cluster, quiet=True)
    assert_exact(df)
    assert df["worker"].str.startswith("tcp://127.0.0.1:").all()


def test_dask_jobqueue_in_its_test_mode_and_a_slurm_job_script(write_spec, tmp_path):
    if os.environ.get("CI") != "true":
        pytest.importorskip("dask_jobqueue", reason="the optional extra cosim[jobqueue] is not installed")
    spec = write_spec(ode_spec())
    # the same classes as on a real queue: jobs are bash scripts here instead of sbatch submissions
    cluster = write(tmp_path, "jobqueue.yaml", "type: dask_jobqueue.local.LocalCluster\n"
                    "kwargs: {cores: 1, memory: 1GB, processes: 1, scheduler_options: {dashboard_address: ':0'}}\n"
                    "scale: {jobs: 2}\n")
    df = cosim.sweep(str(spec), cluster=cluster, quiet=True)
    assert_exact(df)
    # the README's Slurm recipe: a real SLURMCluster renders its sbatch script from the file's kwargs
    from cosim.parallel.cluster.cluster_file import import_cluster_class

    slurm = read_cluster_file(write(tmp_path, "slurm.yaml", readme_cluster_file("slurm.yaml")))
    with import_cluster_class(slurm)(**slurm.kwargs) as made:
        script = made.job_script()
    assert "#SBATCH -p short" in script and "#SBATCH -t 01:00:00" in script and "--nthreads 1" in script


def test_dask_scheduler_address_is_honoured(write_spec, local_cluster, monkeypatch, tmp_path):
    spec = write_spec(ode_spec())
    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", local_cluster)
    cosim.sweep(str(spec), out=tmp_path / "out", quiet=True)
    assert json.loads((tmp_path / "out" / "metadata.json").read_text())["runs"][-1]["scheduler"] == local_cluster
    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", "tcp://127.0.0.1:9")  # nothing listens there
    with pytest.raises(SweepError, match="DASK_SCHEDULER_ADDRESS"):
        cosim.sweep(str(spec), quiet=True)


@pytest.mark.parametrize("text, field, fragment", [
    ("type: distributed.NoSuchCluster\n", "type", "cluster classes there: "),
    ("type: dask_kubernetes.operator.KubeCluster\n", "type", "cosim[kubernetes]"),
    ("type: LocalCluster\n", "type", "import path"),
    ("type: distributed.LocalCluster\nscale: {jobs: -1}\n", "scale.jobs", "whole number"),
    ("type: distributed.LocalCluster\nscale: {jobs: 1, n: 2}\n", "scale", "exactly one"),
    ("type: distributed.LocalCluster\nscale: {n: 1}\nadapt: {maximum: 2}\n", "adapt", "not both"),
    ("type: distributed.LocalCluster\nadapt: {minimum: 3, maximum: 2}\n", "adapt", "minimum <= maximum"),
    ("type: distributed.LocalCluster\nworkers: 3\n", "workers", "only 'type'"),
    ("type: distributed.LocalCluster\nkwargs: [1, 2]\n", "kwargs", "mapping"),
    ("type: [unclosed\n", "line 2, column 1", "syntax"),
])
def test_cluster_file_mistakes_exit_2_with_file_field_and_fix(write_spec, tmp_path, capsys, text, field,
                                                              fragment):
    if "kubernetes" in text:
        try:
            import dask_kubernetes  # noqa: F401
            pytest.skip("dask-kubernetes is installed here: the missing-extra message cannot be shown")
        except ImportError:
            pass
    spec = write_spec(ode_spec())
    cluster = write(tmp_path, "cluster.yaml", text)
    assert main(["sweep", str(spec), "--out", str(tmp_path / "out"), "--cluster", str(cluster)]) == 2
    err = capsys.readouterr().err
    assert f"cluster.yaml: {field}" in err and fragment in err and "fix:" in err
    assert "Traceback" not in err


def test_bad_kwargs_are_reported_with_dasks_reason_and_no_traceback(write_spec, tmp_path, capfd):
    spec = write_spec(ode_spec())
    cluster = write(tmp_path, "cluster.yaml", "type: distributed.LocalCluster\n"
                    "kwargs: {n_workers: 1, no_such_option: 3}\n")
    assert main(["sweep", str(spec), "--out", str(tmp_path / "out"), "--cluster", str(cluster)]) == 2
    err = capfd.readouterr().err
    assert "cluster.yaml: kwargs:" in err and "no_such_option" in err and "fix:" in err
    assert "Traceback" not in err


def test_cluster_and_scheduler_together_are_refused(write_spec, tmp_path, capsys):
    spec = write_spec(ode_spec())
    cluster = write(tmp_path, "cluster.yaml", "type: distributed.LocalCluster\n")
    with pytest.raises(SystemExit) as stop:
        main(["sweep", str(spec), "--cluster", str(cluster), "--scheduler", "tcp://127.0.0.1:9"])
    assert stop.value.code == 2 and "not allowed with argument" in capsys.readouterr().err
    with pytest.raises(ClusterFileError, match="cannot read the cluster file"):
        read_cluster_file(tmp_path / "missing.yaml")


def test_the_readme_kubernetes_file_is_accepted_and_fails_cleanly_without_kubernetes(write_spec, tmp_path):
    """No Kubernetes cluster here: the README's file is read and checked as --cluster reads it, then its start
    fails with one message (no credentials, or dask-kubernetes not installed), exit 2, no traceback."""
    from cosim.parallel.cluster.cluster_file import import_cluster_class
    from cosim.parallel.cluster.local import ALLOWED_FAILURES

    kube = write(tmp_path, "kube.yaml", readme_cluster_file("kube.yaml"))
    config = read_cluster_file(kube)
    assert config.type == "dask_kubernetes.operator.KubeCluster" and config.adapt == {"minimum": 2, "maximum": 50}
    assert config.kwargs["worker_command"].split()[-2:] == ["--nthreads", "1"]
    assert config.kwargs["env"] == {"DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": str(ALLOWED_FAILURES)}
    spec = write_spec(ode_spec())
    done = subprocess.run([sys.executable, "-m", "cosim.cli.main", "sweep", str(spec), "--cluster", str(kube)],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path,
                          env={k: v for k, v in os.environ.items() if not k.startswith("KUBE")})
    assert done.returncode == 2, done.stderr
    assert "kube.yaml:" in done.stderr and "fix:" in done.stderr
    assert "Traceback" not in done.stderr, done.stderr
    try:
        import dask_kubernetes  # noqa: F401
    except ImportError:
        assert "cosim[kubernetes]" in done.stderr
        return
    import inspect

    inspect.signature(import_cluster_class(config)).bind(**config.kwargs)  # every keyword is one KubeCluster takes
    assert "cannot start dask_kubernetes.operator.KubeCluster" in done.stderr


def test_closing_hushes_only_the_batched_send_that_closing_cut_off(caplog):
    # Dask logs a batched message its own teardown cut off at INFO with a CommClosedError traceback, from its
    # event loop's thread, also after the close returned: it reached the terminal above cosim's message
    import logging

    from cosim.parallel.cluster.closing import _hush_batched_sends_cut_off_by_closing

    batched = logging.getLogger("distributed.batched")
    _hush_batched_sends_cut_off_by_closing()
    _hush_batched_sends_cut_off_by_closing()  # once per process, however many studies close
    assert sum(type(f).__name__ == "_CutOffBatchedSend" for f in batched.filters) == 1
    with caplog.at_level(logging.INFO, logger="distributed.batched"):
        batched.info("Batched Comm Closed %r", "<InProc local=inproc://x>", exc_info=False)
        batched.error("Error in batched write")
    assert [r.getMessage() for r in caplog.records if r.name == "distributed.batched"] == ["Error in batched write"]
