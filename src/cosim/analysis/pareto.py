"""Non-dominated (Pareto-optimal) rows of a table of objective values.

Rules:

- A row *dominates* another when it is no worse in every objective and
  strictly better in at least one.
- Rows with the same objective values (ties) do not dominate each other:
  when one of them is on the front, all of them are.
- A row with a missing value (NaN) in any chosen objective is never on the
  front and never dominates another row.

Two objectives use an O(n log n) sweep over the lexicographically sorted
unique rows; more objectives use a cull that removes, vectorized, every row
dominated by the next front member (O(n * front size)).  Above 10 000 rows, the rows dominated by a few
pivots (each objective's best row, the best by the scaled sum) are dropped first: 10^6 random rows leave
a few thousand.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np

if TYPE_CHECKING:
    from cosim.analysis.table import ResultsTable


PREFILTER_ABOVE = 10_000  # rows from which the rows a few pivots dominate are dropped first


def pareto_mask(values: np.ndarray, senses: Sequence[str] | None = None) -> np.ndarray:
    """Boolean mask of the non-dominated rows of ``values`` (n rows, k objectives).

    ``senses`` gives 'min' or 'max' per column (default: all 'min').
    Raises ValueError when the shapes do not fit or a sense is unknown.
    """
    values = np.asarray(values, dtype=float)
    if values.ndim != 2:
        raise ValueError("values must be a 2-D array (rows x objectives)")
    n, k = values.shape
    senses = list(senses) if senses is not None else ["min"] * k
    if len(senses) != k:
        raise ValueError(f"{k} objective column(s) but {len(senses)} sense(s)")
    signs = np.array([_sign(s) for s in senses])
    mask = np.zeros(n, dtype=bool)
    if n == 0 or k == 0:
        return mask
    finite = ~np.isnan(values).any(axis=1)
    rows = values[finite] * signs  # every objective is now minimized
    if len(rows) == 0:
        return mask
    where = np.flatnonzero(finite)
    if len(rows) > PREFILTER_ABOVE:  # most rows of a large table are dominated by one of a few good ones
        keep = ~_dominated_by_pivots(rows)
        rows, where = rows[keep], where[keep]
    unique, inverse = _unique_rows(rows)
    front_unique = _front_2d(unique) if k == 2 else (_front_1d(unique) if k == 1 else _front_cull(unique))
    mask[where] = front_unique[inverse]
    return mask


def _dominated_by_pivots(rows: np.ndarray) -> np.ndarray:
    """Rows (all objectives minimised) dominated by one of a few pivot rows: the best of each column and the
    best by the sum of the columns scaled to [0, 1].  Dropping them changes no other row's fate: whatever one of
    them dominates, its pivot dominates too."""
    columns = np.ascontiguousarray(rows.T)  # column by column: numpy's row-wise all/any are slow on n x 2
    score = np.zeros(len(rows))
    for c in columns:
        lo, hi = c.min(), c.max()
        with np.errstate(invalid="ignore"):
            score += np.nan_to_num((c - lo) / (hi - lo) if hi > lo else 0.0 * c, nan=0.0, posinf=1.0, neginf=0.0)
    pivots = {int(c.argmin()) for c in columns} | {int(score.argmin())}
    out = np.zeros(len(rows), dtype=bool)
    for i in pivots:
        no_worse, better = np.ones(len(rows), dtype=bool), np.zeros(len(rows), dtype=bool)
        for c, p in zip(columns, rows[i]):
            no_worse &= c >= p
            better |= c > p
        out |= no_worse & better
    return out


def _unique_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the distinct rows sorted lexicographically, the index of each row's distinct row): what
    ``np.unique(rows, axis=0, return_inverse=True)`` gives, by one lexsort of the columns (np.unique sorts the rows
    as opaque byte strings: 7 s for 10^6 rows against 0.2 s here; it also told -0.0 from 0.0)."""
    order = np.lexsort(rows.T[::-1])  # the last key is the primary one: column 0 first
    ordered = rows[order]
    new = np.ones(len(rows), dtype=bool)
    new[1:] = np.any(ordered[1:] != ordered[:-1], axis=1)
    inverse = np.empty(len(rows), dtype=np.int64)
    inverse[order] = np.cumsum(new) - 1
    return ordered[new], inverse


def _sign(sense: str) -> float:
    s = sense.lower()
    if s in ("min", "minimize"):
        return 1.0
    if s in ("max", "maximize"):
        return -1.0
    raise ValueError(f"unknown sense '{sense}': use min or max")


def _front_1d(unique: np.ndarray) -> np.ndarray:
    out = np.zeros(len(unique), dtype=bool)
    out[0] = True  # np.unique sorts ascending: the smallest value is the only optimum
    return out


def _front_2d(unique: np.ndarray) -> np.ndarray:
    """Unique rows sorted lexicographically: a row is dominated iff an earlier row has f2 <= its f2."""
    f2 = unique[:, 1]
    best_before = np.concatenate(([np.inf], np.minimum.accumulate(f2)[:-1]))
    return f2 < best_before


def _front_cull(unique: np.ndarray) -> np.ndarray:
    """The lexicographically first remaining row is always non-dominated; drop what it dominates."""
    remaining = np.arange(len(unique))
    front: list[int] = []
    while remaining.size:
        p = remaining[0]
        front.append(p)
        rest = unique[remaining[1:]]
        dominated = np.all(unique[p] <= rest, axis=1)  # rows are unique, so <= everywhere means strictly somewhere
        remaining = remaining[1:][~dominated]
    out = np.zeros(len(unique), dtype=bool)
    out[front] = True
    return out


def front_of(table: "ResultsTable", objectives: list[tuple[str, str]], where: str | None = None):
    """(mask of front rows, rows considered): ok, feasible rows passing ``where``, every objective present."""
    considered = table.ok_mask() & table.feasible_mask() & table.where(where)
    values = np.column_stack([table.values(name) for name, _ in objectives])
    values[~considered] = np.nan
    return pareto_mask(values, [s for _, s in objectives]), considered


def resolve_objectives(table: "ResultsTable", given: list[tuple[str, str]] | None) -> list[tuple[str, str]]:
    """The (column, sense) pairs asked for, or the spec's objectives with a sense; raises AnalysisError."""
    from cosim.analysis.table import AnalysisError

    if given:
        return [(table.check_column(name), sense) for name, sense in given]
    senses = table.objective_senses()
    if not senses:
        raise AnalysisError("no objectives: name them with --min OBJ / --max OBJ (the table's metadata gives "
                            "no objective with a 'sense')")
    return list(senses.items())
