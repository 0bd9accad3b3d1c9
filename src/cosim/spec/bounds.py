"""Which way each objective's partial value can still move while a design runs: the static half of pruning.

A run reduces each objective's signal step by step.  For some reductions the value reached so far is a proven
bound on the final one: ``max`` can only grow, ``min`` only shrink, ``integral_abs`` only grow (its integrand is
``|x| >= 0``).  Others hold under a declaration: ``integral`` of a port whose declared ``min`` is ``>= 0`` only
grows (``max <= 0``: only shrinks); ``final`` of a signal the spec declares ``"monotone"`` (``non-decreasing``,
``non-increasing`` or ``constant``, e.g. energy without recuperation, or a duration known at the start) moves only
that way.  A declaration is checked at every communication point by the run's observer
(:class:`cosim.execution.prune.PruneBound`): the first sample that breaks it ends the bound for that design,
which then runs to its end.  A check alone proves nothing of the samples still to come, so an undeclared
signal is never bounded on the strength of its past samples.

An expression objective is bounded where monotonicity is provable from its parts: sums and differences of
bounded parts whose directions agree, products and quotients with a number, ``deg``, ``rad``, ``sum``,
``mean``, ``sqrt``, ``exp``, ``log``, ``min``/``max`` of parts moving the same way.  Anything else (``mean``,
``rms``, ``time_of_*`` reductions, products of two moving parts, ``abs``) is unbounded and never prunes.

Directions: :data:`UP` (the value so far is a lower bound of the final one), :data:`DOWN` (an upper bound),
:data:`FIXED` (known: both) and None (unbounded).  ``exact`` says the bound is the final value's own
arithmetic on the same samples (max, min, final, initial), so a tie is a tie; an integral's running sum may
differ from the final trapezoid in the last bits, and pruning leaves it a relative margin (:data:`MARGIN`).
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

from cosim.spec.expressions import CONSTANTS, parsed_expression

UP, DOWN, FIXED = "non-decreasing", "non-increasing", "fixed"
MONOTONE = (UP, DOWN, "constant")  # what a spec may declare of an objective's signal ("monotone")
MARGIN = 1e-9  # relative: a running integral and the final trapezoid may differ by rounding (n * eps << this)

# functions that keep the direction of their (single or every) argument
_INCREASING = {"deg", "rad", "sum", "mean", "sqrt", "exp", "log", "log10", "min", "max"}


@dataclass(frozen=True)
class Bound:
    """The direction of one objective's partial value (None: unbounded), why, and whether the run checks a
    declaration for it (``check``: ``"monotone"`` with the declared direction, ``"sign"`` for an integral's
    integrand, or None)."""

    name: str
    direction: str | None
    why: str
    exact: bool = True
    check: str | None = None


def _flip(direction: str | None) -> str | None:
    return {UP: DOWN, DOWN: UP}.get(direction, direction) if direction is not None else None


def _combine(a: str | None, b: str | None) -> str | None:
    """The direction of a sum of parts moving ``a`` and ``b``."""
    if a is None or b is None:
        return None
    if a == FIXED:
        return b
    if b == FIXED or a == b:
        return a
    return None  # one grows, one shrinks: nothing is known


def reduction_bound(name: str, reduce: str, variable: Any = None, monotone: str | None = None) -> Bound:
    """The bound of an objective reducing a signal with ``reduce``; ``variable`` is its port
    (:class:`~cosim.units.protocol.Variable`, for its declared ``min``/``max``) and ``monotone`` the spec's
    declaration of the signal (one of :data:`MONOTONE`)."""
    if reduce == "max":
        return Bound(name, UP, "max only grows")
    if reduce == "min":
        return Bound(name, DOWN, "min only shrinks")
    if reduce == "initial":
        return Bound(name, FIXED, "initial value known from the start")
    if reduce == "integral_abs":
        return Bound(name, UP, "integral of |x| >= 0 only grows", exact=False)
    if reduce == "final":
        if monotone == "constant":
            return Bound(name, FIXED, "final of a signal declared constant (checked every step)", check="monotone")
        if monotone in (UP, DOWN):
            return Bound(name, monotone, f"final of a signal declared {monotone} (checked every step)",
                         check="monotone")
        return Bound(name, None, "final of a signal not declared monotone")
    if reduce == "integral":
        low = getattr(variable, "min", None)
        high = getattr(variable, "max", None)
        if low is not None and low >= 0:
            return Bound(name, UP, f"integral of a port declared min {low:g} >= 0 (checked every step)",
                         exact=False, check="sign")
        if high is not None and high <= 0:
            return Bound(name, DOWN, f"integral of a port declared max {high:g} <= 0 (checked every step)",
                         exact=False, check="sign")
        return Bound(name, None, "integral of a port with no declared sign (min >= 0 or max <= 0)")
    return Bound(name, None, f"{reduce} can move either way until the end")


class _Directions:
    """The direction of an expression over known objectives' bounds (design parameters and numbers: fixed)."""

    def __init__(self, bounds: Mapping[str, Bound]):
        self.bounds = bounds

    def of(self, node: ast.AST) -> tuple[str | None, bool]:
        """(direction, exact) of ``node``."""
        if isinstance(node, ast.Constant):
            return FIXED, True
        if isinstance(node, (ast.Name, ast.Attribute)):
            name = ast.unparse(node)
            if name in self.bounds:
                bound = self.bounds[name]
                return bound.direction, bound.exact
            return FIXED, True  # a constant (pi) or a design parameter: known from the start
        if isinstance(node, ast.Subscript):
            return self.of(node.value)
        if isinstance(node, ast.UnaryOp):
            d, exact = self.of(node.operand)
            if isinstance(node.op, ast.USub):
                return _flip(d), exact
            return (d, exact) if isinstance(node.op, ast.UAdd) else (None, exact)
        if isinstance(node, ast.BinOp):
            (a, ea), (b, eb) = self.of(node.left), self.of(node.right)
            exact = ea and eb
            if isinstance(node.op, ast.Add):
                return _combine(a, b), exact
            if isinstance(node.op, ast.Sub):
                return _combine(a, _flip(b)), exact
            if isinstance(node.op, (ast.Mult, ast.Div)):
                number = _number(node.right)
                if number is not None:  # x * c, x / c: the sign of c decides
                    return (a if number > 0 else _flip(a) if number < 0 else FIXED), exact
                number = _number(node.left)
                if number is not None and isinstance(node.op, ast.Mult):
                    return (b if number > 0 else _flip(b) if number < 0 else FIXED), exact
                return (FIXED if a == FIXED and b == FIXED else None), exact
            return (FIXED if a == FIXED and b == FIXED else None), exact
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            parts = [self.of(arg) for arg in node.args]
            exact = all(e for _, e in parts)
            directions = {d for d, _ in parts}
            if directions == {FIXED}:
                return FIXED, exact
            if node.func.id in _INCREASING:
                moving = directions - {FIXED}
                return (moving.pop() if len(moving) == 1 and None not in moving else None), exact
            return None, exact
        return None, False  # comparisons, boolean operations: no direction


