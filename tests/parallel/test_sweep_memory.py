"""A sweep's client keeps no per-point state: what Dask would keep of a task's points is bounded and small.

Dask keeps the last messages of every connection for debugging (1000 by default) and a sweep's task
messages carry its points, so every process of a cluster cosim starts keeps evaluator.LOG_LENGTH; and a task's
points travel as one pickled bytes object (cosim.parallel.tasks.PointBatch), which the scheduler passes on without unpickling.
The client's memory over 10^6 points is measured in benchmarks/sweep_memory.py.
"""

from __future__ import annotations

import pickle

import numpy as np

from cosim.parallel.cluster.choice import choose_cluster
from cosim.parallel.cluster.client import dask_client
from cosim.parallel.cluster.local import LOG_LENGTH
from cosim.parallel.tasks import PointBatch


def test_a_point_batch_travels_as_one_bytes_object_and_is_unpickled_when_read():
    points = [("p1", {"a.k": 1.5, "a.v": np.array([1.0, 2.0])}), ("p2", {"a.k": -0.0, "a.v": np.array([3.0, 4.0])})]
    data = pickle.dumps(PointBatch(points))
    copy = pickle.loads(data)
    assert pickle.dumps(copy) == data  # passed on (the scheduler's way) as the same bytes
    assert [pid for pid, _ in copy.points] == ["p1", "p2"]
    for (_, got), (_, want) in zip(copy.points, points):
        assert got["a.k"] == want["a.k"] and np.array_equal(got["a.v"], want["a.v"])
    assert np.signbit(copy.points[1][1]["a.k"])  # bit for bit: -0.0 stays -0.0


def test_every_process_of_the_local_cluster_keeps_few_recent_messages():
    with dask_client(choose_cluster(1)) as (client, _, _):
        assert client.scheduler_comm.recent_message_log.maxlen == LOG_LENGTH  # client -> scheduler
        scheduler = client.cluster.scheduler  # runs in this process
        assert [s.recent_message_log.maxlen for s in scheduler.stream_comms.values()] == [LOG_LENGTH]
        assert scheduler.transition_log.maxlen == LOG_LENGTH

        def worker_logs(dask_worker):
            return dask_worker.batched_stream.recent_message_log.maxlen, dask_worker.state.stimulus_log.maxlen

        assert list(client.run(worker_logs).values()) == [(LOG_LENGTH, LOG_LENGTH)]
