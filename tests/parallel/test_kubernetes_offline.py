"""The README's Kubernetes cluster file with the real dask-kubernetes, as far as it goes without a cluster.

No Kubernetes cluster can run here, and nothing is mocked: dask-kubernetes is
installed into a virtual environment of its own (it upgrades packages the
rest of the suite pins, so it is not in the test extra), the README's
``kube.yaml`` is read as printed, ``KubeCluster`` is constructed from it up
to its first contact with the Kubernetes API, and cosim must stop with exit
code 2, one message naming the file and the fix, and no traceback: once
without credentials, once with a real kubeconfig whose API server refuses the
connection.  Slow (the install takes a minute or more): ``python -m pytest -m
slow tests/parallel/test_kubernetes_offline.py``.
"""

from __future__ import annotations

import os
import re
import subprocess

import pytest

from tests.helpers.paths import REPO
from tests.helpers.sweep_fixtures import free_port
from tests.helpers.tools import venv_seeing_this_interpreter

KUBECONFIG = """apiVersion: v1
kind: Config
clusters:
- name: offline
  cluster: {{server: "https://127.0.0.1:{port}"}}
users:
- name: me
  user: {{token: "no-cluster-here"}}
contexts:
- name: offline
  context: {{cluster: offline, user: me, namespace: default}}
current-context: offline
"""


@pytest.fixture(scope="module")
def kubernetes_python(tmp_path_factory):
    """A Python with dask-kubernetes (the kubernetes extra's requirement) beside the suite's packages."""
    venv = tmp_path_factory.mktemp("kubernetes_venv")
    python = venv_seeing_this_interpreter(venv)
    install = subprocess.run([str(python), "-m", "pip", "install", "-q", "dask-kubernetes>=2024.1"],
                             capture_output=True, text=True, timeout=900)
    assert install.returncode == 0, install.stderr  # under CI too: the registry is reachable there
    return python


@pytest.mark.slow
@pytest.mark.parametrize("credentials", ["none", "kubeconfig of an unreachable API server"])
def test_the_readmes_kube_yaml_stops_with_one_message_before_any_cluster(tmp_path, kubernetes_python, credentials):
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    (block,) = [b for b in re.findall(r"```yaml\n(.*?)```", readme, re.S) if "# kube.yaml" in b]
    (tmp_path / "kube.yaml").write_text(block)
    home = tmp_path / "home"
    home.mkdir()
    env = {k: v for k, v in os.environ.items() if not k.startswith("KUBE")}
    env.update(HOME=str(home), PYTHONPATH=str(REPO))
    if credentials != "none":
        port = free_port()  # nothing listens there
        (tmp_path / "kubeconfig").write_text(KUBECONFIG.format(port=port))
        env["KUBECONFIG"] = str(tmp_path / "kubeconfig")
    done = subprocess.run([str(kubernetes_python), "-m", "cosim.cli.main", "sweep",
                           str(REPO / "examples" / "bouncing_ball" / "spec.json"), "--out", str(tmp_path / "out"),
                           "--cluster", str(tmp_path / "kube.yaml")], capture_output=True, text=True, env=env,
                          timeout=300)
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr + done.stdout
    assert f"{tmp_path / 'kube.yaml'}: kwargs: cannot start dask_kubernetes.operator.KubeCluster" in done.stderr
    if credentials == "none":
        assert "Unable to find valid credentials" in done.stderr and "credentials" in done.stderr
    else:
        assert f"ConnectionRefusedError: [Errno 111] Connect call failed ('127.0.0.1', {port})" in done.stderr
        assert "the Kubernetes API server of your kubeconfig" in done.stderr
    assert not (tmp_path / "out" / "results.parquet").exists()
