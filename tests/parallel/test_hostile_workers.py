"""Units that misbehave inside a sweep's worker children: junk on the channel to the worker, memory
leaks and hogs, hangs without a --timeout.  Rows out = points in, and nothing hangs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from cosim.parallel.isolation.payload import make_payload
from cosim.parallel.isolation.runner import IsolatedRunner
from cosim.studies.sweep import Sweep
from cosim.system.validate import check_spec
from tests.helpers.paths import REPO

UNIT = '''
import os, pickle, struct, sys, time
from cosim import PythonUnit, Variable

_LEAK = []

class Misbehave(PythonUnit):
    """mode 0 behaves; 1-3 write junk into the channel to the worker; 4 leaks 60 MB a point;
    5 allocates 2 GB once; 6 hangs."""

    variables = (Variable("mode", "parameter", type="Integer", start=0), Variable("k", "parameter", start=1.0),
                 Variable("pid", "output", start=0.0), Variable("y", "output", start=0.0))

    def do_step(self, t, h):
        channel = int(sys.argv[2])  # the child's pipe to its worker (see cosim.parallel.isolation)
        if self.mode == 1:
            os.write(channel, b"\\xff\\xff\\xff\\x7fjunk")  # a length header of 2 GB
        elif self.mode == 2:
            os.write(channel, struct.pack("!i", 100000) + b"short")  # a message that never completes
        elif self.mode == 3:
            data = pickle.dumps(("nonsense", 1))
            os.write(channel, struct.pack("!i", len(data)) + data)  # well-formed, but not a row
        elif self.mode == 4:
            _LEAK.append(b"x" * (60 << 20))
        elif self.mode == 5:
            big = b"x" * (2 << 30)
        elif self.mode == 6:
            time.sleep(3600)
        self.pid = float(os.getpid())
        self.y = 3.0 * self.k
'''


def _spec(tmp_path: Path, values: list, extra: dict | None = None) -> Path:
    (tmp_path / "misbehave.py").write_text(UNIT)
    spec = {"units": {"m": {"python": "misbehave.py:Misbehave"}}, "experiment": {"stop": 0.1, "step": 0.1},
            "objectives": {"y": {"signal": "m.y", "reduce": "final"}, "pid": {"signal": "m.pid", "reduce": "final"}},
            "design": {"parameters": {"m.mode": {"values": values}}}}
    spec.update(extra or {})
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(spec))
    return path


def _points(modes: list[int]) -> list[tuple[str, dict]]:
    return [(f"p{i}", {"m.mode": mode, "m.k": float(i)}) for i, mode in enumerate(modes)]


def _run(tmp_path: Path, modes: list[int], timeout: float | None, env: dict | None = None,
         monkeypatch=None) -> list[dict]:
    for key, value in (env or {}).items():
        monkeypatch.setenv(key, value)
    payload = make_payload(check_spec(_spec(tmp_path, [0, 1])))  # the limits travel with the payload
    runner = IsolatedRunner(payload)
    try:
        return runner.run(_points(modes), timeout)
    finally:
        runner.close()


def test_junk_on_the_channel_costs_one_point_and_never_hangs(tmp_path, monkeypatch):
    modes = [0, 1, 0, 2, 0, 3, 0]
    rows = _run(tmp_path, modes, timeout=10, monkeypatch=monkeypatch)
    assert [r.point_id for r in rows] == [f"p{i}" for i in range(7)]
    statuses = [r.status for r in rows]
    assert statuses[1] == "crashed" and statuses[5] == "crashed" and statuses[3] in ("crashed", "timeout")
    assert "other than a result on its channel" in rows[1].message
    for i in (0, 2, 4, 6):  # a fresh child took over after each broken one
        assert statuses[i] == "ok" and rows[i].objectives["y"] == 3.0 * i
    assert len({rows[i].objectives["pid"] for i in (0, 2, 4, 6)}) == 4


def test_junk_in_a_real_sweep_keeps_rows_in_equal_rows_out(tmp_path, local_cluster):
    spec = _spec(tmp_path, [0, 1, 2, 3, 10, 11, 12])  # modes 10-12 behave like 0
    table = Sweep(spec, out=tmp_path / "out", scheduler=local_cluster, timeout=10, batch_size=7, quiet=True).run()
    assert len(table) == 7
    by_mode = dict(zip(table["m.mode"], table["status"]))
    assert by_mode[0] == by_mode[10] == by_mode[11] == by_mode[12] == "ok"
    assert by_mode[1] == by_mode[3] == "crashed" and by_mode[2] in ("crashed", "timeout")


def test_a_leaking_child_is_recycled_by_its_resident_memory(tmp_path, monkeypatch):
    rows = _run(tmp_path, [4] * 10, timeout=60, env={"COSIM_CHILD_RSS_MB": "400"}, monkeypatch=monkeypatch)
    assert all(r.status == "ok" for r in rows), [r.message for r in rows]
    pids = [r.objectives["pid"] for r in rows]
    assert len(set(pids)) >= 2  # 10 x 60 MB would be 600 MB in one child
    for pid in set(pids):
        # 60 MB more per point, recycled above 400 MB: after the 7th point at the latest, whatever the child held
        # to start with (about 100-150 MB; less since the children no longer import jsonschema)
        assert pids.count(pid) <= 7


def test_a_child_is_recycled_after_n_points(tmp_path, monkeypatch):
    rows = _run(tmp_path, [0] * 6, timeout=60, env={"COSIM_CHILD_POINTS": "2"}, monkeypatch=monkeypatch)
    pids = [r.objectives["pid"] for r in rows]
    assert all(r.status == "ok" for r in rows)
    assert pids[0] == pids[1] != pids[2] == pids[3] != pids[4] == pids[5] and len(set(pids)) == 3


def test_the_memory_limit_of_a_child_fails_the_point_not_the_machine(tmp_path, monkeypatch):
    rows = _run(tmp_path, [0, 5, 0], timeout=60, env={"COSIM_CHILD_MEMORY_MB": "1024"}, monkeypatch=monkeypatch)
    assert [r.status for r in rows] == ["ok", "failed", "ok"]
    assert "MemoryError" in rows[1].message


def _cosim(*args: str, env: dict, timeout: float = 180) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cosim.cli.main", *args], capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=str(REPO), **env), timeout=timeout)


def test_a_hanging_point_without_timeout_ends_by_the_default(tmp_path):
    spec = _spec(tmp_path, [0, 6, 10])
    done = _cosim("sweep", str(spec), "--out", str(tmp_path / "out"), "--workers", "1",
                  env={"COSIM_TIMEOUT_FIRST": "3"})
    assert done.returncode == 1, done.stderr
    assert "timeout: no result within the timeout of 3 s" in done.stderr and "2 ok, 1 timeout" in done.stdout


def test_the_default_timeout_follows_the_measured_point_time(tmp_path):
    spec = _spec(tmp_path, [0, 10, 11, 12, 13, 14, 15, 16, 17, 6])  # the last point hangs
    done = _cosim("sweep", str(spec), "--out", str(tmp_path / "out"), "--workers", "1", "--batch-size", "1",
                  env={"COSIM_TIMEOUT_FLOOR": "2", "COSIM_TIMEOUT_FIRST": "600"})
    assert done.returncode == 1, done.stderr
    assert "9 ok, 1 timeout" in done.stdout and "within the timeout of 2 s" in done.stderr
    well_behaved = tmp_path / "well_behaved"  # the dry run samples points spread over the space: none may hang
    well_behaved.mkdir()
    dry = _cosim("sweep", str(_spec(well_behaved, [0, 10, 11, 12, 13])), "--dry-run", "--workers", "1", env={})
    assert "timeout: 60 s per point by default" in dry.stdout, dry.stdout