def _number(node: ast.AST) -> float | None:
    """The value of a numeric literal (or a named constant, or its negation), else None."""
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
        return float(node.value)
    if isinstance(node, ast.Name) and node.id in ("pi", "e"):
        return float(CONSTANTS[node.id])
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        inner = _number(node.operand)
        return None if inner is None else -inner
    return None


def objective_bounds(objectives: Sequence[Any], port_of: Callable[[str], Any] = lambda signal: None,
                     broken: Mapping[str, str] | None = None) -> dict[str, Bound]:
    """Every objective's :class:`Bound`, in the spec's order.

    ``objectives``: the spec's objective records (``name``, ``signal``, ``reduce``, ``expr``, ``monotone``);
    ``port_of(signal)``: the signal's port (a Variable) or None when unknown.  Expressions are analysed after
    the objectives they use (a cycle, refused by the spec check, leaves the rest unbounded).  ``broken``: reduced
    objectives whose declaration a run found broken (name -> what was seen): unbounded from then on.
    """
    bounds: dict[str, Bound] = {}
    for o in objectives:
        if not o.expr:
            bounds[o.name] = reduction_bound(o.name, o.reduce, port_of(o.signal), getattr(o, "monotone", None))
            if broken and o.name in broken:
                bounds[o.name] = Bound(o.name, None, f"declaration broken: {broken[o.name]}")
    pending = [o for o in objectives if o.expr]
    names = {o.name for o in objectives}
    while pending:
        ready = [o for o in pending if parsed_expression(o.expr).names & names <= bounds.keys()]
        if not ready:
            for o in pending:
                bounds[o.name] = Bound(o.name, None, "expression in a cycle")
            break
        for o in ready:
            tree = ast.parse(o.expr.strip(), mode="eval").body
            direction, exact = _Directions(bounds).of(tree)
            used = sorted(parsed_expression(o.expr).names & names)
            parts = ", ".join(f"{n} {bounds[n].direction or 'unbounded'}" for n in used)
            why = (f"expression of {parts}: " if parts else "expression of numbers and parameters: ") + (
                "monotone" if direction else "no proven direction")
            bounds[o.name] = Bound(o.name, direction, why, exact=exact)
            pending.remove(o)
    return {o.name: bounds[o.name] for o in objectives}


def system_bounds(system: Any) -> dict[str, Bound]:
    """:func:`objective_bounds` of a built system's spec, the ports taken from its probes."""
    ports = {s.text: s.variable for s in system.probes}
    return objective_bounds(system.spec.objectives, lambda signal: ports.get(signal))
