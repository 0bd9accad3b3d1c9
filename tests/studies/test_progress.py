"""The one status line of every study: one line per tenth in a log, rewritten in place on a terminal."""

from __future__ import annotations

import io

from cosim.studies.optimize import Progress as OptimizeProgress
from cosim.studies.progress import StatusLine, duration
from cosim.studies.sweep import Progress as SweepProgress


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_log_gets_one_line_per_tenth_and_the_last():
    log = io.StringIO()
    line = StatusLine(1000, log)
    for done in range(1, 1001):
        line.show(done, f"{done} done")
    lines = log.getvalue().splitlines()
    assert lines == [f"{done} done" for done in (1, 100, 200, 300, 400, 500, 600, 700, 800, 900, 1000)]


def test_a_terminal_line_is_rewritten_in_place_and_ended_by_close():
    tty = Terminal()
    line = StatusLine(3, tty)
    line.show(1, "one")
    line.show(2, "two")  # within the interval: not shown
    line.show(3, "three")  # the finished work is always shown
    line.close()
    assert tty.getvalue() == "one\rthree\r\n"


def test_a_closed_stream_does_not_stop_the_study():
    stream = io.StringIO()
    stream.close()
    line = StatusLine(2, stream)
    line.show(2, "done")
    line.close()


def test_sweep_and_optimisation_lines_use_it():
    log = io.StringIO()
    sweep = SweepProgress(4, log)
    sweep.update(2, 1)
    sweep.update(2, 0)
    optimize = OptimizeProgress(10, log)
    optimize.show(10, 3, 4, 0.5)
    lines = log.getvalue().splitlines()
    assert lines[0].startswith("[############............] 2/4 points, 1 not ok, ")
    assert lines[1].startswith("[########################] 4/4 points, 1 not ok, ") and lines[1].endswith("0:00 left")
    assert lines[2].startswith("10/10 evaluations, 3 not ok, front 4, hypervolume 0.5000, ")


def test_durations():
    assert (duration(59.4), duration(61), duration(3600 + 62), duration(float("inf"))) == ("0:59", "1:01", "1:01:02", "?")


def test_the_sweep_line_counts_each_point_once_and_pruned_points_apart():
    """A point's row handed twice (a stop hands the rows it interrupted again, cosim.parallel.point_stream) is
    one point: done never passes the total (a pruned sweep once showed '14/12 points'); a pruned point is a
    result, not 'not ok'."""
    from cosim.execution.point_row import PointRow

    log = io.StringIO()
    sweep = SweepProgress(3, log)
    first = [PointRow("a", "ok"), PointRow("b", "pruned", "pruned at t=0.5: design a strictly dominates")]
    sweep.rows(first)
    sweep.rows(first + [PointRow("c", "failed", "boom")])  # a and b again, with c
    sweep.rows([PointRow("c", "failed", "boom")])
    assert (sweep.done, sweep.failed, sweep.pruned) == (3, 1, 1)
    last = log.getvalue().splitlines()[-1]
    assert last.startswith("[########################] 3/3 points, 1 not ok, 1 pruned, ")
