"""Surrogates of a results table's objectives: fitted, stored in ``DIR/surrogate/``, read back, asked.

``DIR/surrogate/models.json`` holds every number of every surrogate (:mod:`.models`; no pickle, so the C code
of ``cosim export-surrogate`` can evaluate it and a file from elsewhere runs no code), their k-fold Q², the
parameter ranking and the failure classifier; ``DIR/surrogate/summary.csv`` one row per objective.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from cosim.analysis.surrogate.failures import FailureModel, fit_failures
from cosim.analysis.surrogate.fit import FOLDS, Fitted, fit_objective
from cosim.analysis.surrogate.models import model_from_json
from cosim.analysis.surrogate.ranking import Influence, parameter_q2, sobol_ranking
from cosim.analysis.table import ResultsTable
from cosim.errors import AnalysisError, did_you_mean

FORMAT = "cosim-surrogate"
VERSION = 1
MAX_ROWS = 500  # a Gaussian process costs n^3: above this, a random subset of the ok rows is fitted


@dataclass
class ObjectiveSurrogate:
    name: str
    fitted: Fitted
    ranking: list[Influence]
    rows: int  # designs fitted on


@dataclass
class SurrogateSet:
    """The surrogates of one table: same parameters (in this order) for every objective."""

    parameters: list[str]
    objectives: dict[str, ObjectiveSurrogate]
    failures: FailureModel | None
    source: str = ""
    notes: list[str] = field(default_factory=list)

    def predict(self, designs: pd.DataFrame, what: str = "the designs") -> pd.DataFrame:
        """``designs`` with, per objective, ``OBJ`` (the prediction) and ``OBJ_std`` (one standard deviation),
        and ``p_fail`` when failures were modelled.  Raises AnalysisError naming a missing or non-numeric
        parameter column, or a row without a value (``what`` names the table in the message)."""
        x = design_matrix(designs, self.parameters, what)
        out = designs.copy()
        for name, surrogate in self.objectives.items():
            out[name], out[f"{name}_std"] = surrogate.fitted.model.predict(x)
        if self.failures is not None:
            out["p_fail"] = self.failures.probability(x)
        return out

    def summary(self) -> pd.DataFrame:
        """One row per objective: surrogate, Q², RMSE, designs, each parameter's total Sobol index ``ST[p]`` and
        its Q² (coefficient of prognosis of the parameter, :func:`.ranking.parameter_q2`) ``Q2[p]``."""
        rows = []
        for name, s in self.objectives.items():
            row: dict[str, Any] = {"objective": name, "surrogate": s.fitted.candidate, "q2": s.fitted.q2,
                                   "rmse": s.fitted.rmse, "designs": s.rows,
                                   "ranking": " > ".join(i.parameter for i in s.ranking)}
            row.update({f"ST[{i.parameter}]": i.total for i in s.ranking})
            row.update({f"Q2[{i.parameter}]": parameter_q2(s.fitted.q2, i) for i in s.ranking})
            rows.append(row)
        return pd.DataFrame(rows)

    def to_json(self) -> dict[str, Any]:
        return {"format": FORMAT, "version": VERSION, "source": self.source, "parameters": self.parameters,
                "notes": self.notes,
                "objectives": {name: {"model": s.fitted.model.to_json(), "q2": s.fitted.q2, "rmse": s.fitted.rmse,
                                      "candidate": s.fitted.candidate, "tried": s.fitted.tried, "rows": s.rows,
                                      "simulated": s.fitted.simulated,
                                      "cross_validated": s.fitted.cross_validated,
                                      "ranking": [vars(i) for i in s.ranking],
                                      "parameter_q2": {i.parameter: parameter_q2(s.fitted.q2, i)
                                                       for i in s.ranking}}
                               for name, s in self.objectives.items()},
                "failures": self.failures.to_json() if self.failures is not None else None}


def design_matrix(frame: pd.DataFrame, parameters: list[str], what: str) -> np.ndarray:
    """The parameter columns of ``frame`` as an (n, d) float array; AnalysisError for a missing column or value."""
    missing = [p for p in parameters if p not in frame.columns]
    if missing:
        raise AnalysisError(f"{what}: no column '{missing[0]}'.{did_you_mean(missing[0], map(str, frame.columns))} "
                            f"Give one column per design parameter: {', '.join(parameters)}")
    x = frame[parameters].apply(pd.to_numeric, errors="coerce").to_numpy(float)
    bad = np.argwhere(~np.isfinite(x))
    if len(bad):
        row, col = bad[0]
        raise AnalysisError(f"{what}: row {row + 1}, column '{parameters[col]}' has no number "
                            f"({frame[parameters[col]].iloc[row]!r}); give a number for every design parameter")
    return x


def fit_table(table: ResultsTable, objectives: list[str] | None = None, method: str = "auto",
              max_rows: int = MAX_ROWS, seed: int = 0, folds: int = FOLDS) -> SurrogateSet:
    """A surrogate per objective (default: every objective column the spec names) on the table's ok rows.

    Parameters are the spec's design parameters that vary.  Raises AnalysisError when the table has no
    spec (so no known parameters), an objective column is unknown, or too few ok rows have a value.
    """
    parameters = [p for p in table.parameter_columns() if p in table.numeric_columns()]
    if not parameters:
        raise AnalysisError(f"{table.path}: no design parameters known (no metadata.json with the spec beside the "
                            "table); give the spec with --spec spec.json")
    notes = []
    constant = [p for p in parameters if np.nanmin(table.values(p)) == np.nanmax(table.values(p))]
    if constant:
        notes.append(f"parameters left out, the same in every row: {', '.join(constant)}")
        parameters = [p for p in parameters if p not in constant]
    names = objectives or [c for c in table.objective_columns() if c in table.numeric_columns()]
    if not names:
        raise AnalysisError(f"{table.path}: the spec names no numeric objective; choose with --objective OBJ")
    for name in names:
        table.check_column(name)
    x_all = np.column_stack([table.values(p) for p in parameters])
    ok = table.ok_mask() & np.all(np.isfinite(x_all), axis=1)
    rng = np.random.default_rng(seed)
    fitted: dict[str, ObjectiveSurrogate] = {}
    for name in names:
        y_all = table.values(name)
        rows = np.flatnonzero(ok & np.isfinite(y_all))
        if len(rows) > max_rows:
            rows = np.sort(rng.choice(rows, max_rows, replace=False))
            notes.append(f"{name}: fitted on {max_rows} random ok rows of {int((ok & np.isfinite(y_all)).sum())} "
                         "(--max-rows)")
        if len(rows) < folds + 1:
            raise AnalysisError(f"{table.path}: objective '{name}' has {len(rows)} ok rows with a value; a "
                                f"surrogate needs at least {folds + 1}")
        result = fit_objective(x_all[rows], y_all[rows], method, folds, seed)
        fitted[name] = ObjectiveSurrogate(name, result, sobol_ranking(result.model, parameters, seed=seed),
                                          len(rows))
    finite = np.all(np.isfinite(x_all), axis=1)
    failures = fit_failures(x_all[finite], ~table.ok_mask()[finite], folds, seed)
    return SurrogateSet(parameters, fitted, failures, str(table.path), notes)


def write(surrogates: SurrogateSet, folder: str | Path) -> Path:
    """``folder/models.json`` and ``folder/summary.csv``; returns the folder."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "models.json").write_text(json.dumps(surrogates.to_json(), indent=1), encoding="utf-8")
    surrogates.summary().to_csv(folder / "summary.csv", index=False)
    return folder


