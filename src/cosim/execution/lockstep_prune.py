"""Exact pruning inside a lock-step group: rows proven off the front leave the group, the group steps on.

A lock-step group (:mod:`cosim.execution.lockstep`) keeps every sample of its K rows.  :class:`GroupBound`
gives each row the verdict a :class:`~cosim.execution.prune.PruneBound` gives a single run, without a
Python call per row and sample: the partial reductions (max, min, final, initial, integral, integral_abs)
and the checks of the declarations bounds rely on (``monotone``, an integrand's declared sign) are brought
up to date for all rows at once, with numpy over the samples taken since the last comparison; then each
row still running hands its partial values to its own PruneBound, whose comparison with the front (the
same code as a single run's: strict dominance, ties never prune, a broken constraint on a bounded
objective) decides.  A pruned row is masked out of the group the way a row that reached its ``stop_when``
is (its units are no longer stepped or read), so the other rows' samples, and results, are unchanged bit
for bit.

The comparisons take at most :data:`~cosim.execution.prune.OVERHEAD_SHARE` of the group's time, as in a
single run (each running row is compared on its own every :data:`FULL_EVERY` comparisons; in between only
the rows a vectorised prefilter picks: those a front member is at least as good as in every objective it
can bound for all rows at once, a necessary condition of dominance); a later comparison is never wrong (a bound only moves away from the front).  A declaration
broken anywhere in a window is found before the comparison that would rely on it.  Integrals are summed
window by window, in another order than a single run's running sum: the relative margin of inexact bounds
(:data:`~cosim.spec.bounds.MARGIN`) covers the last bits.
"""

from __future__ import annotations

import copy
import time
from types import SimpleNamespace
from typing import Any, Sequence

import numpy as np

from cosim.execution.prune import OVERHEAD_SHARE, PruneBound, PruneOrder
from cosim.spec.bounds import DOWN, FIXED, UP

FULL_EVERY = 8  # every this many comparisons each running row is compared, not only the prefilter's picks


class _GroupPartial:
    """One signal objective's running reduction for every row: (rows, elements) arrays."""

    def __init__(self, reduce: str, index: np.ndarray, direction: str | None, check: str | None, rows: int):
        self.reduce, self.index, self.direction, self.check = reduce, index, direction, check
        self.value = self.first = self.last = np.zeros((rows, len(index)))
        self.broken = np.zeros(rows, dtype=bool)

    def start(self, x: np.ndarray) -> None:
        self.first = self.last = x
        self.value = np.zeros_like(x) if self.reduce in ("integral", "integral_abs") else x
        if self.check == "sign":
            self._sign(x[None])

    def add(self, t: np.ndarray, x: np.ndarray) -> None:
        """Samples ``x`` (window, rows, elements) at times ``t`` (window + 1: the last time processed first)."""
        r = self.reduce
        if r == "max":
            self.value = np.maximum(self.value, x.max(axis=0))  # NaN stays NaN, as in a single run
        elif r == "min":
            self.value = np.minimum(self.value, x.min(axis=0))
        elif r == "final":
            self.value = x[-1]
        elif r in ("integral", "integral_abs"):
            y = np.abs(x) if r == "integral_abs" else x
            before = np.concatenate([(np.abs(self.last) if r == "integral_abs" else self.last)[None], y[:-1]])
            self.value = self.value + (np.diff(t)[:, None, None] * (y + before) / 2).sum(axis=0)
        if self.check == "sign":
            self._sign(x)
        elif self.check is not None:
            before = np.concatenate([self.last[None], x[:-1]])
            if self.direction == UP:
                bad = np.less(x, before)
            elif self.direction == DOWN:
                bad = np.greater(x, before)
            else:
                bad = np.not_equal(x, self.first[None]) if self.direction == FIXED else np.zeros(x.shape, bool)
            self.broken |= bad.any(axis=(0, 2))
        self.last = x[-1]

    def _sign(self, x: np.ndarray) -> None:
        bad = np.less(x, 0) if self.direction == UP else np.greater(x, 0)
        self.broken |= bad.any(axis=(0, 2))

    def current(self, row: int) -> Any:
        value = self.first[row] if self.reduce == "initial" else self.value[row]
        return float(value[0]) if len(value) == 1 else np.array(value, dtype=float)


def _copy_of(bound: PruneBound) -> PruneBound:
    """Another PruneBound in the state ``bound`` is in after ``attached``: its own partials, the same analysis
    (replaced, never changed in place, when a declaration breaks)."""
    twin = copy.copy(bound)
    twin._partials = [copy.copy(p) for p in bound._partials]
    return twin


