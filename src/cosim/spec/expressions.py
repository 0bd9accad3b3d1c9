"""Safe arithmetic expressions for objectives and design constraints.

An expression is parsed with Python's ``ast`` module and then *interpreted*
node by node over a whitelist: numbers, names, ``+ - * / // % **``,
comparisons, ``and or not``, a few math functions, and 1-based element access
``name[i]`` on array values.  Nothing is ever passed to ``eval``.

Every operation's cost is bounded, so an expression from a hostile spec can
neither hang the client nor exhaust its memory: the text's length and nesting
depth are limited at parse time (``COSIM_EXPRESSION_LENGTH``,
``COSIM_EXPRESSION_DEPTH``), as are the size of number literals and the
functions' argument counts; powers of whole numbers are computed as floats
(``9**9**9`` overflows at once instead of building a number with millions of
digits).  Any failure while evaluating (division of whole numbers by zero,
overflow, a bad index) is an :class:`ExpressionError` with one line of text;
``strict=True`` also turns float division by zero and invalid results into
errors (design constraints use it).

Names may be dotted, as a spec and a results table write them: ``move.v_max``
is one name, and ``traj.waypoints[9]`` is the value named ``traj.waypoints[9]``
when there is one (a table column, a design parameter of one element), else
element 9 of the array ``traj.waypoints``.
"""

from __future__ import annotations

import ast
import functools
import math
import operator
import re
from typing import Any, Callable, Literal, Mapping, Sequence

import numpy as np

from cosim.errors import ExpressionError
from cosim.util import limits


def identifier(name: str) -> str:
    """The name an expression uses for a table column or a design parameter: the one rule of cosim.

    A name that already is an identifier stays as it is.  Otherwise every run
    of characters other than letters, digits and ``_`` becomes one ``_`` and
    the ones at both ends are dropped (``traj.q_via[2]`` -> ``traj_q_via_2``);
    a result that is empty or starts with a digit gets ``c_`` in front.
    """
    if name.isidentifier():
        return name
    text = re.sub(r"[^A-Za-z0-9_]+", "_", name).strip("_")
    return text if text and not text[0].isdigit() else f"c_{text}"


FUNCTIONS: dict[str, Callable[..., Any]] = {
    "abs": np.abs, "sqrt": np.sqrt, "exp": np.exp, "log": np.log, "log10": np.log10,
    "sin": np.sin, "cos": np.cos, "tan": np.tan, "deg": np.degrees, "rad": np.radians,
    "sum": np.sum, "mean": np.mean,
    "min": lambda *a: np.min(a[0]) if len(a) == 1 else np.minimum.reduce(a),
    "max": lambda *a: np.max(a[0]) if len(a) == 1 else np.maximum.reduce(a),
}
# how many arguments each function takes: (fewest, most); None: any number
_ARITY: dict[str, tuple[int, int | None]] = {name: (1, 1) for name in FUNCTIONS}
_ARITY.update(min=(1, None), max=(1, None))
MAX_LITERAL = 1e308  # number literals beyond a float's range are refused
CONSTANTS = {"pi": np.pi, "e": np.e, "true": True, "false": False, "True": True, "False": False}

_BINARY: dict[type[ast.operator], Callable[[Any, Any], Any]] = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
           ast.FloorDiv: operator.floordiv, ast.Mod: operator.mod, ast.Pow: operator.pow}
_UNARY: dict[type[ast.unaryop], Callable[[Any], Any]] = {ast.USub: operator.neg, ast.UAdd: operator.pos, ast.Not: np.logical_not}
COMPARISONS = {ast.Lt: operator.lt, ast.LtE: operator.le, ast.Gt: operator.gt, ast.GtE: operator.ge,
            ast.Eq: operator.eq, ast.NotEq: operator.ne}


