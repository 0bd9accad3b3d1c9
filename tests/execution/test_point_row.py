"""PointRow (cosim.execution.point_row): the one type of a point's outcome, from a point's process to the table."""

from __future__ import annotations

import dataclasses
import math
import pickle
import subprocess
import sys

import pytest

from cosim.execution.point_row import STATUSES, TAIL_COLUMNS, PointRow
from cosim.execution.run import RunResult
from cosim.results import columns


def test_a_row_becomes_a_table_row_point_id_columns_objectives_then_the_tail():
    row = PointRow("p1", "ok", "", 0.25, {"e": 1.5, "q[1]": 2.0}, "tcp://w:1")
    table_row = row.to_dict({"__design_index": 7, "a": 3.0})
    assert list(table_row) == ["point_id", "__design_index", "a", "e", "q[1]", "status", "message", "run_time",
                               "worker"]
    assert table_row == {"point_id": "p1", "__design_index": 7, "a": 3.0, "e": 1.5, "q[1]": 2.0, "status": "ok",
                         "message": "", "run_time": 0.25, "worker": "tcp://w:1"}
    assert tuple(row.tail()) == TAIL_COLUMNS  # the table's last columns, in their order
    assert columns.TAIL_COLUMNS is TAIL_COLUMNS and columns.STATUSES is STATUSES  # defined once


def test_a_row_is_made_from_a_run_result_and_named_by_its_worker_without_changing_it():
    result = RunResult("failed", "unit 'm' failed at t=0.1", {"y": math.inf}, None, 0.5)
    row = PointRow.of("p2", result, 0.75)
    assert (row.point_id, row.status, row.message, row.run_time, row.objectives) == \
        ("p2", "failed", "unit 'm' failed at t=0.1", 0.75, {"y": math.inf})
    assert not row.ok and row.worker == ""
    named = row.on_worker("host:123")
    assert named.worker == "host:123" and row.worker == ""
    assert dataclasses.replace(named, worker="") == row
    with pytest.raises(dataclasses.FrozenInstanceError):
        row.status = "ok"  # type: ignore[misc]


def test_a_lost_point_has_no_run_time_and_no_objectives():
    row = PointRow("p3", "crashed", "its worker died")
    assert math.isnan(row.run_time) and row.objectives == {} and row.worker == "" and not row.ok
    assert math.isnan(row.to_dict()["run_time"])


def test_a_row_pickles_as_its_fields_no_larger_than_the_dict_it_replaced():
    objectives = {f"e_el_run[{i}]": 1.25 * i for i in range(1, 8)} | {"e_total": 3.0, "t_end": 2.3}
    row = PointRow("f70b2884ebca0b1c", "ok", "", 0.0123, objectives, "tcp://127.0.0.1:40000")
    as_dict = {"point_id": row.point_id, "status": row.status, "message": row.message, "run_time": row.run_time,
               "objectives": objectives, "worker": row.worker}
    data = pickle.dumps(row, protocol=pickle.HIGHEST_PROTOCOL)
    back = pickle.loads(data)
    assert back == row and type(back) is PointRow and back.objectives == objectives
    assert len(data) <= len(pickle.dumps(as_dict, protocol=pickle.HIGHEST_PROTOCOL))


def test_the_task_module_stays_light_with_rows_in_it():
    """A Dask scheduler and every worker import cosim.parallel.tasks (and so PointRow) to unpickle tasks and
    rows: that import must not pull numpy or the engine."""
    code = ("import sys, cosim.parallel.tasks, cosim.execution.point_row; "
            "print(sorted(m for m in ('numpy', 'pandas', 'cosim.execution.run', 'cosim.system') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