class GroupBound:
    """The pruning of one lock-step group's first ``rows`` rows against ``order``'s front (module docstring).

    :meth:`start` takes the first sample (rows x probe columns), :meth:`step` each later one and returns the
    rows pruned at it; :attr:`verdicts` then holds each pruned row's PruneBound (its ``reason``,
    ``stop_time``, ``dominated_by`` and bound vector, as after a single run).
    """

    def __init__(self, system: Any, order: PruneOrder, columns: Sequence[str], rows: int):
        front = order.front()
        self.idle = not len(front.ids) and not order.settings.constraints  # nothing can prune: no work at all
        self.verdicts: dict[int, PruneBound] = {}
        self._rows: list[PruneBound] = []
        if self.idle:
            return
        context = SimpleNamespace(columns=list(columns))
        first = PruneBound(system, order.settings, front)
        first.attached(context)
        self._rows = [first] + [_copy_of(first) for _ in range(rows - 1)]  # attached once: the bounds' analysis
        self._partials = [_GroupPartial(p.reduce, p.index, p.bound.direction, p.bound.check, rows)
                          for p in self._rows[0]._partials]
        self._times: list[float] = []
        self._samples: list[np.ndarray] = []
        self._started = time.perf_counter()
        self._spent = 0.0  # seconds of comparisons so far: at most OVERHEAD_SHARE of the group's time
        self._checks = 0
        self._broken_seen = np.zeros((len(self._partials), rows), dtype=bool)
        self._front = front.values
        # per objective pruned on: (its partial, whether maximized) where it is a scalar signal objective, whose
        # bound the prefilter computes for all rows at once; None where only a row's own comparison can
        names = [p.name for p in self._rows[0]._partials]
        self._plain = [(names.index(n), sense == "maximize")
                       if n in names and len(self._partials[names.index(n)].index) == 1 else None
                       for n, sense in order.settings.objectives]
        # rows not picked by the prefilter are compared one by one every FULL_EVERY comparisons only: for a
        # constraint, or an objective the prefilter does not bound
        self._sweeps = bool(order.settings.constraints) or None in self._plain

    def start(self, t: float, values: np.ndarray) -> None:
        if self.idle:
            return
        for p in self._partials:
            p.start(values[:len(self._rows), p.index])
        self._times = [t]

    def step(self, t: float, values: np.ndarray, active: np.ndarray) -> np.ndarray:
        """Take the sample at ``t``; the rows among ``active`` proven off the front now (maybe none)."""
        if self.idle:
            return active[:0]
        self._times.append(t)
        self._samples.append(values[:len(self._rows)])
        now = time.perf_counter()
        if self._spent > OVERHEAD_SHARE * (now - self._started):
            return active[:0]  # the comparisons so far took their share of the group's time: later
        pruned = self._compare(t, active)
        self._spent += time.perf_counter() - now
        return pruned

    def _compare(self, t: float, active: np.ndarray) -> np.ndarray:
        window = np.stack(self._samples)
        times = np.array(self._times)
        for p in self._partials:
            p.add(times, window[:, :, p.index])
        self._times, self._samples = [t], []
        self._checks += 1
        rows = active if self._sweeps and self._checks % FULL_EVERY == 0 else active[self._candidates(active)]
        pruned = [row for row in rows.tolist() if self._verdict(t, row)]
        return np.array(pruned, dtype=active.dtype)

    def _candidates(self, active: np.ndarray) -> np.ndarray:
        """Which ``active`` rows a front member may dominate now: it is at least as good as the row's bound in
        every objective the prefilter bounds (a necessary condition only: the row's comparison decides)."""
        if not len(self._front):
            return np.zeros(len(active), dtype=bool)
        bound = np.full((len(active), len(self._plain)), np.inf)  # inf: not bounded here, excludes nothing
        for j, plain in enumerate(self._plain):
            if plain is None:
                continue
            i, maximize = plain
            p = self._partials[i]
            if p.direction not in ((DOWN, FIXED) if maximize else (UP, FIXED)):
                bound[:, j] = -np.inf  # never bounded this way: no member can be at least as good
                continue
            v = (p.first if p.reduce == "initial" else p.value)[active, 0]
            v = -v if maximize else v
            bound[:, j] = np.where(np.isfinite(v) & ~p.broken[active], v, -np.inf)
        picked: np.ndarray = np.all(self._front[None, :, :] <= bound[:, None, :], axis=2).any(axis=1)
        return picked

    def _verdict(self, t: float, row: int) -> bool:
        """The row's own PruneBound, given the group's partial values, compares with the front: pruned?"""
        bound = self._rows[row]
        newly = False
        for i, (mine, group) in enumerate(zip(bound._partials, self._partials)):
            mine.value = mine.first = group.current(row)  # current() of a PruneBound partial reads these
            if group.broken[row] and not self._broken_seen[i, row]:
                self._broken_seen[i, row] = newly = True
                mine.broken = f"its declaration broke before t={t:g}"
        if newly:
            bound._forget_broken()
        bound._compare(t)
        if bound.reason is None:
            return False
        self.verdicts[row] = bound
        return True
