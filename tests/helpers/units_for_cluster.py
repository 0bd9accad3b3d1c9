"""Python units for the cluster tests: a slow unit whose points can be caught in flight, one that kills its worker;
and the source of a unit reading a declared data file, written into a spec's folder by the tests that ship it."""

from __future__ import annotations

import os
import signal
import time

from cosim import PythonUnit, Variable


class SlowSquare(PythonUnit):
    """y = x**2 after ``delay`` seconds of wall time per step.

    The point with x == ``kill_at`` kills the Dask worker process running it
    (the parent of cosim's child process) at its first step, as the OOM killer
    would, once that worker has run for 3 s.  With the environment variable SLOW_SQUARE_MARKERS set to a folder,
    each step writes a file named after the worker's process id there, so a test
    knows which worker has a point in flight.
    """

    variables = (
        Variable("x", "parameter", start=0.0),
        Variable("delay", "parameter", start=0.05),
        Variable("kill_at", "parameter", start=-1.0),
        Variable("y", "output", start=0.0),
    )

    def do_step(self, t, h):
        markers = os.environ.get("SLOW_SQUARE_MARKERS")
        if markers:
            with open(os.path.join(markers, str(os.getppid())), "w") as marker:
                marker.write(str(self.x))
        if self.x == self.kill_at:
            # Not while the worker is starting: a Dask nanny does not restart a worker killed before its nanny
            # has seen it start (distributed 2026.8), and a loaded machine may then be left without workers.
            # An out-of-memory kill hits a worker that has been running; so does this one.
            import psutil

            worker = psutil.Process(os.getppid())
            if "multiprocessing" not in " ".join(worker.cmdline()):  # a Dask worker process is started by it
                raise RuntimeError("kill_at needs Dask worker processes (sweep_fixtures.worker_processes): "
                                   "a local cosim cluster's workers run in the client")
            started = worker.create_time()
            time.sleep(max(0.0, started + 3.0 - time.time()))
            os.kill(worker.pid, signal.SIGKILL)
            time.sleep(60)  # cosim's child stops itself when it sees its parent gone
        time.sleep(self.delay)
        self.y = self.x ** 2


# y = gain * k with the gain read from the JSON file its String parameter 'table' names (a declared data file)
TABLE_GAIN_SOURCE = '''
import json

from cosim import PythonUnit, Variable


class TableGain(PythonUnit):
    """y = gain * k, the gain read in initialize() from the JSON file named by 'table'."""

    variables = (Variable("table", "parameter", type="String", start=""), Variable("k", "parameter", start=1.0),
                 Variable("y", "output", start=0.0))
    data_files = ("table",)

    def initialize(self):
        with open(self.table, encoding="utf-8") as f:
            self.gain = json.load(f)["gain"]

    def do_step(self, t, h):
        self.y = self.gain * self.k
'''
