"""What a designer decides with, over one results table: filters, objectives, weights, ranking, selection.

:class:`Decision` is the state of the decision room (``cosim explore``), kept
apart from any view so that it is tested without a browser:

- **filters**: a range per numeric column (:class:`cosim.analysis.filters.RangeFilters`);
  ``active()`` are the rows inside every narrowed range;
- **objectives**: (column, 'min'|'max') pairs, by default every objective with a
  sense (the optimisation's, then the spec's others: :meth:`ResultsTable.sensed_objectives`);
- **candidates**: the active rows that are ok, feasible and have a value in
  every objective: the rows the Pareto front and the ranking are made of;
- **Pareto front**: the non-dominated candidates (:func:`cosim.analysis.pareto.pareto_mask`);
- **weights** per objective and a **ranking** by weighted sum or TOPSIS
  (:mod:`cosim.analysis.ranking`) of the candidates;
- **selection**: the rows the designer picked (row positions, in pick order),
  exported as CSV or as ``cosim run --point`` commands, and re-run with the
  spec's recorded signals (:func:`cosim.analysis.rerun.rerun_rows`).
"""

from __future__ import annotations

import shlex
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from cosim.analysis.filters import RangeFilters
from cosim.analysis.pareto import pareto_mask
from cosim.analysis.ranking import METHODS, rank_order, scores, utilities
from cosim.analysis.table import AnalysisError, ResultsTable

NOT_OK = ("failed", "timeout", "crashed", "pruned")  # the statuses a row other than 'ok' can have (pruned: bounds)


