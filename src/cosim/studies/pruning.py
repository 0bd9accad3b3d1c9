"""Exact pruning on the study's side: the front of finished designs, and what travels to the running ones.

:class:`FrontKeeper` holds the current Pareto front of the finished (``ok``, feasible) designs over the objectives
pruned on (the spec's objectives with a sense, or those named) and the study's constraints.  Each batch of points
sent to a worker carries a :class:`PruneOrder` (the settings and a snapshot of the front: a few rows of a few
floats), and the worker's child process gives it to each point's :class:`~cosim.execution.prune.PruneBound`.

Why the batch and not a Dask Variable, pub/sub or dataset: a point runs in a child process of the worker
(:mod:`cosim.parallel.isolation`), which has no Dask client of its own; the batch is the one message that
already goes from the study to that child, so the front rides along at no extra round trip (its pickled size is
measured in benchmarks/pruning.md).  A snapshot may be older than the newest front: that costs pruning, never
correctness, since any finished feasible design that strictly dominates a bound proves the design off the front.

A design off the front when another finished design dominates it cannot change the front either: whatever it
would dominate, the design dominating it dominates too.
"""

from __future__ import annotations

import math
import re
from typing import Any, Mapping, Sequence

import numpy as np

from cosim.errors import Problem, SpecError
from cosim.execution.prune import PruneOrder, PruneSettings, parse_constraint
from cosim.parallel.point_stream import BatchSizer
from cosim.spec.bounds import system_bounds

PRUNED = "pruned"
FIRST_SHARE = 0.05  # the space-filling subset run first: 5 % of the points
FIRST_MIN, FIRST_MAX = 8, 64


def prune_settings(system: Any, objectives: Sequence[tuple[str, str]] | None = None,
                   constraints: Sequence[str] = ()) -> PruneSettings:
    """The settings of a pruned study of ``system``: ``objectives`` ((name, sense); default: the spec's
    objectives with a sense) and ``constraints`` (comparisons ``name op number``).

    Raises SpecError when there is no objective to prune on, a constraint is not such a comparison, or no
    objective pruned on is bounded (pruning could never stop a design: say so instead of running slower).
    """
    spec = system.spec
    chosen = list(objectives or [(o.name, o.sense) for o in spec.objectives if o.sense])
    if not chosen:
        raise SpecError([Problem(spec.path, "$.objectives", "pruning needs objectives with a sense",
                                 "give objectives a \"sense\" (minimize or maximize), or name them")])
    parsed = []
    for i, text in enumerate(constraints):
        c = parse_constraint(text)
        if c is None:
            raise SpecError([Problem(spec.path, f"$.optimize.constraints[{i}]", f"'{text}' is not a comparison "
                                     "of one objective with a number", "write it as e.g. 'peak_tau <= 1'")])
        parsed.append(c)
    bounds = system_bounds(system)
    if not any(bounds.get(name.split("[")[0]) and bounds[name.split("[")[0]].direction for name, _ in chosen):
        listed = ", ".join(f"{n} ({bounds[n.split('[')[0]].why})" for n, _ in chosen if n.split("[")[0] in bounds)
        raise SpecError([Problem(spec.path, "$.objectives", f"no objective pruned on is bounded while a design "
                                 f"runs: {listed}", "declare a monotone signal (\"monotone\") or prune on "
                                 "objectives that are bounded (cosim inspect lists them)")])
    return PruneSettings(tuple((n, s) for n, s in chosen), tuple(parsed))


class FrontKeeper:
    """The front of finished feasible designs (minimizing form), updated row by row."""

    def __init__(self, settings: PruneSettings):
        self.settings = settings
        self.ids: list[str] = []
        self.values = np.empty((0, len(settings.objectives)))

    def feasible(self, objectives: Mapping[str, float]) -> bool:
        """Whether a finished design meets every constraint (a missing or NaN value: not feasible)."""
        import operator

        ops = {"<=": operator.le, "<": operator.lt, ">=": operator.ge, ">": operator.gt}
        for name, op, c in self.settings.constraints:
            v = objectives.get(name, math.nan)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and ops[op](v, c)):
                return False
        return True

    def add(self, point_id: str, objectives: Mapping[str, float]) -> bool:
        """Take a finished design's row; True when the front changed."""
        try:
            row = np.array([objectives[n] if s == "minimize" else -objectives[n]
                            for n, s in self.settings.objectives], dtype=float)
        except KeyError:
            return False
        if not np.isfinite(row).all() or not self.feasible(objectives):
            return False
        if len(self.ids):
            dominated = np.all(self.values <= row, axis=1) & np.any(self.values < row, axis=1)
            if dominated.any() or np.all(self.values == row, axis=1).any():
                return False  # dominated, or equal to a member: the front proves no more with it
            keep = ~(np.all(row <= self.values, axis=1) & np.any(row < self.values, axis=1))
            self.ids = [i for i, k in zip(self.ids, keep) if k]
            self.values = self.values[keep]
        self.ids.append(point_id)
        self.values = np.vstack([self.values, row])
        return True

    def order(self) -> PruneOrder:
        return PruneOrder(self.settings, tuple(self.ids), tuple(tuple(float(x) for x in r) for r in self.values))


