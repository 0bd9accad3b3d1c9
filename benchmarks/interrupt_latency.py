"""Signal-to-exit latency of `cosim sweep` and the finished points it keeps (issue 29, item 3).

    python benchmarks/interrupt_latency.py                      # points of 0.3 s, 5 s and 60 s
    python benchmarks/interrupt_latency.py --seconds 0.3,5      # quicker

For each point time P, ``cosim sweep`` (its own local cluster of 2 workers, batch size left to cosim) runs a
Python unit that sleeps P s and then appends its point and the time it finished to a log. Once points
are running (25 points finished for short points, else 2.5 P or 20 s after start), the client gets SIGTERM;
the script measures the time from the signal to the client's exit, and compares the points finished
before the signal (the log) with the rows kept in the results folder's part files (all rows kept, and
those not ok: a point the stop cut short must get no row).

Target (issue 29): exit within about 2 s of the signal whatever P, every point finished before it kept.

    python benchmarks/interrupt_latency.py --cluster subprocess --seconds 0.3

runs the sweep on a cluster file's SubprocessCluster of 2 workers instead (``--cluster local``: a LocalCluster
file) and stops it as a terminal's Ctrl-C does, SIGINT to its whole process group (the cluster's processes
get it too); the time is then until the client exits, and "group gone" until no process of the group is left.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

UNIT = """
import time
from cosim import PythonUnit, Variable

class Slow(PythonUnit):
    variables = (Variable("k", "parameter", start=1.0), Variable("pause", "parameter", start=0.0),
                 Variable("y", "output", start=0.0))

    def do_step(self, t, h):
        time.sleep(self.pause)
        self.y = 3.0 * self.k
        with open(LOG, "a") as log:
            log.write(f"{self.k:g} {time.time():.3f}\\n")
"""


CLUSTER_FILES = {
    "subprocess": {"type": "distributed.deploy.subprocess.SubprocessCluster",
                   "kwargs": {"n_workers": 2, "worker_kwargs": {"nthreads": 1}, "dashboard_address": "127.0.0.1:0"}},
    "local": {"type": "distributed.LocalCluster",
              "kwargs": {"n_workers": 2, "threads_per_worker": 1, "dashboard_address": "127.0.0.1:0"}},
}


def _group_alive(group: int) -> bool:
    import psutil

    for process in psutil.process_iter(["status"]):
        try:
            if os.getpgid(process.pid) == group and process.info["status"] != psutil.STATUS_ZOMBIE:
                return True
        except (ProcessLookupError, psutil.Error):
            pass
    return False


def run_case(folder: Path, pause: float, cluster: str | None = None) -> dict:
    points = max(8, int(40 / max(pause, 0.3)))
    log = folder / "finished.log"
    (folder / "slow.py").write_text(UNIT.replace("LOG", repr(str(log))))
    spec = {"name": "slow", "units": {"s": {"python": "slow.py:Slow", "parameters": {"pause": pause}}},
            "experiment": {"stop": 0.1, "step": 0.1}, "objectives": {"y": {"signal": "s.y", "reduce": "final"}},
            "design": {"parameters": {"s.k": {"min": 1, "max": points, "step": 1}}}}
    (folder / "spec.json").write_text(json.dumps(spec))
    out = folder / "out"
    where = ["--workers", "2"]
    if cluster is not None:
        (folder / "cluster.json").write_text(json.dumps(CLUSTER_FILES[cluster]))
        where = ["--cluster", str(folder / "cluster.json")]
    with open(folder / "stderr.txt", "w") as stderr:  # a file: a pipe would wait for every process holding it
        proc = subprocess.Popen([sys.executable, "-m", "cosim.cli.main", "sweep", str(folder / "spec.json"), "--out",
                                 str(out), *where], stdout=subprocess.DEVNULL, stderr=stderr, text=True,
                                env=dict(os.environ, PYTHONPATH=str(REPO / "src")), start_new_session=True)
    started = time.monotonic()
    wait = 2.5 * pause if pause >= 1 else None
    while True:
        finished_so_far = len(log.read_text().split("\n")) - 1 if log.exists() else 0
        if wait is None and finished_so_far >= 25 or \
                wait is not None and log.exists() and time.monotonic() - started > max(wait, 20):
            break
        time.sleep(0.05)
    signalled = time.time()
    if cluster is None:
        os.kill(proc.pid, signal.SIGTERM)
    else:  # Ctrl-C: the cluster's processes on this machine get it too
        os.killpg(proc.pid, signal.SIGINT)
    proc.wait(timeout=600)
    latency = time.time() - signalled
    while _group_alive(proc.pid) and time.time() - signalled < 60:
        time.sleep(0.05)
    group_gone = time.time() - signalled
    time.sleep(1.0)  # what the group's last processes print
    err = (folder / "stderr.txt").read_text()
    finished = {float(line.split()[0]) for line in log.read_text().split("\n") if line.strip()
                and float(line.split()[1]) <= signalled}
    import pandas as pd

    files = sorted((out / "parts").glob("part-*.parquet"))
    rows = pd.concat([pd.read_parquet(p) for p in files]) if files else pd.DataFrame({"s.k": [], "status": []})
    kept = set(rows["s.k"])
    not_ok = int((rows["status"] != "ok").sum())  # a row the stop made up (a killed point as crashed) would be wrong
    try:  # the point children of the local cluster are ended with the client; none may outlive it long
        subprocess.run(["pkill", "-s", str(proc.pid)], check=False)  # only this sweep's own session
    except OSError:
        pass
    return {"pause": pause, "exit_code": proc.returncode, "latency": latency, "group_gone": group_gone,
            "last_line": (err.strip().splitlines() or [""])[-1], "finished": len(finished),
            "kept": len(kept & finished), "kept_rows": len(kept), "not_ok": not_ok, "traceback": "Traceback" in err,
            "broken_pipe": "BrokenPipe" in err}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seconds", default="0.3,5,60")
    parser.add_argument("--cluster", choices=sorted(CLUSTER_FILES), help="a cluster file's cluster, stopped by Ctrl-C")
    args = parser.parse_args()
    pauses = [float(s) for s in args.seconds.split(",")]
    print(time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()), "load", open("/proc/loadavg").read().split()[:3])
    print("| point time | exit code | signal to exit | group gone | points finished before the signal | of them kept | "
          "rows kept | rows not ok | traceback | BrokenPipe | last line |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for pause in pauses:
        with tempfile.TemporaryDirectory() as tmp:
            r = run_case(Path(tmp), pause, args.cluster)
        print(f"| {pause:g} s | {r['exit_code']} | {r['latency']:.1f} s | {r['group_gone']:.1f} s | {r['finished']} | "
              f"{r['kept']} | {r['kept_rows']} | {r['not_ok']} | {'yes' if r['traceback'] else 'no'} | "
              f"{'yes' if r['broken_pipe'] else 'no'} | `{r['last_line'][:50]}` |", flush=True)
    print(time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()), "load", open("/proc/loadavg").read().split()[:3])


if __name__ == "__main__":
    main()
