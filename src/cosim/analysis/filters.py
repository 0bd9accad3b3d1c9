"""Range filters over the numeric columns of a results table: which rows a user still looks at.

Every numeric column has its *bounds* (finite min and max) and a *range* the
user may narrow.  A row is *active* when, in every narrowed column, its value
lies inside the range; a missing value (NaN) lies outside every narrowed
range, so narrowing an objective drops the failed rows that have none.  A
column left at its bounds filters nothing, NaN included.

The Tk explorer (:mod:`cosim.analysis.explorer`) and the decision room
(:mod:`cosim.analysis.decision`, the web view) share this one implementation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cosim.analysis.table import ResultsTable


@dataclass
class Range:
    lo: float
    hi: float


class RangeFilters:
    """The bounds and user ranges of every numeric column of ``table`` (see the module docstring)."""

    def __init__(self, table: ResultsTable):
        self.table = table
        self.columns = table.numeric_columns()
        self._values = {c: table.values(c) for c in self.columns}
        self.bounds: dict[str, Range] = {}
        for c, v in self._values.items():
            finite = v[np.isfinite(v)]
            self.bounds[c] = Range(float(finite.min()), float(finite.max())) if finite.size else Range(0.0, 0.0)
        self.ranges = {c: Range(b.lo, b.hi) for c, b in self.bounds.items()}

    def values(self, column: str) -> np.ndarray:
        """The column as floats (cached; NaN where missing); raises AnalysisError for an unknown column."""
        if column not in self._values:
            self.table.check_column(column)
        return self._values[column]

    def set_range(self, column: str, lo: float, hi: float) -> None:
        """Narrow (or widen) ``column`` to [lo, hi], clipped to its bounds; lo > hi swaps them.

        Raises AnalysisError (with a suggestion) for a column that is not a numeric column of the table.
        """
        b = self.bounds[self.table.check_column(column)]
        lo, hi = sorted((float(lo), float(hi)))
        self.ranges[column] = Range(max(lo, b.lo), min(hi, b.hi))

    def reset(self, column: str | None = None) -> None:
        """Every column (or only ``column``) back to its bounds."""
        for c in ([column] if column else self.columns):
            b = self.bounds[c]
            self.ranges[c] = Range(b.lo, b.hi)

    def narrowed(self) -> list[str]:
        """Columns whose range is narrower than their bounds, in table order."""
        return [c for c, r in self.ranges.items() if r.lo > self.bounds[c].lo or r.hi < self.bounds[c].hi]

    def active(self) -> np.ndarray:
        """Boolean mask of the rows inside every narrowed range."""
        mask = np.ones(len(self.table.df), dtype=bool)
        for c in self.narrowed():
            v, r = self._values[c], self.ranges[c]
            with np.errstate(invalid="ignore"):
                mask &= (v >= r.lo) & (v <= r.hi)
        return mask
