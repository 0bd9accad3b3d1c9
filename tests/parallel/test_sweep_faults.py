"""Faults are data: the real fault FMU segfaults, hangs, returns an error or outputs NaN for chosen points.

Each faulty point must end with its own status and message, and every other
point of the same sweep (also those after it in the same batch, on the same
worker) must be ok with the right values.
"""

from __future__ import annotations

import pytest

import cosim
from cosim.parallel.isolation.payload import make_payload
from cosim.parallel.isolation.runner import IsolatedRunner
from cosim.system.validate import check_spec
from tests.helpers.paths import HELPERS

TIMEOUT = 1.5
EXPECTED = {0: ("ok", ""), 1: ("crashed", "SIGSEGV"), 2: ("timeout", f"timeout of {TIMEOUT:g} s"),
            3: ("failed", "returned Error"), 4: ("failed", "not finite")}


def fault_spec(version: int) -> dict:
    return {
        "name": f"faults_fmi{version}",
        "units": {"f": {"fmu": f"builtin:fault_fmi{version}"}},
        "experiment": {"stop": 0.2, "step": 0.01},
        "objectives": {"t_end": {"signal": "f.y", "reduce": "final"}},
        # the ok points come before and after every faulty one, in one batch
        "design": {"parameters": {"f.mode": {"values": [0, 1, 2, 3, 4]},
                                  "f.trigger_time": {"values": [0.05, 0.5]}}},
    }


@pytest.mark.parametrize("version", [2, 3])
def test_each_fault_gets_its_status_and_every_other_point_is_ok(write_spec, local_cluster, version):
    spec_path = write_spec(fault_spec(version), f"faults{version}.json")
    df = cosim.sweep(str(spec_path), scheduler=local_cluster, timeout=TIMEOUT, batch_size=10, quiet=True)
    assert len(df) == 10 and df["point_id"].is_unique
    for _, row in df.iterrows():
        if row["f.trigger_time"] > 0.2:  # the fault would come after the stop time: a normal run
            status, fragment = "ok", ""
        else:
            status, fragment = EXPECTED[row["f.mode"]]
        assert row["status"] == status, (row["f.mode"], row["message"])
        assert fragment in row["message"]
        if status == "ok":
            assert row["t_end"] == pytest.approx(0.2) and row["message"] == ""
    hung = df[df["status"] == "timeout"]
    assert ((hung["run_time"] >= TIMEOUT) & (hung["run_time"] < TIMEOUT + 2)).all()
    assert df["worker"].nunique() == 1  # one batch: the same worker went on after the crash and the hang


def test_python_unit_exception_and_bad_value_are_failed_rows(write_spec, local_cluster):
    spec = {
        "units": {"bad": {"python": f"{HELPERS / 'units_for_tests.py'}:Failing"}},
        "experiment": {"stop": 1.0, "step": 0.1},
        "objectives": {"y_end": {"signal": "bad.y", "reduce": "final"}},
        "design": {"parameters": {"bad.fail_at": {"values": [0.35, 5.0]}}},
    }
    df = cosim.sweep(str(write_spec(spec)), scheduler=local_cluster, quiet=True)
    assert list(df["status"]) == ["failed", "ok"]
    assert "boom" in df.loc[0, "message"] and "t=0.4" in df.loc[0, "message"]
    assert df.loc[1, "y_end"] == pytest.approx(0.9)


def test_isolated_runner_restarts_after_crash_and_hang(write_spec):
    system = check_spec(write_spec(fault_spec(2)))
    runner = IsolatedRunner(make_payload(system))
    try:
        points = [("a", {"f.mode": 0}), ("b", {"f.mode": 1, "f.trigger_time": 0.0}), ("c", {"f.mode": 0}),
                  ("d", {"f.mode": 2, "f.trigger_time": 0.0}), ("e", {"f.mode": 0}), ("f", {"f.mode": 9})]
        rows = runner.run(points, timeout=1.0)
    finally:
        runner.close()
    assert [r.point_id for r in rows] == list("abcdef")
    assert [r.status for r in rows] == ["ok", "crashed", "ok", "timeout", "ok", "failed"]
    assert rows[4].objectives == {"t_end": pytest.approx(0.2)}
    assert "outside the range of 'mode'" in rows[5].message  # checked like a spec value, not run
