"""Safe arithmetic expressions for objectives and design constraints.

An expression is parsed with Python's ``ast`` module and then *interpreted*
node by node over a whitelist: numbers, names, ``+ - * / // % **``,
comparisons, ``and or not``, a few math functions, and 1-based element access
``name[i]`` on array values.  Nothing is ever passed to ``eval``.
"""

from __future__ import annotations

import ast
import operator
from typing import Any, Callable, Mapping

import numpy as np

from .errors import UserError

FUNCTIONS: dict[str, Callable[..., Any]] = {
    "abs": np.abs, "sqrt": np.sqrt, "exp": np.exp, "log": np.log, "log10": np.log10,
    "sin": np.sin, "cos": np.cos, "tan": np.tan, "deg": np.degrees, "rad": np.radians,
    "sum": np.sum, "mean": np.mean,
    "min": lambda *a: np.min(a[0]) if len(a) == 1 else np.minimum.reduce(a),
    "max": lambda *a: np.max(a[0]) if len(a) == 1 else np.maximum.reduce(a),
}
CONSTANTS = {"pi": np.pi, "e": np.e, "true": True, "false": False, "True": True, "False": False}

_BINARY = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
           ast.FloorDiv: operator.floordiv, ast.Mod: operator.mod, ast.Pow: operator.pow}
_UNARY = {ast.USub: operator.neg, ast.UAdd: operator.pos, ast.Not: np.logical_not}
COMPARISONS = {ast.Lt: operator.lt, ast.LtE: operator.le, ast.Gt: operator.gt, ast.GtE: operator.ge,
            ast.Eq: operator.eq, ast.NotEq: operator.ne}


class ExpressionError(UserError, ValueError):
    """The expression is malformed, uses something not allowed, or names an unknown value."""


class Expression:
    """A parsed, checked expression; ``names`` are the values it needs.

    Raises ExpressionError on construction when the text is not a valid
    expression or uses a construct outside the whitelist.
    """

    def __init__(self, text: str):
        self.text = text
        try:
            self._tree = ast.parse(text.strip(), mode="eval").body
        except SyntaxError as exc:
            raise ExpressionError(f"cannot parse '{text}': {exc.msg} at column {exc.offset}") from None
        self.names: set[str] = set()
        self._check(self._tree)

    @property
    def free_names(self) -> set[str]:
        """Names that must come from the values (all but the built-in constants)."""
        return self.names - CONSTANTS.keys()

    def _check(self, node: ast.AST) -> None:
        if isinstance(node, ast.Constant):
            if not isinstance(node.value, (int, float, bool)):
                raise ExpressionError(f"'{self.text}': only numbers are allowed as constants")
        elif isinstance(node, ast.Name):
            self.names.add(node.id)  # may also be a constant; a value of that name takes precedence
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
            if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS or node.keywords:
                name = getattr(node.func, "id", ast.unparse(node.func))
                raise ExpressionError(f"'{self.text}': unknown function '{name}'; allowed: "
                                      + ", ".join(sorted(FUNCTIONS)))
            for arg in node.args:
                self._check(arg)
        elif isinstance(node, ast.Subscript):
            if not (isinstance(node.value, ast.Name) and isinstance(node.slice, ast.Constant)
                    and isinstance(node.slice.value, int)):
                raise ExpressionError(f"'{self.text}': only name[i] with a whole number i is allowed")
            self.names.add(node.value.id)
        else:
            raise ExpressionError(f"'{self.text}': '{ast.unparse(node)}' is not allowed in an expression")

    def evaluate(self, values: Mapping[str, Any]) -> Any:
        """The value of the expression; raises ExpressionError for an unknown name or bad index."""
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            return self._eval(self._tree, values)

    def _eval(self, node: ast.AST, values: Mapping[str, Any]) -> Any:
        if isinstance(node, ast.Constant):
            return node.value
        if isinstance(node, ast.Name):
            if node.id not in values:
                if node.id in CONSTANTS:
                    return CONSTANTS[node.id]
                raise ExpressionError(f"'{self.text}': unknown name '{node.id}'")
            value = values[node.id]
            return np.asarray(value, dtype=float) if isinstance(value, (list, tuple)) else value
        if isinstance(node, ast.BinOp):
            left, right = self._eval(node.left, values), self._eval(node.right, values)
            if isinstance(node.op, ast.Div):
                return np.divide(np.asarray(left, dtype=float), right)[()]
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
            array = np.atleast_1d(self._eval(node.value, values))
            index = node.slice.value  # type: ignore[attr-defined]
            if not 1 <= index <= array.size:
                raise ExpressionError(f"'{self.text}': index {index} outside 1..{array.size}")
            return array.flat[index - 1]
        raise ExpressionError(f"'{self.text}': cannot evaluate '{ast.unparse(node)}'")
