"""Exact pruning inside a run: :class:`PruneBound` ends a design once a finished design strictly dominates
everything it can still reach, or a constraint on a bounded objective is already broken.

At each communication point the observer updates the partial reductions of the objectives (max, min, final,
initial, integral, integral_abs: each in O(1) per sample) and checks the declarations; as often as
:data:`OVERHEAD_SHARE` of the run's time allows (every step of a slow model, every few of a cheap one: late is
never wrong, a bound only moves away from the front) it evaluates the expressions the pruned objectives need
and turns them into a *bound vector* through the directions of :mod:`cosim.spec.bounds`: for a minimized
objective moving up (or fixed) the value so far is the best the design can still end with; for one that is
unbounded the best is -inf, so it never prunes.  A front member ``f`` prunes the design when ``f <= b`` in every
objective and ``f < b`` in one (both in minimizing form, an inexact bound less a relative margin): ties never
prune.  The declarations bounds rely on (``monotone``, an integrand's declared sign) are checked on every sample;
the first sample that breaks one leaves that objective (and expressions of it) unbounded for this design.

A pruned run ends with status ``pruned``; its objectives are the bound vector (NaN where unbounded), and its
message names the dominating design and the time it stopped (:meth:`PruneBound.objectives_at_stop`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from cosim.execution.observers import columns_of
from cosim.master.observers import StopCondition, flatten_objectives
from cosim.spec.bounds import DOWN, FIXED, MARGIN, UP, Bound, system_bounds
from cosim.spec.expressions import evaluate_expressions, parsed_expression

PRUNED = "pruned"
OVERHEAD_SHARE = 0.05  # at most this share of a run's time goes to comparing its bound with the front
_COMPARE = {"<=", "<", ">=", ">"}


@dataclass
class Front:
    """Finished designs to prune against: ``ids`` and ``values`` (rows, in the order of the objectives pruned on,
    in minimizing form: a maximized objective negated).  ``refresh`` (optional) returns a newer Front or None;
    the observer calls it at most every ``refresh_every`` steps."""

    ids: list[str] = field(default_factory=list)
    values: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))
    refresh: Callable[[], "Front | None"] | None = None
    refresh_every: int = 50


@dataclass(frozen=True)
class PruneSettings:
    """What to prune on: ``objectives`` ((flat name, 'minimize'|'maximize'), in the front's column order) and
    ``constraints`` ((flat name, comparison, number): e.g. ('peak_tau_ratio', '<=', 1.0))."""

    objectives: tuple[tuple[str, str], ...]
    constraints: tuple[tuple[str, str, float], ...] = ()


@dataclass(frozen=True)
class PruneOrder:
    """What a study's batch carries to the child process that runs its points (cosim.studies.pruning): the
    settings and a snapshot of the front (ids, rows in minimizing form)."""

    settings: PruneSettings
    ids: tuple[str, ...]
    values: tuple[tuple[float, ...], ...]

    def front(self) -> Front:
        k = len(self.settings.objectives)
        return Front(list(self.ids), np.array(self.values, dtype=float).reshape(len(self.ids), k))


def parse_constraint(text: str) -> tuple[str, str, float] | None:
    """('name', op, number) of a comparison ``name op number`` (or ``number op name``), else None: only such
    constraints can be found broken by a bound."""
    import ast

    try:
        node = ast.parse(text.strip(), mode="eval").body
    except SyntaxError:
        return None
    if not (isinstance(node, ast.Compare) and len(node.ops) == 1):
        return None
    ops = {ast.Lt: "<", ast.LtE: "<=", ast.Gt: ">", ast.GtE: ">="}
    op = ops.get(type(node.ops[0]))
    left, right = node.left, node.comparators[0]
    flip = {"<": ">", "<=": ">=", ">": "<", ">=": "<="}

    def number(n: Any) -> float | None:
        if isinstance(n, ast.Constant) and isinstance(n.value, (int, float)) and not isinstance(n.value, bool):
            return float(n.value)
        if isinstance(n, ast.UnaryOp) and isinstance(n.op, ast.USub):
            inner = number(n.operand)
            return None if inner is None else -inner
        return None

    if op is None:
        return None
    right_value, left_value = number(right), number(left)
    if right_value is not None and not isinstance(left, ast.Constant):
        return ast.unparse(left), op, right_value
    if left_value is not None:
        return ast.unparse(right), flip[op], left_value
    return None


class _Partial:
    """The running reduction of one signal objective, and the check of the declaration its bound relies on.

    Its samples are numpy vectors (one element per signal element); a scalar signal, the usual case, takes a
    path of Python floats, since per-sample numpy calls on one element would cost more than a cheap step."""

    KINDS = ("max", "min", "final", "initial", "integral", "integral_abs")

    def __init__(self, name: str, reduce: str, index: np.ndarray, bound: Bound):
        self.name, self.reduce, self.index, self.bound = name, reduce, index, bound
        self.scalar = int(index[0]) if len(index) == 1 else None
        self.value: Any = None
        self.first: Any = None
        self.last: Any = None
        self.t: float = math.nan
        self.broken: str | None = None

    def _sample(self, values: np.ndarray) -> Any:
        return float(values[self.scalar]) if self.scalar is not None else values[self.index]

    def start(self, t: float, values: np.ndarray) -> None:
        x = self._sample(values)
        self.first = self.last = x
        self.t = t
        zero = 0.0 if self.scalar is not None else np.zeros_like(x)
        self.value = zero if self.reduce in ("integral", "integral_abs") else x
        self._check(t, x, None)

    def add(self, t: float, values: np.ndarray) -> None:
        if self.value is None:
            self.start(t, values)
            return
        x, r, last = self._sample(values), self.reduce, self.last
        if self.scalar is not None:
            if r == "max":
                self.value = x if x > self.value or x != x else self.value  # a NaN sample stays NaN
            elif r == "min":
                self.value = x if x < self.value or x != x else self.value
            elif r == "final":
                self.value = x
            elif r == "integral":
                self.value += (t - self.t) * (x + last) / 2
            elif r == "integral_abs":
                self.value += (t - self.t) * (abs(x) + abs(last)) / 2
        elif r == "max":
            self.value = np.maximum(self.value, x)
        elif r == "min":
            self.value = np.minimum(self.value, x)
        elif r == "final":
            self.value = x
        elif r == "integral":
            self.value = self.value + (t - self.t) * (x + last) / 2
        elif r == "integral_abs":
            self.value = self.value + (t - self.t) * (np.abs(x) + np.abs(last)) / 2
        if self.bound.check is not None and self.broken is None:
            if self.scalar is None or not self._holds(x, last):
                self._check(t, x, last)
        self.last, self.t = x, t

    def _holds(self, x: float, last: float) -> bool:
        """The declaration's quick test on a scalar sample (True: nothing to look into)."""
        d = self.bound.direction
        if self.bound.check == "sign":
            return x >= 0 if d == UP else x <= 0
        return x >= last if d == UP else x <= last if d == DOWN else x == self.first

    def _check(self, t: float, x: Any, last: Any) -> None:
        """Record the first sample that breaks the declaration the bound relies on."""
        b = self.bound
        if self.broken is not None or b.check is None or b.direction is None:
            return
        if b.check == "sign":
            bad = np.any(np.less(x, 0)) if b.direction == UP else np.any(np.greater(x, 0))
            if bad:
                self.broken = f"a {'negative' if b.direction == UP else 'positive'} sample at t={t:g}"
        elif last is not None:
            if b.direction == UP and np.any(np.less(x, last)):
                self.broken = f"it decreased at t={t:g}"
            elif b.direction == DOWN and np.any(np.greater(x, last)):
                self.broken = f"it increased at t={t:g}"
            elif b.direction == FIXED and np.any(np.not_equal(x, self.first)):
                self.broken = f"it changed at t={t:g}"

    def current(self) -> Any:
        if self.value is None or self.reduce not in self.KINDS:
            n = 1 if self.scalar is not None else len(self.index)
            return math.nan if n == 1 else np.full(n, np.nan)
        value = self.first if self.reduce == "initial" else self.value
        if self.scalar is not None:
            return value
        return float(value[0]) if len(value) == 1 else np.array(value, dtype=float)


class PruneBound(StopCondition):
    """A :class:`~cosim.master.observers.StopCondition` that ends a design proven unable to reach the front
    (module docstring).  ``front`` is what it compares against (:class:`Front`), ``settings`` what it prunes on.

    After a stop, :attr:`dominated_by` is the id of the dominating design (None for a broken constraint),
    :attr:`stop_time` the time, :attr:`bound` the bound vector (flat name -> value, NaN where unbounded).
    """

    status = PRUNED

    def __init__(self, system: Any, settings: PruneSettings, front: Front):
        self.system, self.settings, self.front = system, settings, front
        self.reason = None
        self.dominated_by: str | None = None
        self.stop_time: float | None = None
        self.bound: dict[str, float] = {}
        self.checks = 0

    def attached(self, context: Any) -> None:
        self.reason, self.dominated_by, self.stop_time, self.bound = None, None, None, {}
        spec = self.system.spec
        self._bounds = system_bounds(self.system)
        wanted = {_base(n) for n, _ in self.settings.objectives} | {_base(n) for n, _, _ in self.settings.constraints}
        needed = _closure(spec.objectives, wanted)
        self._exprs = [o for o in spec.objectives if o.expr and o.name in needed]
        columns = list(context.columns)
        self._partials = [_Partial(o.name, o.reduce, np.array([columns.index(c) for c in
                                                                 columns_of(self.system, o.signal)]),
                                   self._bounds[o.name])
                          for o in spec.objectives if o.signal and o.name in needed]
        self._directions = self._flat_directions()
        self._steps = 0
        self._next_check = 0.0

    def _flat_directions(self) -> tuple[list[tuple[str | None, bool]], list[tuple[str | None, bool]]]:
        """(direction, exact) of each pruned objective and each constraint's objective, as bounded now."""
        def of(name: str) -> tuple[str | None, bool]:
            b = self._bounds.get(_base(name))
            return (b.direction, b.exact) if b is not None else (None, False)
        return ([of(n) for n, _ in self.settings.objectives], [of(n) for n, _, _ in self.settings.constraints])

    def initialized(self, t: float, values: np.ndarray) -> None:
        for p in self._partials:
            p.start(t, values)
        if any(p.broken is not None for p in self._partials):  # e.g. a negative first sample of an integrand
            self._forget_broken()

    def load(self, times: np.ndarray, values: np.ndarray) -> bool:
        for i, t in enumerate(times):  # a warm start's replay: the samples one by one, as the run took them
            (self.initialized if i == 0 else self._add)(float(t), values[i])
        return True

    def _add(self, t: float, values: np.ndarray) -> None:
        broke = False
        for p in self._partials:
            p.add(t, values)
            broke = broke or (p.broken is not None and p.bound.direction is not None)
        if broke:  # at once, not at the next comparison: what the observer reports is what it relies on
            self._forget_broken()

    def step(self, t: float, values: np.ndarray) -> None:
        self._add(t, values)
        self._steps += 1
        # The comparison costs more than a cheap step: it runs once the run has spent OVERHEAD_SHARE**-1 times
        # its last cost since the last one.  Late is never wrong (a bound only moves away from the front), it
        # only stops a design a few steps later; the declarations above are still checked on every sample.
        now = time.perf_counter()
        if now < self._next_check:
            return
        self._compare(t)
        self._next_check = now + (time.perf_counter() - now) / OVERHEAD_SHARE

    def _compare(self, t: float) -> None:
        front = self.front
        if front.refresh is not None and self.checks % front.refresh_every == 0:
            newer = front.refresh()
            if newer is not None:
                newer.refresh, newer.refresh_every = front.refresh, front.refresh_every
                self.front = front = newer
        if not len(front.ids) and not self.settings.constraints:
            return  # nothing to compare with yet
        self.checks += 1
        flat = self._partial_values()
        reason = self._broken_constraint(flat) or self._dominated(flat)
        if reason:
            self.reason, self.stop_time = f"pruned at t={t:.12g}: {reason}", t

    def _forget_broken(self) -> None:
        """A declaration was found broken: its objective (and expressions of it) are unbounded from now on."""
        from cosim.spec.bounds import objective_bounds

        broken = {p.name: p.broken for p in self._partials if p.broken}
        ports = {s.text: s.variable for s in self.system.probes}
        self._bounds = objective_bounds(self.system.spec.objectives, lambda s: ports.get(s), broken)
        for p in self._partials:
            p.bound = self._bounds[p.name]
        self._directions = self._flat_directions()

    def _partial_values(self) -> dict[str, float]:
        values = {p.name: p.current() for p in self._partials}
        with np.errstate(all="ignore"):
            try:
                values = evaluate_expressions(self._exprs, values)
            except Exception:  # an expression of partial values may not evaluate yet (e.g. 0/0): no bound now
                return {}
        return flatten_objectives(values)

    def _bound_vector(self, flat: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
        """(bound, margin) in minimizing form: -inf where unbounded."""
        b = np.full(len(self.settings.objectives), -np.inf)
        margin = np.zeros(len(b))
        for j, ((name, sense), (direction, exact)) in enumerate(zip(self.settings.objectives, self._directions[0])):
            v = flat.get(name, math.nan)
            if not math.isfinite(v) or direction is None:
                continue
            if sense == "minimize" and direction in (UP, FIXED):
                b[j] = v
            elif sense == "maximize" and direction in (DOWN, FIXED):
                b[j] = -v
            margin[j] = 0.0 if exact else MARGIN * abs(b[j])
        return b, margin

    def _dominated(self, flat: Mapping[str, float]) -> str | None:
        b, margin = self._bound_vector(flat)
        if not np.isfinite(b).any() or not len(self.front.ids):
            return None
        limit = b - margin
        front = self.front.values
        le = np.all(front <= limit, axis=1)
        lt = np.any(front < limit, axis=1)
        hits = np.flatnonzero(le & lt)
        if not len(hits):
            return None
        self.dominated_by = self.front.ids[int(hits[0])]
        self.bound = self._bound_record(flat)
        return f"design {self.dominated_by} strictly dominates every value it can still reach"

    def _broken_constraint(self, flat: Mapping[str, float]) -> str | None:
        for (name, op, c), (direction, exact) in zip(self.settings.constraints, self._directions[1]):
            v = flat.get(name, math.nan)
            if direction is None or not math.isfinite(v):
                continue
            m = 0.0 if exact else MARGIN * abs(v)
            if direction in (UP, FIXED) and ((op == "<=" and v - m > c) or (op == "<" and v - m >= c)):
                broken = True
            elif direction in (DOWN, FIXED) and ((op == ">=" and v + m < c) or (op == ">" and v + m <= c)):
                broken = True
            else:
                continue
            if broken:
                self.bound = self._bound_record(flat)
                return f"constraint {name} {op} {c:g} is already broken ({name} reached {v:.6g})"
        return None

    def _bound_record(self, flat: Mapping[str, float]) -> dict[str, float]:
        """Flat name -> the bound of every objective pruned on or constrained (NaN where unbounded)."""
        record: dict[str, float] = {}
        names = [n for n, _ in self.settings.objectives] + [n for n, _, _ in self.settings.constraints]
        directions = self._directions[0] + self._directions[1]
        for name, (direction, _) in zip(names, directions):
            record[name] = float(flat.get(name, math.nan)) if direction is not None else math.nan
        return record

    def objectives_at_stop(self, flat: Mapping[str, float]) -> dict[str, float]:
        """The objective columns of a pruned row: the bound vector where bounded, NaN elsewhere."""
        return {name: self.bound.get(name, math.nan) for name in flat}


def prune_columns(system: Any, settings: PruneSettings) -> set[str]:
    """The probe columns whose samples the bounds of ``settings`` reduce while a design runs."""
    wanted = {_base(n) for n, _ in settings.objectives} | {_base(n) for n, _, _ in settings.constraints}
    needed = _closure(system.spec.objectives, wanted)
    return {c for o in system.spec.objectives if o.signal and o.name in needed for c in columns_of(system, o.signal)}


def _base(name: str) -> str:
    """The objective of a flat column name: 'e_el[3]' -> 'e_el'."""
    return name.split("[", 1)[0]


def _closure(objectives: Sequence[Any], wanted: set[str]) -> set[str]:
    """``wanted`` and every objective their expressions use, transitively."""
    by_name = {o.name: o for o in objectives}
    needed: set[str] = set()
    todo = [n for n in wanted if n in by_name]
    while todo:
        name = todo.pop()
        if name in needed:
            continue
        needed.add(name)
        o = by_name[name]
        if o.expr:
            todo.extend(n for n in parsed_expression(o.expr).names if n in by_name)
    return needed
