"""The design space of a spec: parameters -> points with deterministic ids.

:class:`DesignSpace` turns a spec's ``design`` section into design points.
Per parameter (``'unit.param'`` or an element ``'unit.param[i]'``):

- ``{min, max, step}``: an inclusive range.  Values are computed in decimal
  arithmetic from the numbers as written (``0.1`` steps give exactly 0.3, not
  0.30000000000000004); the last value is ``max`` when ``max - min`` is a
  multiple of ``step``, else the last one below it.  All-integer ranges give ints.
- ``{values: [...]}``: those values, in order (each may itself be an array).
- ``{bool: true}``: ``False`` then ``True``.
- array parameters: ``min``/``max``/``step`` given as arrays make each element
  its own range (a scalar among them applies to every element); the point's
  value is the list of element values.

Methods: ``grid`` (full factorial; the first parameter varies slowest) or the
samplers ``lhs``, ``sobol`` and ``random`` (scipy.stats.qmc / numpy, seeded
by ``seed``).  A sampler draws each range uniformly in ``[min, max]`` (snapped
to ``step`` when one is given) and picks list and boolean values with equal
chances.

A ``constraint`` keeps only points where it is true.  It names parameters as
the spec does (``motor.k_m``, ``traj.q_via[2]``), or by the identifier made by
replacing every run of characters that are not letters, digits or ``_`` by a
single ``_``, trailing ones dropped (``motor_k_m``, ``traj_q_via_2``).  The bare
parameter name (``k_m``) works too when no other parameter has it.  An array
parameter's elements are ``name[i]`` (from 1), e.g. ``traj.q_via[2]``.

Point ids are the first 16 hex digits of SHA-256 over the spec digest and the
point's values, so the same point of the same spec always has the same id.
Points are produced lazily: a grid of 100 000 points never exists as 100 000
Python objects at once.
"""

from __future__ import annotations

import collections
import hashlib
import itertools
import json
import math
import warnings
from dataclasses import dataclass
from decimal import Decimal
from typing import Any, Iterator, Sequence

import numpy as np

from cosim.errors import ExpressionError, Problem, SpecError, json_path
from cosim.spec.expressions import Expression, identifier
from cosim.spec.loader import DesignParameterSpec, Spec
from cosim.util import limits

SAMPLERS = ("lhs", "sobol", "random")


@dataclass(frozen=True)
class Point:
    """One design point: its position in the space, its id and ``{target: value}``."""

    index: int
    id: str
    values: dict[str, Any]


expression_name = identifier  # the name a constraint uses for a target ('traj.q_via[2]' -> 'traj_q_via_2')


def flat_columns(target: str, value: Any) -> dict[str, Any]:
    """A parameter's value as table columns: scalars as ``target``, arrays as ``target[i]`` (from 1)."""
    if isinstance(value, (list, tuple, np.ndarray)):
        return {f"{target}[{i}]": v for i, v in enumerate(_flatten(value), start=1)}
    return {target: value}


def _flatten(value: Any) -> list[Any]:
    out: list[Any] = []
    for v in value:
        if isinstance(v, (list, tuple, np.ndarray)):
            out.extend(_flatten(v))
        else:
            out.append(v)
    return out


def _decimal(x: Any) -> Decimal:
    return Decimal(repr(x)) if isinstance(x, float) else Decimal(int(x))


_GRID_NEEDS_A_STEP = ("a grid needs a 'step' for each range",
                      "add 'step', or use method 'lhs', 'sobol' or 'random' with 'samples'; for cosim optimize or "
                      "cosim sensitivity, which draw from [min, max] and need no step, check it with "
                      "'cosim validate SPEC --for optimize' (or --for sensitivity)")


def range_problem(lo: Any, hi: Any, step: Any, grid: bool = True) -> tuple[str, str] | None:
    """(what is wrong, the fix) for a range ``min``/``max``/``step``, or None: the one check of a range.

    ``grid``: the range is stepped (a sampler draws from ``[min, max]`` and
    needs no step).  Used by the design space and by ``cosim validate``.
    """
    if grid and step is None:
        return _GRID_NEEDS_A_STEP
    if isinstance(step, (int, float)) and step <= 0:
        return f"step must be positive, got {step}", "write a positive step"
    if isinstance(lo, (int, float)) and isinstance(hi, (int, float)) and hi < lo:
        return f"max ({hi}) is below min ({lo})", "swap them"
    return None


def _check_range(lo: Any, hi: Any, step: Any, grid: bool = True) -> None:
    problem = range_problem(lo, hi, step, grid)
    if problem is not None:
        raise ValueError(problem[0])


