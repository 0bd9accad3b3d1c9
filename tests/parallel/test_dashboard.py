"""What the Dask dashboard and the worker logs show of a study: tasks named by the study and their points,
faults as rows (no traceback in any worker's log), the dashboard web server's errors as one line.

Real LocalCluster, real `dask scheduler` / `dask worker` processes (their stderr kept in files), the real fault
FMU (segfault, hang, error, NaN) and a Python unit that raises.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest
from dask.utils import key_split

import cosim
from cosim.parallel.dashboard.task_keys import payload_key, task_key
from tests.helpers.paths import HELPERS, REPO
from tests.helpers.sweep_fixtures import free_port, kill_group, wait_for_workers


def ode_spec(n: int) -> dict:
    return {
        "name": "dash-demo",
        "units": {"ode": {"fmu": "builtin:linear_ode_fmi3"}},
        "experiment": {"stop": 0.1, "step": 0.05},
        "objectives": {"y_end": {"signal": "ode.y", "reduce": "final"}},
        "design": {"parameters": {"ode.a": {"values": [-float(i) for i in range(n)]}}},
    }


def test_task_key_names_the_study_in_its_prefix_and_the_points_after_it():
    assert key_split(task_key("sweep", "my-study", [3, 4, 5], 40)) == "cosim sweep my_study"
    assert task_key("sweep", "s", [3, 4, 5], 40).startswith("cosim sweep s-points 4..6 of 40-")
    assert task_key("sweep", "s", [7], 40).startswith("cosim sweep s-point 8 of 40-")
    assert task_key("optimize", "s", [0, 2, 9], 10).startswith("cosim optimize s-3 points from 1 of 10-")
    assert task_key("sweep", "s", [1], 2) != task_key("sweep", "s", [1], 2)  # a point run again is a new task


def test_the_dashboard_shows_one_progress_bar_per_sweep_and_each_task_names_its_points(write_spec, local_cluster):
    from distributed import Client, get_task_stream

    with Client(local_cluster) as client, get_task_stream(client) as stream:
        df = cosim.sweep(str(write_spec(ode_spec(7))), scheduler=local_cluster, batch_size=3, quiet=True)
        time.sleep(1)  # the task stream plugin hears of the last task a moment after the sweep has its row
    assert (df["status"] == "ok").all()
    keys = sorted(str(task["key"]) for task in stream.data)
    assert {key_split(k) for k in keys} == {"cosim sweep dash_demo"}  # the progress bar's name
    assert [k.split("-")[1] for k in keys] == ["point 7 of 7", "points 1..3 of 7", "points 4..6 of 7"]


def test_the_payload_is_one_piece_of_data_named_after_the_study(local_cluster):
    """Issue 39: a study's payload was scattered as a dict, which Dask keeps as one key per entry: the dashboard
    showed data named 'key', 'system', 'files' and 'limits'. Now it is one key named for people."""
    from distributed import Client

    from cosim.parallel.scattered import ScatteredPayload

    payload = {"key": "k1", "system": {"units": 3}, "files": {"a.py": b"x = 1"}, "limits": {}}
    with Client(local_cluster) as client:
        scattered = ScatteredPayload(client, payload, payload_key("sweep", "my-study"))
        future = scattered.future()
        held = client.run_on_scheduler(lambda dask_scheduler: [str(k) for k in dask_scheduler.tasks])
        ours = [k for k in held if k.startswith("cosim ")]
        assert [key_split(k) for k in ours] == ["cosim sweep my_study system and unit files"]
        assert not {"key", "system", "files", "limits"} & {key_split(k) for k in held}
        assert client.submit(lambda p: p, future, pure=False).result() == payload  # a task gets the whole dict
        assert scattered.future() is future  # kept while alive: scattered once
        scattered.release()
        deadline = time.monotonic() + 10
        while ours[0] in client.run_on_scheduler(lambda dask_scheduler: [str(k) for k in dask_scheduler.tasks]):
            assert time.monotonic() < deadline, "the released payload stayed on the scheduler"
            time.sleep(0.1)
    assert key_split(payload_key("", "")) == "cosim system and unit files"


@pytest.fixture
def logged_workers(tmp_path):
    """`dask scheduler` and 2 `dask worker` processes whose stderr (their log) goes to files; yields (address, logs)."""
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    logs = [tmp_path / "scheduler.log", tmp_path / "workers.log"]
    handles = [open(path, "wb") for path in logs]
    scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                  "--port", str(port), "--no-dashboard"], stdout=handles[0], stderr=handles[0],
                                 start_new_session=True)
    workers = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nworkers", "2",
                                "--nthreads", "1", "--no-dashboard", "--host", "127.0.0.1"], cwd=tmp_path,
                               stdout=handles[1], stderr=handles[1], start_new_session=True)
    try:
        wait_for_workers(address, 2, seconds=90)
        yield address, logs
    finally:
        kill_group(workers)
        kill_group(scheduler)
        for handle in handles:
            handle.close()


def test_failing_points_are_rows_and_leave_no_traceback_in_any_log(write_spec, logged_workers, capfd):
    address, logs = logged_workers
    faults = {
        "name": "faults",
        "units": {"f": {"fmu": "builtin:fault_fmi2"}},
        "experiment": {"stop": 0.2, "step": 0.01},
        "objectives": {"t_end": {"signal": "f.y", "reduce": "final"}},
        # ok, segfault, hang, FMI error, NaN
        "design": {"parameters": {"f.mode": {"values": [0, 1, 2, 3, 4]}, "f.trigger_time": {"values": [0.05]}}},
    }
    raising = {
        "name": "raising",
        "units": {"bad": {"python": f"{HELPERS / 'units_for_tests.py'}:Failing"}},
        "experiment": {"stop": 1.0, "step": 0.1},
        "objectives": {"y_end": {"signal": "bad.y", "reduce": "final"}},
        "design": {"parameters": {"bad.fail_at": {"values": [0.35, 5.0, 0.05]}}},
    }
    df = cosim.sweep(str(write_spec(faults, "faults.json")), scheduler=address, timeout=1.5, batch_size=2,
                            quiet=True)
    assert list(df["status"]) == ["ok", "crashed", "timeout", "failed", "failed"]
    df = cosim.sweep(str(write_spec(raising, "raising.json")), scheduler=address, quiet=True)
    assert list(df["status"]) == ["failed", "ok", "failed"]
    assert "boom" in df.loc[0, "message"]
    from distributed import Client

    with Client(address, timeout=10) as client:
        in_memory = [line for records in client.get_worker_logs().values() for _, line in records]
        in_memory += [line for _, line in client.get_scheduler_logs()]
    time.sleep(0.5)  # let the processes flush their stderr
    for path in logs:
        text = path.read_text(errors="replace")
        assert "Traceback" not in text, f"{path.name}:\n{text[-3000:]}"
        assert "boom" not in text, f"{path.name}:\n{text[-3000:]}"
    assert not [line for line in in_memory if "Traceback" in line or "boom" in line]
    assert "Traceback" not in capfd.readouterr().err


DASHBOARD_SCRIPT = """
import sys, urllib.error, urllib.request
from cosim.parallel.cluster.choice import choose_cluster
from cosim.parallel.cluster.client import dask_client

if __name__ == "__main__":
    with dask_client(choose_cluster(1)) as (_, _, link):
        urllib.request.urlopen(link, timeout=60).read()  # the dashboard is loaded when first opened
        try:
            status = urllib.request.urlopen(link.rsplit("/", 1)[0] + "/sitemap.json", timeout=30).status
        except urllib.error.HTTPError as exc:
            status = exc.code
    print(status)
"""


def test_the_dashboards_web_server_errors_are_one_line_on_the_terminal(tmp_path):
    """The terminal of a cosim process whose local cluster's dashboard hits an error in a page handler."""
    pytest.importorskip("bokeh", reason="distributed serves its dashboard only with bokeh (an optional extra)")
    script = tmp_path / "dashboard_error.py"
    script.write_text(DASHBOARD_SCRIPT)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=180,
                          env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert done.returncode == 0, done.stderr
    if done.stdout.strip() != "500":
        pytest.skip(f"GET /sitemap.json no longer fails in this distributed version (HTTP {done.stdout.strip()}): "
                    "no page error to show")
    assert "Uncaught exception GET /sitemap.json" in done.stderr and "KeyError" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr, done.stderr