class Expression:
    """A parsed, checked expression; ``names`` are the values it needs.

    Raises ExpressionError on construction when the text is not a valid
    expression or uses a construct outside the whitelist.
    """

    def __init__(self, text: str):
        self.text = text
        self._shown = text if len(text) <= 80 else text[:77] + "..."
        longest = limits.limit("expression_length")
        if len(text) > longest:
            raise ExpressionError(f"'{self._shown}': {len(text)} characters, more than the limit of {longest}; "
                                  f"{limits.raise_hint('expression_length')}")
        try:
            self._tree = ast.parse(text.strip(), mode="eval").body
        except SyntaxError as exc:
            raise ExpressionError(f"cannot parse '{self._shown}': {exc.msg} at column {exc.offset}") from None
        except (RecursionError, MemoryError, ValueError) as exc:  # the parser's own limits
            raise ExpressionError(f"cannot parse '{self._shown}': nested too deeply for the parser "
                                  f"({type(exc).__name__})") from None
        self._check_depth(self._tree)
        self.names: set[str] = set()
        self._elements: set[tuple[str, int]] = set()  # (name, i) of every name[i]
        self._bare: set[str] = set()  # names used without [i]
        self._check(self._tree)

    def _check_depth(self, tree: ast.AST) -> None:
        """Refuse nesting deeper than the limit (iteratively: the recursive checks below need it bounded)."""
        deepest = limits.limit("expression_depth")
        stack = [(tree, 1)]
        while stack:
            node, depth = stack.pop()
            if depth > deepest:
                raise ExpressionError(f"'{self._shown}': nested more than {deepest} levels deep; "
                                      f"{limits.raise_hint('expression_depth')}")
            stack.extend((child, depth + 1) for child in ast.iter_child_nodes(node))

    @property
    def free_names(self) -> set[str]:
        """Names that must come from the values (all but the built-in constants)."""
        return self.names - CONSTANTS.keys()

    @property
    def lookups(self) -> set[str]:
        """Every name evaluation may look up: the names, and ``name[i]`` for each element used."""
        return self.names | {f"{name}[{i}]" for name, i in self._elements}

    def unknown_names(self, known: set[str] | Mapping[str, Any]) -> list[str]:
        """The names this expression needs that ``known`` lacks, sorted.

        ``name[i]`` is satisfied by a value ``name[i]`` or by an array ``name``.
        """
        missing = {n for n in self._bare if n not in known and n not in CONSTANTS}
        missing |= {f"{n}[{i}]" for n, i in self._elements if n not in known and f"{n}[{i}]" not in known}
        return sorted(missing)

    def _check(self, node: ast.AST) -> None:
        if isinstance(node, ast.Constant):
            if not isinstance(node.value, (int, float, bool)):
                raise ExpressionError(f"'{self._shown}': only numbers are allowed as constants")
            if not isinstance(node.value, bool) and abs(node.value) > MAX_LITERAL:
                raise ExpressionError(f"'{self._shown}': the number {str(node.value)[:20]}... is too large "
                                      f"(at most {MAX_LITERAL:g})")
        elif isinstance(node, (ast.Name, ast.Attribute)):
            self.names.add(self._dotted(node))  # may also be a constant; a value of that name takes precedence
            self._bare.add(self._dotted(node))
        elif isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            self._check(node.left)
            self._check(node.right)
        elif isinstance(node, ast.UnaryOp) and type(node.op) in _UNARY:
            self._check(node.operand)
        elif isinstance(node, ast.BoolOp):
            for value in node.values:
                self._check(value)
        elif isinstance(node, ast.Compare) and all(type(op) in COMPARISONS for op in node.ops):
            self._check(node.left)
            for comparator in node.comparators:
                self._check(comparator)
        elif isinstance(node, ast.Call):
            if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
                name = getattr(node.func, "id", ast.unparse(node.func))
                raise ExpressionError(f"'{self._shown}': unknown function '{name}'; allowed: "
                                      + ", ".join(sorted(FUNCTIONS)))
            if node.keywords:  # max(x, initial=0): a known function, called with a keyword it does not take
                given = ", ".join(f"{k.arg}=" if k.arg else "**" for k in node.keywords)
                example = (f", e.g. {node.func.id}({', '.join(ast.unparse(a) for a in node.args) or 'x'}, 0)"
                           if node.func.id in ("max", "min") else "")
                raise ExpressionError(f"'{self._shown}': {node.func.id}() takes no keyword arguments (got "
                                      f"{given}); give its arguments by position{example}")
            fewest, most = _ARITY[node.func.id]
            if len(node.args) < fewest or (most is not None and len(node.args) > most):
                wanted = f"{fewest}" if fewest == most else f"at least {fewest}"
                raise ExpressionError(f"'{self._shown}': {node.func.id}() takes {wanted} argument(s), "
                                      f"got {len(node.args)}")
            for arg in node.args:
                self._check(arg)
        elif isinstance(node, ast.Subscript):
            if not (isinstance(node.value, (ast.Name, ast.Attribute)) and isinstance(node.slice, ast.Constant)
                    and isinstance(node.slice.value, int) and not isinstance(node.slice.value, bool)):
                # bool is an int to Python: x[True] would read x[1]
                raise ExpressionError(f"'{self._shown}': only name[i] with a whole number i is allowed")
            self.names.add(self._dotted(node.value))
            self._elements.add((self._dotted(node.value), node.slice.value))
        else:
            raise ExpressionError(f"'{self._shown}': '{ast.unparse(node)}' is not allowed in an expression")

    def _dotted(self, node: ast.AST) -> str:
        """'a.b.c' for the attribute chain a.b.c of plain names (a spec's 'unit.port'); raises otherwise."""
        if isinstance(node, ast.Name):
            return node.id
        if isinstance(node, ast.Attribute) and not node.attr.startswith("__"):  # a name, never an attribute
            return f"{self._dotted(node.value)}.{node.attr}"
        raise ExpressionError(f"'{self._shown}': '{ast.unparse(node)}' is not allowed in a name")

    def evaluate(self, values: Mapping[str, Any], strict: bool = False) -> Any:
        """The value of the expression.

        Raises ExpressionError (one line) for an unknown name, a bad index, a
        division of whole numbers by zero, an overflow or any other failure of
        an operation.  With ``strict``, float division by zero and invalid
        operations (``0/0``, ``sqrt(-1)``) are errors too instead of inf/NaN.
        """
        mode: Literal["raise", "ignore"] = "raise" if strict else "ignore"
        try:
            with np.errstate(divide=mode, invalid=mode, over=mode):
                return self._eval(self._tree, values)
        except ExpressionError:
            raise
        except (ArithmeticError, ValueError, TypeError, IndexError) as exc:
            raise ExpressionError(f"'{self._shown}': cannot evaluate: {_reason(exc)}") from None

    def _eval(self, node: ast.AST, values: Mapping[str, Any]) -> Any:
        if isinstance(node, ast.Constant):
            return node.value
        if isinstance(node, (ast.Name, ast.Attribute)):
            name = self._dotted(node)
            if name not in values:
                if name in CONSTANTS:
                    return CONSTANTS[name]
                raise ExpressionError(f"'{self._shown}': unknown name '{name}'")
            value = values[name]
            return np.asarray(value, dtype=float) if isinstance(value, (list, tuple)) else value
        if isinstance(node, ast.BinOp):
            left, right = self._eval(node.left, values), self._eval(node.right, values)
            if isinstance(node.op, ast.Div):
                return np.divide(np.asarray(left, dtype=float), right)[()]
            if isinstance(node.op, ast.Pow):
                return _power(left, right)
            if isinstance(left, float) or isinstance(right, float):
                left = np.float64(left)  # numpy floats follow errstate: strict makes 1e308 * 10 an overflow error
            return _BINARY[type(node.op)](left, right)
        if isinstance(node, ast.UnaryOp):
            return _UNARY[type(node.op)](self._eval(node.operand, values))
        if isinstance(node, ast.BoolOp):
            results = [bool(self._eval(v, values)) for v in node.values]
            return all(results) if isinstance(node.op, ast.And) else any(results)
        if isinstance(node, ast.Compare):
            left = self._eval(node.left, values)
            for op, comparator in zip(node.ops, node.comparators):
                right = self._eval(comparator, values)
                if not COMPARISONS[type(op)](left, right):
                    return False
                left = right
            return True
        if isinstance(node, ast.Call):
            return FUNCTIONS[node.func.id](*[self._eval(a, values) for a in node.args])  # type: ignore[attr-defined]
        if isinstance(node, ast.Subscript):
            index = node.slice.value  # type: ignore[attr-defined]
            element = f"{self._dotted(node.value)}[{index}]"
            if element in values:  # a value named like the element: a table column, a one-element parameter
                return values[element]
            array = np.atleast_1d(self._eval(node.value, values))
            if not 1 <= index <= array.size:
                raise ExpressionError(f"'{self._shown}': index {index} outside 1..{array.size}")
            return array.flat[index - 1]
        raise ExpressionError(f"'{self._shown}': cannot evaluate '{ast.unparse(node)}'")