def read(folder: str | Path) -> SurrogateSet:
    """The surrogates :func:`write` stored in ``folder`` (or its ``models.json``); AnalysisError when there are
    none or the file is not ours."""
    path = Path(folder)
    path = path / "models.json" if path.is_dir() else path
    if not path.is_file():
        raise AnalysisError(f"{path}: no surrogates here; fit them first with `cosim surrogate DIR`")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise AnalysisError(f"{path}: cannot read the surrogates: {exc}") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise AnalysisError(f"{path}: not a file of cosim surrogates (no \"format\": \"{FORMAT}\"); fit them again "
                            "with `cosim surrogate DIR`")
    objectives = {}
    for name, entry in data["objectives"].items():
        fitted = Fitted(model_from_json(entry["model"]), float(entry["q2"]), float(entry["rmse"]),
                        str(entry["candidate"]), dict(entry["tried"]), list(entry.get("simulated", [])),
                        list(entry.get("cross_validated", [])))
        objectives[name] = ObjectiveSurrogate(name, fitted, [Influence(**i) for i in entry["ranking"]],
                                              int(entry["rows"]))
    failures = FailureModel.from_json(data["failures"]) if data.get("failures") else None
    return SurrogateSet(list(data["parameters"]), objectives, failures, str(data.get("source", "")),
                        list(data.get("notes", [])))


def surrogate_folder(table_path: str | Path) -> Path:
    """``DIR/surrogate`` for a results folder DIR, else ``surrogate/`` beside the table file."""
    path = Path(table_path)
    return (path if path.is_dir() else path.parent) / "surrogate"