class FreshFronts(BatchSizer):
    """Batches for a pruned study: the front travels with each batch, so a batch's points all compare with the
    front as it was when the batch left.  The first tasks hold one point each (otherwise a quarter of the study
    would leave with an empty front), and a task lasts about PRUNE_TASK_SECONDS at most.

    ``group`` > 1: the points run in lock-step groups of up to that many (cosim.execution.lockstep; pruned
    rows leave a group, cosim.execution.lockstep_prune).  Once the first rows are back a task then holds at
    least ``group`` points and lasts about the unpruned sweep's TASK_SECONDS: the time of an ok point run
    alone (the first ones) would otherwise make tasks too small to form groups, and every point would run
    alone at several times a grouped point's cost."""

    PRUNE_TASK_SECONDS = 0.1

    def __init__(self, todo: int, n_workers: int, size: int | None = None, group: int = 1):
        super().__init__(todo, n_workers, size)
        self.group = 1 if size is not None else group
        if size is None:
            self.first = 1
            if group < 2:
                self.TASK_SECONDS = self.PRUNE_TASK_SECONDS

    def next(self) -> int:
        size = super().next()
        if self.group > 1 and self.point_seconds is not None:
            size = max(size, min(self.group, self.remaining))
        return size


def lockstep_group(system: Any) -> int:
    """The largest lock-step group the points of ``system`` run in (1: they run one by one)."""
    from cosim.execution.lockstep import GROUP_SIZE, can_run_in_lockstep  # deferred: the stepping machinery

    return GROUP_SIZE if can_run_in_lockstep(system) else 1


def first_count(total: int) -> int:
    """How many points the space-filling subset run first holds."""
    return min(total, max(FIRST_MIN, min(FIRST_MAX, round(FIRST_SHARE * total))))


def maximin_first(points: Sequence[Any], coordinates: np.ndarray, n: int) -> list[int]:
    """Indices of ``n`` of ``points`` chosen greedily for the largest smallest distance (maximin) in the unit
    cube of ``coordinates`` (one row per point): start at the point nearest the centre, then each time the
    point farthest from those chosen.  Deterministic; ties go to the lower index."""
    if n <= 0 or not len(points):
        return []
    lo, hi = coordinates.min(axis=0), coordinates.max(axis=0)
    unit = (coordinates - lo) / np.where(hi > lo, hi - lo, 1.0)
    chosen = [int(np.argmin(((unit - 0.5) ** 2).sum(axis=1)))]
    nearest = ((unit - unit[chosen[0]]) ** 2).sum(axis=1)
    while len(chosen) < min(n, len(points)):
        nxt = int(np.argmax(nearest))
        chosen.append(nxt)
        nearest = np.minimum(nearest, ((unit - unit[nxt]) ** 2).sum(axis=1))
    return chosen


def numeric_coordinates(points: Sequence[Any]) -> np.ndarray:
    """The points' parameter values as a float matrix (one column per flat value; non-numbers as 0)."""
    rows = []
    for p in points:
        row = []
        for v in p.values.values():
            for x in np.atleast_1d(np.asarray(v, dtype=object)).ravel():
                row.append(float(x) if isinstance(x, (int, float, np.number)) else 0.0)
        rows.append(row)
    return np.array(rows, dtype=float) if rows else np.empty((0, 0))


def pruning_order(points: Sequence[Any]) -> tuple[list[Any], dict[str, Any]]:
    """``points`` reordered: a maximin subset first, then the rest in design order; and the metadata saying
    so (method, how many first, their ids)."""
    n = first_count(len(points))
    first = maximin_first(points, numeric_coordinates(points), n)
    chosen = set(first)
    ordered = [points[i] for i in first] + [p for i, p in enumerate(points) if i not in chosen]
    return ordered, {"method": "maximin subset first, then design order", "first": len(first),
                     "first_ids": [points[i].id for i in first]}


_PRUNED_AT = re.compile(r"^pruned at t=([^:]+): (?:design (\S+) strictly dominates)?")


def pruned_columns(row: Any) -> dict[str, Any]:
    """The ``pruned_by`` (id of the dominating design; empty for a broken constraint or a row not pruned) and
    ``pruned_at`` (the time it stopped; NaN when not pruned) columns of a row of a pruned study, read from the
    message :class:`~cosim.execution.prune.PruneBound` gives a pruned run."""
    match = _PRUNED_AT.match(row.message or "") if row.status == PRUNED else None
    if match is None:
        return {"pruned_by": "", "pruned_at": math.nan}
    return {"pruned_by": match.group(2) or "", "pruned_at": float(match.group(1))}