def _power(base: Any, exponent: Any) -> Any:
    """``base ** exponent`` in floating point, so its cost never depends on the size of the result.

    Python computes ``int ** int`` exactly, and ``9**9**9`` would build a
    number with hundreds of millions of digits; as floats it overflows at once
    (OverflowError, or inf for numpy arrays).
    """
    if isinstance(base, (int, np.integer)) and not isinstance(base, bool):
        base = float(base)
    if isinstance(base, np.ndarray) and base.dtype.kind in "iub":
        base = base.astype(float)
    if isinstance(exponent, (int, np.integer)) and not isinstance(exponent, bool):
        exponent = float(exponent)
    result = operator.pow(base, exponent)
    if isinstance(result, float) and math.isinf(result) and math.isfinite(base) and math.isfinite(exponent):
        raise OverflowError("power overflowed")
    return result


def _reason(exc: BaseException) -> str:
    """One line saying why an operation failed."""
    text = str(exc).splitlines()[0] if str(exc) else ""
    if isinstance(exc, ZeroDivisionError) or "divide by zero" in text:
        return "division by zero"
    if isinstance(exc, OverflowError) or "overflow" in text:
        return "the result is too large"
    if "invalid value" in text:
        return "invalid operation (the result is not a number)"
    return f"{type(exc).__name__}: {text}"


@functools.lru_cache(maxsize=512)
def parsed_expression(text: str) -> Expression:
    """``Expression(text)``, parsed once per process: a sweep evaluates the same few expressions at every point
    (parsing costs more than a fast point's reductions).  Expressions are never changed after parsing."""
    return Expression(text)


def evaluate_expressions(objectives: Sequence[Any], values: Mapping[str, Any]) -> dict[str, Any]:
    """Add the expression objectives to ``values`` (dependencies first).

    ``objectives`` are the spec's objective records (``name`` and ``expr``, None for a reduced signal).

    Raises ExpressionError when an expression cannot be evaluated.
    """
    result = dict(values)
    pending = [o for o in objectives if o.expr]
    parsed = {o.name: parsed_expression(o.expr) for o in pending}
    names = {o.name for o in objectives}
    while pending:
        ready = [o for o in pending if parsed[o.name].names & names <= result.keys()]
        if not ready:  # cycles are refused by the system check; this is a safety net
            raise ValueError("objective expressions refer to each other in a cycle")
        for o in ready:
            value = parsed[o.name].evaluate(result)
            result[o.name] = float(value) if np.ndim(value) == 0 else np.asarray(value, dtype=float)
            pending.remove(o)
    return result