def range_count(lo: Any, hi: Any, step: Any) -> int:
    """How many values ``range_values(lo, hi, step)`` has, computed without making them.

    Raises ValueError for a missing or non-positive step or hi < lo.
    """
    _check_range(lo, hi, step)
    return int((_decimal(hi) - _decimal(lo)) // _decimal(step)) + 1


def range_values(lo: Any, hi: Any, step: Any) -> list[Any]:
    """Inclusive ``lo, lo+step, ..., <= hi`` computed without floating-point drift.

    Ints when all three are ints. Raises ValueError for a missing or non-positive step or hi < lo.
    """
    _check_range(lo, hi, step)
    d_lo, d_step = _decimal(lo), _decimal(step)
    n = int((_decimal(hi) - d_lo) // d_step)
    if all(isinstance(x, int) and not isinstance(x, bool) for x in (lo, hi, step)):
        return [lo + i * step for i in range(n + 1)]
    return [float(d_lo + i * d_step) for i in range(n + 1)]


class _Dimension:
    """One axis of the space: a finite value list, or a continuous range for samplers."""

    def __init__(self, values: list[Any] | None = None, lo: float | None = None, hi: float | None = None,
                 step: Any = None, integer: bool = False):
        self.values = values
        self.lo, self.hi, self.step, self.integer = lo, hi, step, integer

    def __len__(self) -> int:
        return len(self.values) if self.values is not None else 0

    def sample(self, u: float) -> Any:
        """Map u in [0, 1) onto this dimension."""
        if self.values is not None and self.lo is None:
            return self.values[min(int(u * len(self.values)), len(self.values) - 1)]
        assert self.lo is not None and self.hi is not None  # a dimension is either values or a range
        x = self.lo + u * (self.hi - self.lo)
        if self.step is not None:
            # snap to the grid of the range, staying inside it
            k = min(max(round((x - self.lo) / self.step), 0), int((self.hi - self.lo) // self.step + 1e-9))
            x = float(_decimal(self.lo) + k * _decimal(self.step))
        return int(round(x)) if self.integer else float(x)


class _Parameter:
    """One design parameter: one dimension, or one per element (array ranges)."""

    def __init__(self, spec: DesignParameterSpec, sampled: bool, file: str):
        self.target = spec.target
        path = json_path(["design", "parameters", spec.target])
        self.is_array = False
        try:
            if spec.is_bool:
                self.dims = [_Dimension([False, True])]
            elif spec.values is not None:
                counts = collections.Counter(json.dumps(v, sort_keys=True) for v in spec.values)
                repeated = sorted(t for t, n in counts.items() if n > 1)
                if repeated:  # the same point twice would share one id
                    raise ValueError(f"values repeat: {', '.join(repeated[:5])}"
                                     + (f" and {len(repeated) - 5} more" if len(repeated) > 5 else ""))
                self.dims = [_Dimension(list(spec.values))]
            else:
                lo, hi, step = spec.min, spec.max, spec.step
                arrays = [x for x in (lo, hi, step) if isinstance(x, list)]
                if arrays:
                    size = len(arrays[0])
                    if any(len(a) != size for a in arrays):
                        raise ValueError("min, max and step arrays must have the same length")
                    self.is_array = True
                    per = [[x[i] if isinstance(x, list) else x for x in (lo, hi, step)] for i in range(size)]
                else:
                    per = [[lo, hi, step]]
                self.dims = [self._range(a, b, s, sampled) for a, b, s in per]
        except (ValueError, TypeError) as exc:
            fix = (_GRID_NEEDS_A_STEP[1] if str(exc) == _GRID_NEEDS_A_STEP[0]  # not a number to correct: a study
                   else "write numbers with min <= max and a positive step, and each value once")
            raise SpecError([Problem(file, path, str(exc), fix)]) from None

    @staticmethod
    def _range(lo: Any, hi: Any, step: Any, sampled: bool) -> _Dimension:
        integer = all(isinstance(x, int) and not isinstance(x, bool) for x in (lo, hi, step) if x is not None)
        _check_range(lo, hi, step, grid=not sampled)
        if sampled:
            return _Dimension(None, lo, hi, step, integer)
        count, most = range_count(lo, hi, step), limits.limit("points")
        if count > most:  # checked before a single value is made
            raise ValueError(f"the range {lo} .. {hi} in steps of {step} has {count:,} values, more than the "
                             f"limit of {most:,} design points; {limits.raise_hint('points')}")
        return _Dimension(range_values(lo, hi, step))

    def value(self, parts: Sequence[Any]) -> Any:
        return list(parts) if self.is_array else parts[0]


class DesignSpace:
    """The points of a spec's design space (see the module docstring).

    ``len()`` is the number of points (for a constraint it is counted once,
    by evaluating the constraint without keeping the points).  Iterating
    yields :class:`Point` objects lazily, in a deterministic order.
    """

    def __init__(self, spec: Spec, dimensions_only: bool = False):
        self.spec = spec
        design = spec.design
        self.method = design.method
        sampled = self.method in SAMPLERS or dimensions_only
        size = [] if dimensions_only else size_problems(spec)  # before any value or sample is made
        if size:
            raise SpecError(size)
        self.parameters = [_Parameter(p, sampled, spec.path) for p in design.parameters]
        self.targets = [p.target for p in self.parameters]
        self._dims = [d for p in self.parameters for d in p.dims]
        self._samples: np.ndarray | None = None
        if sampled and not dimensions_only:
            if design.samples is None and self.parameters:
                raise SpecError([Problem(spec.path, "$.design.samples", f"method '{self.method}' needs 'samples'",
                                         "add e.g. \"samples\": 100")])
            self._samples = self._draw(design.samples or 1, design.seed)
        self.constraint, self._names = self._constraint(design.constraint)
        self._count: int | None = None

    @classmethod
    def from_spec(cls, spec: Spec) -> "DesignSpace":
        """The design space of ``spec``; raises SpecError for a bad range, sampler or constraint."""
        return cls(spec)

    @classmethod
    def dimensions_of(cls, spec: Spec) -> "DesignSpace":
        """The space's parameters as dimensions (ranges continuous, or stepped where a step is given),
        drawing no points: for drivers that choose the points themselves (optimisation, sensitivity).
        Raises SpecError like :meth:`from_spec`."""
        return cls(spec, dimensions_only=True)

    @property
    def dimensions(self) -> list[tuple[str, "_Dimension"]]:
        """``(flat name, dimension)`` per axis: ``target``, or ``target[i]`` (from 1) for array elements."""
        out = []
        for p in self.parameters:
            for i, dim in enumerate(p.dims, start=1):
                out.append((f"{p.target}[{i}]" if p.is_array else p.target, dim))
        return out

    def values_of(self, flat: Sequence[Any]) -> dict[str, Any]:
        """``{target: value}`` from one value per dimension (in :attr:`dimensions` order)."""
        return self._values(tuple(flat))

    def accepts(self, values: dict[str, Any]) -> bool:
        """Whether the design ``constraint`` holds for ``values`` (True without one)."""
        return self._accepts(values)

    # -- construction helpers -------------------------------------------------
    def _draw(self, n: int, seed: int | None) -> np.ndarray:
        d = len(self._dims)
        if d == 0:
            return np.zeros((1, 0))
        if self.method == "lhs":
            from scipy.stats import qmc

            design: np.ndarray = qmc.LatinHypercube(d, rng=seed).random(n)
            return design
        if self.method == "sobol":
            from scipy.stats import qmc

            with warnings.catch_warnings():  # scipy warns when n is not a power of two; still a valid design
                warnings.simplefilter("ignore")
                design = qmc.Sobol(d, scramble=True, rng=seed).random(n)
                return design
        return np.random.default_rng(seed).random((n, d))

    def _constraint(self, text: str | None) -> tuple[Expression | None, dict[str, str]]:
        names: dict[str, str] = {}
        short: dict[str, list[str]] = {}
        for target in self.targets:
            names[target] = names[expression_name(target)] = target
            bare = target.partition(".")[2]
            short.setdefault(bare, []).append(target)
            if expression_name(bare) != bare:
                short.setdefault(expression_name(bare), []).append(target)
        for name, targets in short.items():
            if len(targets) == 1 and name not in names:
                names[name] = targets[0]
        if not text:
            return None, names
        fix = ("name parameters as the spec does ('motor.k_m', 'traj.q_via[2]') or as identifiers (motor_k_m, "
               "traj_q_via_2); known: " + ", ".join(sorted(self.targets)))
        try:
            expression = Expression(text)
        except ExpressionError as exc:
            raise SpecError([Problem(self.spec.path, "$.design.constraint", str(exc), fix)]) from None
        unknown = expression.unknown_names(names)
        if unknown:
            raise SpecError([Problem(self.spec.path, "$.design.constraint",
                                     f"unknown name(s) in the constraint: {', '.join(unknown)}", fix)])
        return expression, names

    def check(self) -> None:
        """Evaluate the constraint on the first candidate point: a bad index shows before any point runs.

        ``cosim validate`` calls it so that it refuses what a sweep would. Raises SpecError like iterating.
        """
        first = next(self._raw(), None)
        if first is not None and self.parameters:
            self._accepts(self._values(first))

    # -- points ---------------------------------------------------------------
    def _raw(self) -> Iterator[tuple[Any, ...]]:
        """Per candidate point, the flat tuple of dimension values (before the constraint)."""
        if self._samples is not None:
            for row in self._samples:
                yield tuple(dim.sample(u) for dim, u in zip(self._dims, row))
        else:
            grids: list[list[Any]] = []
            for dim in self._dims:
                assert dim.values is not None  # without samples, every dimension is a grid of values
                grids.append(dim.values)
            yield from itertools.product(*grids)

    def _values(self, flat: tuple[Any, ...]) -> dict[str, Any]:
        values, i = {}, 0
        for p in self.parameters:
            values[p.target] = p.value(flat[i:i + len(p.dims)])
            i += len(p.dims)
        return values

    def _accepts(self, values: dict[str, Any]) -> bool:
        if self.constraint is None:
            return True
        scope = {name: values[target] for name, target in self._names.items()}
        try:  # strict: a division by zero or an invalid operation is the spec's mistake, not "true"
            return bool(self.constraint.evaluate(scope, strict=True))
        except (ExpressionError, TypeError, ValueError) as exc:
            raise SpecError([Problem(self.spec.path, "$.design.constraint", str(exc),
                                     "check the indices and names used in the constraint")]) from None

    def point_id(self, values: dict[str, Any]) -> str:
        """The deterministic id of a point with these values (16 hex digits)."""
        text = json.dumps([self.spec.digest, [values[t] for t in self.targets]], default=_json_default,
                          separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def __iter__(self) -> Iterator[Point]:
        index = 0
        # a sampler snapping to steps may draw the same point twice: it is kept once
        seen: set[str] | None = set() if self._samples is not None else None
        for flat in self._raw():
            values = self._values(flat)
            if self._accepts(values):
                pid = self.point_id(values)
                if seen is not None:
                    if pid in seen:
                        continue
                    seen.add(pid)
                yield Point(index, pid, values)
                index += 1

    def __len__(self) -> int:
        if self._count is None:
            if self.constraint is None and self._samples is None:
                self._count = math.prod(len(d) for d in self._dims)
            else:
                self._count = sum(1 for _ in self._raw_ids())
        return self._count

    def _raw_ids(self) -> Iterator[str]:
        if self._samples is None:
            for flat in self._raw():
                if self._accepts(self._values(flat)):
                    yield ""
        else:
            yield from (p.id for p in self)

    def head(self, n: int) -> list[Point]:
        """The first ``n`` points."""
        return list(itertools.islice(iter(self), n))

    def spread(self, n: int) -> list[Point]:
        """``n`` points evenly spaced over the whole space: the first, the last and between (all when fewer).

        For estimates from a few runs: the first points of a grid differ only in the fastest-varying
        parameter and may all be cheap (or all dear), so the sample is taken across the enumeration.
        """
        total = len(self)
        if total <= n:
            return list(self)
        wanted = sorted({round(k * (total - 1) / (n - 1)) for k in range(n)}) if n > 1 else [0]
        picked: list[Point] = []
        for point in self:
            if point.index == wanted[len(picked)]:
                picked.append(point)
                if len(picked) == len(wanted):
                    break
        return picked

    def stratified(self, n: int, seed: int = 0) -> list[Point]:
        """About ``n`` points that together cover every parameter's range (all points when there are at most ``n``).

        A Latin hypercube over the grid's axes: each axis is cut into ``n`` equal strata and each stratum of
        each axis holds one point (an axis with at most ``n`` values gets each value, about equally often).
        For estimates from a few runs: where the dear points of a space lie along any parameter, a share of
        the sample in proportion to their region's size lands there, where :meth:`spread`, striding through
        the enumeration, covers only the slowest-varying parameter evenly. Two hypercube points falling in
        one grid cell give one point, so a small grid may give fewer than ``n``. A constrained grid takes,
        per hypercube point, the nearest accepted point; a sampled space (lhs, sobol, random) is
        space-filling already and is spread evenly over its draw. Deterministic for a given ``seed``; in
        enumeration order. Raises SpecError like iterating (a constraint that cannot be evaluated).
        """
        if len(self) <= n:
            return list(self)
        if self._samples is not None or not self._dims:
            return self.spread(n)
        sizes = [len(d) for d in self._dims]
        cells = self._latin_cells(n, sizes, seed)
        if self.constraint is not None:
            return self._nearest_accepted(cells, sizes)
        points = []
        for index in sorted({int(np.ravel_multi_index(tuple(row), sizes)) for row in cells}):
            values = self._values(self._flat_at(np.unravel_index(index, sizes)))
            points.append(Point(index, self.point_id(values), values))
        return points

    @staticmethod
    def _latin_cells(n: int, sizes: list[int], seed: int, tries: int = 64) -> np.ndarray:
        """``n`` grid cells (value indices per axis) of a centred Latin hypercube: the k-th stratum of an axis of
        m values is the value at (k + 1/2) m / n, so every value is taken when m <= n; the strata are paired
        across axes at random, keeping the pairing of ``tries`` with the fewest cells taken twice."""
        rng = np.random.default_rng(seed)
        strata = (np.arange(n) + 0.5) / n
        best: np.ndarray | None = None
        for _ in range(tries):
            cells = np.column_stack([rng.permutation((strata * m).astype(int)) for m in sizes])
            if best is None or len(np.unique(cells, axis=0)) > len(np.unique(best, axis=0)):
                best = cells
            if len(np.unique(best, axis=0)) == n:
                break
        assert best is not None  # tries >= 1
        return best

    def _flat_at(self, cell: Sequence[Any]) -> tuple[Any, ...]:
        """The dimension values of one grid cell (one value index per dimension)."""
        return tuple(dim.values[int(k)] for dim, k in zip(self._dims, cell) if dim.values is not None)

    def _nearest_accepted(self, cells: np.ndarray, sizes: list[int]) -> list[Point]:
        """Per target cell, the accepted grid point nearest to it (axes scaled to [0, 1]); one pass over the grid."""
        scale = np.array(sizes, dtype=float)
        targets = (cells + 0.5) / scale
        best: list[tuple[float, Point] | None] = [None] * len(cells)
        index = 0
        for cell in itertools.product(*(range(s) for s in sizes)):
            values = self._values(self._flat_at(cell))
            if not self._accepts(values):
                continue
            distance = (((np.array(cell) + 0.5) / scale - targets) ** 2).sum(axis=1)
            for k in np.flatnonzero([b is None or d < b[0] for b, d in zip(best, distance)]):
                best[k] = (float(distance[k]), Point(index, self.point_id(values), values))
            index += 1
        picked = {b[1].index: b[1] for b in best if b is not None}
        return [picked[i] for i in sorted(picked)]

    def columns(self, values: dict[str, Any]) -> dict[str, Any]:
        """A point's values as flat table columns (arrays as ``target[i]``)."""
        out: dict[str, Any] = {}
        for target in self.targets:
            out.update(flat_columns(target, values[target]))
        return out


def size_problems(spec: Spec) -> list[Problem]:
    """Design spaces larger than the ``points`` limit, counted without making a single point.

    A grid has the product of its parameters' value counts (a range counts
    ``floor((max - min) / step) + 1`` values, an array range the product over
    its elements), a sampler ``samples`` points.  Parameters whose numbers
    are malformed are left to the other checks.
    """
    design, most = spec.design, limits.limit("points")
    fix = f"use fewer values or larger steps, or a sampler with fewer samples; {limits.raise_hint('points')}"
    if design.method in SAMPLERS:
        if isinstance(design.samples, int) and design.samples > most:
            return [Problem(spec.path, "$.design.samples", f"{design.samples:,} samples, more than the limit of "
                            f"{most:,} design points", fix)]
        return []
    total, factors = 1, []
    for p in design.parameters:
        try:
            count = _value_count(p)
        except (TypeError, ValueError, ArithmeticError):
            continue
        if count > most:
            return [Problem(spec.path, json_path(["design", "parameters", p.target]), f"{count:,} values, more "
                            f"than the limit of {most:,} design points", fix)]
        total *= count
        factors.append(str(count))
    if total > most:
        return [Problem(spec.path, "$.design", f"the grid has {total:,} points ({' x '.join(factors)}), more "
                        f"than the limit of {most:,}", fix)]
    return []


def _value_count(p: DesignParameterSpec) -> int:
    if p.is_bool:
        return 2
    if p.values is not None:
        return len(p.values)
    arrays = [x for x in (p.min, p.max, p.step) if isinstance(x, list)]
    size = len(arrays[0]) if arrays else 1
    count = 1
    for i in range(size):
        lo, hi, step = (x[i] if isinstance(x, list) else x for x in (p.min, p.max, p.step))
        count *= range_count(lo, hi, step)
    return count


def _json_default(x: Any) -> Any:
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"not JSON serializable: {type(x).__name__}")