class Decision:
    """The decision room's state over ``table`` (module docstring)."""

    def __init__(self, table: ResultsTable, objectives: Sequence[tuple[str, str]] | None = None):
        self.table = table
        self.filters = RangeFilters(table)
        self.objectives: list[tuple[str, str]] = []
        self.weights: dict[str, float] = {}
        self.method = "weighted_sum"
        self.selection: list[int] = []
        if objectives is None:
            objectives = [(c, s) for c, s in table.sensed_objectives().items() if c in self.filters.bounds]
        self.set_objectives(objectives)

    # -- objectives and weights -----------------------------------------------------------------------------
    def set_objectives(self, objectives: Sequence[tuple[str, str]]) -> None:
        """Rank and find the front by these (column, 'min'|'max') pairs; a weight already given is kept, a new
        objective weighs 1.  Raises AnalysisError for a column that is not numeric or a sense other than min/max."""
        checked = []
        for name, sense in objectives:
            if sense not in ("min", "max"):
                raise AnalysisError(f"objective '{name}': sense '{sense}' is neither 'min' nor 'max'")
            checked.append((self.table.check_column(name), sense))
        self.objectives = checked
        self.weights = {name: self.weights.get(name, 1.0) for name, _ in checked}

    def set_weight(self, objective: str, weight: float) -> None:
        """The weight of one objective (>= 0); raises AnalysisError for an unknown objective or a negative weight."""
        if objective not in self.weights:
            raise AnalysisError(f"'{objective}' is not one of the objectives ranked: {', '.join(self.weights)}")
        if not np.isfinite(weight) or weight < 0:
            raise AnalysisError(f"the weight of '{objective}' must be a number >= 0, not {weight}")
        self.weights[objective] = float(weight)

    def set_method(self, method: str) -> None:
        """'weighted_sum' or 'topsis'; raises AnalysisError for another name."""
        if method not in METHODS:
            raise AnalysisError(f"unknown ranking method '{method}': use one of {', '.join(METHODS)}")
        self.method = method

    # -- derived rows ---------------------------------------------------------------------------------------
    def active(self) -> np.ndarray:
        """Rows inside every narrowed range."""
        return self.filters.active()

    def objective_values(self) -> np.ndarray:
        """The objective columns as a float matrix (rows x objectives)."""
        if not self.objectives:
            return np.zeros((len(self.table.df), 0))
        return np.column_stack([self.filters.values(c) for c, _ in self.objectives])

    def candidates(self) -> np.ndarray:
        """Active rows that are ok, feasible and have every objective (all active ok rows without objectives)."""
        mask = self.active() & self.table.ok_mask() & self.table.feasible_mask()
        return mask & np.all(np.isfinite(self.objective_values()), axis=1)

    def pareto(self) -> np.ndarray:
        """Mask of the non-dominated candidates (none without objectives)."""
        values = self.objective_values()
        front = np.zeros(len(values), dtype=bool)
        if not self.objectives:
            return front
        rows = np.flatnonzero(self.candidates())
        front[rows] = pareto_mask(values[rows], [s for _, s in self.objectives])
        return front

    def scores(self) -> np.ndarray:
        """Score of every row by the current method and weights (higher is better); NaN outside the candidates
        and where every weight is 0 or there is no objective."""
        out = np.full(len(self.table.df), np.nan)
        weights = [self.weights[c] for c, _ in self.objectives]
        if not self.objectives or sum(weights) == 0:
            return out
        rows = np.flatnonzero(self.candidates())
        if rows.size:
            out[rows] = scores(self.objective_values()[rows], [s for _, s in self.objectives], weights, self.method)
        return out

    def ranking(self, top: int | None = None, score: np.ndarray | None = None) -> np.ndarray:
        """Row positions of the scored candidates, best first, ties in row order (at most ``top``); ``score`` is
        :meth:`scores` when the caller has it already."""
        score = self.scores() if score is None else score
        rows = np.flatnonzero(np.isfinite(score))
        if top is not None and top < rows.size:  # sort only the rows that can be among the top (ties kept)
            key = -score[rows]
            rows = rows[key <= np.partition(key, top - 1)[top - 1]]
        order = rows[rank_order(score[rows])]
        return order if top is None else order[:top]

    def profile(self, rows: Sequence[int]) -> np.ndarray:
        """Utilities in [0, 1] (1 best, scaled over the candidates) of ``rows`` for each objective, for a radar
        chart: a row that is not a candidate (filtered out, failed) gets NaN."""
        out = np.full((len(rows), len(self.objectives)), np.nan)
        if not self.objectives or not len(rows):
            return out
        candidates = np.flatnonzero(self.candidates())
        if candidates.size:
            u = utilities(self.objective_values()[candidates], [s for _, s in self.objectives])
            where = np.full(len(self.table.df), -1)
            where[candidates] = np.arange(candidates.size)
            for i, r in enumerate(rows):
                if where[int(r)] >= 0:
                    out[i] = u[where[int(r)]]
        return out

    def status_counts(self) -> dict[str, int]:
        """Rows per status ('ok' for every row of a table without a status column)."""
        if "status" not in self.table.df.columns:
            return {"ok": len(self.table.df)}
        return {str(k): int(v) for k, v in self.table.df["status"].astype(str).value_counts().items()}

    # -- selection ------------------------------------------------------------------------------------------
    def select(self, rows: Sequence[int]) -> None:
        """Replace the selection by ``rows`` (duplicates dropped, order kept); raises IndexError outside the
        table."""
        n = len(self.table.df)
        chosen: list[int] = []
        for r in rows:
            r = int(r)
            if not 0 <= r < n:
                raise IndexError(f"row {r} outside 0..{n - 1}")
            if r not in chosen:
                chosen.append(r)
        self.selection = chosen

    def selected_frame(self) -> pd.DataFrame:
        """The selected rows, every column, in pick order."""
        return self.table.df.iloc[self.selection]

    def selection_csv(self) -> str:
        """The selected rows as CSV text (a header and one line per design)."""
        return self.selected_frame().to_csv(index=False)

    def run_commands(self) -> list[str]:
        """One ``cosim run SPEC --point ID --results FOLDER`` line per selected design (shell-quoted).

        SPEC is the spec file the table's metadata names; without one, ``spec.json`` beside the table, which
        the user must supply.  Raises AnalysisError when the table has no ``point_id`` column.
        """
        if "point_id" not in self.table.df.columns:
            raise AnalysisError(f"{self.table.path} has no point_id column: its designs cannot be named to "
                                "cosim run --point")
        meta = self.table.metadata or {}
        spec = Path(meta["spec_path"]) if meta.get("spec_path") else self.table.path.parent / "spec.json"
        folder = self.table.path.parent
        ids = self.table.df["point_id"].astype(str).to_numpy()
        return [f"cosim run {shlex.quote(str(spec))} --point {shlex.quote(ids[r])} --results "
                f"{shlex.quote(str(folder))}" for r in self.selection]
