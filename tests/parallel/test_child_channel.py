"""The pipe from a worker's child is closed by the thread that reads it, never under it.

Closed by IsolatedRunner.close while that thread was about to read again, the pipe's descriptor number went to
the next child's pipe and the old thread read that child's first bytes: after a recycled child
(COSIM_CHILD_POINTS) the new one was reported as "junk on its channel while loading the system" and every point
of the rest of its batch as failed (seen 1 776 times in a sweep of 10^6 trivial points on a loaded machine).
"""

from __future__ import annotations

import os
import time
from multiprocessing.connection import Connection

from cosim.execution.point_row import PointRow
from cosim.parallel.isolation.channel import Channel
from cosim.parallel.isolation.payload import make_payload
from cosim.parallel.isolation.runner import IsolatedRunner
from cosim.system.validate import check_spec
from tests.helpers.paths import HELPERS


def test_the_reader_thread_closes_the_pipe_itself_once_the_child_is_gone():
    read_fd, write_fd = os.pipe()
    inbox, outbox = Connection(read_fd, writable=False), Connection(write_fd, readable=False)
    channel = Channel(inbox)
    outbox.send(("row", (PointRow("p", "ok", "", 0.5), None)))
    assert channel.get(5) == ("row", (PointRow("p", "ok", "", 0.5), None))
    outbox.close()  # the child is gone
    assert channel.get(5) == ("eof", None)
    deadline = time.monotonic() + 5
    while not inbox.closed and time.monotonic() < deadline:
        time.sleep(0.01)
    assert inbox.closed


def test_children_recycled_after_every_point_give_every_row(write_spec, monkeypatch):
    monkeypatch.setenv("COSIM_CHILD_POINTS", "1")  # a new child for every point: 40 handovers of the pipes
    spec = write_spec({
        "name": "recycled",
        "units": {"g": {"python": f"{HELPERS / 'units_for_tests.py'}:Gain"}},
        "experiment": {"stop": 1.0, "step": 1.0},
        "objectives": {"y": {"signal": "g.y", "reduce": "final"}},
    })
    runner = IsolatedRunner(make_payload(check_spec(spec)))
    try:
        rows = runner.run([(f"p{i}", {}) for i in range(40)])
    finally:
        runner.close()
    assert [r.status for r in rows] == ["ok"] * 40, [r.message for r in rows if r.status != "ok"]
