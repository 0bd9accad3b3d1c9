"""A results table with what is known about its columns: units, senses, roles.

:func:`load_results` reads any table (``.parquet``, ``.csv``, or a sweep
folder holding ``results.parquet``) and, when a ``metadata.json`` lies beside
it, the spec of the sweep that produced it.  Nothing here needs the metadata:
without it every numeric column is just a column without a unit.

Filtering with ``--where``
    A ``where`` text is an :class:`cosim.spec.expressions.Expression`
    (numbers, ``+ - * / ** %``, comparisons, ``and or not``, ``abs sqrt min
    max ...``) evaluated over whole columns at once.  Columns are named as the
    table names them (``traj.waypoints[9] > -50``, ``e_el[1] < 3``), or by the
    identifier rule constraints also accept (see :mod:`cosim.spec.design`):
    every run of characters other than letters, digits and ``_`` becomes one
    ``_`` and trailing ones are dropped, so ``traj.waypoints[9]`` is also
    ``traj_waypoints_9``.  A comparison with a missing value (NaN) is false, so
    rows without a value drop out.
"""

from __future__ import annotations

import ast
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import pandas as pd

from cosim.errors import AnalysisError, ExpressionError, did_you_mean
from cosim.results.columns import TAIL_COLUMNS
from cosim.spec.expressions import COMPARISONS, Expression, identifier

TAIL = TAIL_COLUMNS  # the old name


def base_name(column: str) -> str:
    """``'e_el[3]'`` -> ``'e_el'``: the spec's name of an array element column."""
    return column.split("[", 1)[0]


@dataclass
class ResultsTable:
    """A results table and optional sweep metadata.

    ``df`` holds the rows; ``metadata`` the parsed ``metadata.json`` (or None);
    ``spec`` the raw spec dict of the sweep (or None).
    """

    df: pd.DataFrame
    path: Path
    metadata: dict[str, Any] | None = None
    spec: dict[str, Any] | None = None
    # what the reader should know about where the rows came from (an unfinished study's parts), or ""
    note: str = ""
    _units: dict[str, str] = field(default_factory=dict, repr=False)
    # senses chosen by the reader (`cosim report --min A --min B`); they replace the spec's
    _chosen_senses: dict[str, str] | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.spec:
            for name, o in (self.spec.get("objectives") or {}).items():
                if isinstance(o, Mapping) and o.get("unit"):
                    self._units[name] = str(o["unit"])
            for target, p in ((self.spec.get("design") or {}).get("parameters") or {}).items():
                if isinstance(p, Mapping) and p.get("unit"):
                    self._units[target] = str(p["unit"])
        self._units.setdefault("run_time", "s")

    # -- columns --------------------------------------------------------------
    @property
    def columns(self) -> list[str]:
        return [str(c) for c in self.df.columns]

    def numeric_columns(self) -> list[str]:
        """Columns with numbers or booleans (booleans count as 0/1), in table order."""
        return [str(c) for c in self.df.columns
                if pd.api.types.is_numeric_dtype(self.df[c]) or pd.api.types.is_bool_dtype(self.df[c])]

    def check_column(self, name: str, numeric: bool = True) -> str:
        """``name`` when the table has it; raises AnalysisError with a suggestion otherwise."""
        known = self.numeric_columns() if numeric else self.columns
        if name in known:
            return name
        if name in self.columns:
            raise AnalysisError(f"column '{name}' is not numeric; numeric columns: {', '.join(known)}")
        raise AnalysisError(f"no column '{name}' in {self.path}.{did_you_mean(name, known)} "
                            f"Columns: {', '.join(known)}")

    def values(self, name: str) -> np.ndarray:
        """A numeric column as float array (booleans as 0/1, missing as NaN)."""
        column = self.df[name] if name in self.df.columns else None
        if column is None or not (pd.api.types.is_numeric_dtype(column) or pd.api.types.is_bool_dtype(column)):
            self.check_column(name)  # raises, naming the numeric columns
        return pd.to_numeric(column, errors="coerce").to_numpy(dtype=float, na_value=np.nan)

    def unit(self, column: str) -> str:
        """The unit of a column from the spec ('' when unknown)."""
        return self._units.get(column) or self._units.get(base_name(column), "")

    def label(self, column: str) -> str:
        """An axis label: ``'e_el[1] [J]'``, or the bare name without a unit."""
        unit = self.unit(column)
        return f"{column} [{unit}]" if unit else column

    def choose_objectives(self, objectives: list[tuple[str, str]]) -> None:
        """Use these (column, 'min'|'max') pairs as the table's objectives from now on, whatever the spec says;
        raises AnalysisError for a column the table does not have."""
        self._chosen_senses = {self.check_column(name): sense for name, sense in objectives}

    def objective_senses(self) -> dict[str, str]:
        """Flat objective columns with a ``sense`` -> 'min' or 'max': those chosen with choose_objectives, else
        those an optimisation ran on (its metadata, or the spec's ``optimize`` section) when given, else the
        spec's, in spec order."""
        if self._chosen_senses:
            return dict(self._chosen_senses)
        optimized = ((self.metadata or {}).get("optimize") or {}).get("objectives") \
            or ((self.spec or {}).get("optimize") or {}).get("objectives")
        if isinstance(optimized, Mapping) and optimized:
            return {c: ("max" if str(s).startswith("max") else "min")
                    for name, s in optimized.items() for c in self._columns_of(name)}
        senses: dict[str, str] = {}
        for name, o in ((self.spec or {}).get("objectives") or {}).items():
            sense = o.get("sense") if isinstance(o, Mapping) else None
            if sense not in ("minimize", "maximize", "min", "max"):
                continue
            for column in self._columns_of(name):
                senses[column] = "max" if sense.startswith("max") else "min"
        return senses

    def sensed_objectives(self) -> dict[str, str]:
        """Every flat objective column with a sense -> 'min' or 'max': those chosen with choose_objectives, else
        an optimisation's objectives first, then every other objective of the spec that has a sense (the
        decision room ranks on all of them: an optimisation of one objective whose spec states three ranks
        on three).  :meth:`objective_senses` stays the optimisation's own, for its front and report."""
        senses = self.objective_senses()
        if self._chosen_senses:
            return senses
        for name, o in ((self.spec or {}).get("objectives") or {}).items():
            sense = o.get("sense") if isinstance(o, Mapping) else None
            if sense in ("minimize", "maximize", "min", "max"):
                for column in self._columns_of(name):
                    senses.setdefault(column, "max" if sense.startswith("max") else "min")
        return senses

    def objective_columns(self) -> list[str]:
        """Flat columns of every objective the spec names (with or without a sense)."""
        out: list[str] = []
        for name in ((self.spec or {}).get("objectives") or {}):
            out.extend(self._columns_of(name))
        return out

    def parameter_columns(self) -> list[str]:
        """Flat columns of every design parameter the spec names."""
        out: list[str] = []
        for target in (((self.spec or {}).get("design") or {}).get("parameters") or {}):
            out.extend(self._columns_of(target))
        return out

    def _columns_of(self, name: str) -> list[str]:
        if name in self.df.columns:
            return [name]
        prefix = name + "["
        return [str(c) for c in self.df.columns if str(c).startswith(prefix)]

    # -- rows -----------------------------------------------------------------
    def ok_mask(self) -> np.ndarray:
        """True for rows whose status is 'ok' (every row when there is no status column)."""
        if "status" not in self.df.columns:
            return np.ones(len(self.df), dtype=bool)
        return (self.df["status"].astype(str) == "ok").to_numpy()

    def feasible_mask(self) -> np.ndarray:
        """False for rows an optimisation marked infeasible (column ``feasible``); True everywhere else."""
        if "feasible" not in self.df.columns:
            return np.ones(len(self.df), dtype=bool)
        return self.df["feasible"].fillna(False).astype(bool).to_numpy()

    def where(self, text: str | None) -> np.ndarray:
        """Boolean mask of the rows for which ``text`` is true (all rows for None or '').

        Raises AnalysisError for a malformed expression or an unknown name.
        """
        if not text:
            return np.ones(len(self.df), dtype=bool)
        names = {identifier(c): c for c in self.numeric_columns()} | {c: c for c in self.numeric_columns()}
        try:
            expression = ColumnExpression(text)
        except ExpressionError as exc:
            raise AnalysisError(f"--where: {exc}") from None
        unknown = expression.unknown_names(names)
        if unknown:
            hint = did_you_mean(unknown[0], names)
            raise AnalysisError(f"--where '{text}': unknown name '{unknown[0]}'.{hint} Name columns as the table "
                                f"does; known: {', '.join(map(str, self.numeric_columns()))}")
        scope = {n: self.values(names[n]) for n in expression.lookups if n in names}
        try:
            result = expression.evaluate(scope)
        except (ExpressionError, TypeError, ValueError) as exc:
            raise AnalysisError(f"--where '{text}': {exc}") from None
        mask = np.broadcast_to(np.asarray(result), (len(self.df),))
        if mask.dtype != bool:
            mask = np.nan_to_num(mask.astype(float), nan=0.0) != 0
        return np.array(mask, dtype=bool)

    def row(self, index: int) -> dict[str, Any]:
        """All values of one row (by position), for display."""
        return {str(k): v for k, v in self.df.iloc[index].items()}


class ColumnExpression(Expression):
    """An Expression evaluated element-wise over whole columns.

    The base class answers ``and``/``or`` and chained comparisons with one
    Python bool; here they combine arrays element by element.
    """

    def _eval(self, node: ast.AST, values: Mapping[str, Any]) -> Any:
        if isinstance(node, ast.BoolOp):
            parts = [np.asarray(self._eval(v, values)).astype(bool) for v in node.values]
            combine = np.logical_and if isinstance(node.op, ast.And) else np.logical_or
            return combine.reduce(parts)
        if isinstance(node, ast.Compare):
            left = self._eval(node.left, values)
            result: Any = True
            for op, comparator in zip(node.ops, node.comparators):
                right = self._eval(comparator, values)
                result = np.logical_and(result, COMPARISONS[type(op)](left, right))
                left = right
            return result
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
            return np.logical_not(np.asarray(self._eval(node.operand, values)).astype(bool))
        return super()._eval(node, values)


def load_results(path: str | Path, spec: str | Path | None = None) -> ResultsTable:
    """Read a results table: a sweep folder, a ``.parquet`` or a ``.csv`` file.

    A folder whose study was interrupted (or is still running) holds rows in ``parts/``: they are read with the
    compacted table, each point once (:meth:`cosim.results.store.ResultsStore.read`), and ``note`` says so.

    A ``metadata.json`` beside the table is read when present (its ``spec``
    entry gives units and senses).  ``spec`` (a spec.json) replaces the spec
    of the metadata, for tables stored without one; re-runs then use it too.
    Raises AnalysisError when the table is missing or unreadable, SpecError
    when ``spec`` is broken.
    """
    path = Path(path)
    folder = path if path.is_dir() else None
    if folder is not None:
        path = folder / "results.parquet"
    parts = sorted((folder / "parts").glob("part-*.parquet")) if folder is not None else []
    if not path.exists() and not parts:
        raise AnalysisError(f"{path}: no such results table (give a results.parquet, a .csv or a sweep folder)")
    note = ""
    try:
        if folder is not None and parts:  # an interrupted (or running) study: its rows so far, as --resume would find them
            from cosim.results.store import ResultsStore

            df = ResultsStore(folder).read()
            note = (f"{folder}: an unfinished study (interrupted, or still running): {len(df)} rows read from "
                    f"{len(parts)} part file(s){' and results.parquet' if path.exists() else ''}; the same "
                    "command with --resume completes it")
        elif path.suffix.lower() == ".csv":
            df = pd.read_csv(path)
        else:
            df = pd.read_parquet(path)
    except Exception as exc:  # pyarrow and pandas raise many kinds for a bad file
        raise AnalysisError(f"{path if not parts else folder}: cannot read the table: {exc}") from None
    metadata = None
    meta_path = path.parent / "metadata.json"
    if meta_path.exists():
        try:
            metadata = json.loads(meta_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            metadata = None  # a broken metadata file costs units and senses, not the table
    if spec is not None:
        from cosim.spec.loader import load_spec

        loaded = load_spec(spec)
        metadata = {**(metadata or {}), "spec_path": str(Path(spec).resolve()), "spec_digest": loaded.digest,
                    "spec": dict(loaded.raw)}
    return ResultsTable(df=df, path=path, metadata=metadata, spec=spec_of(metadata), note=note)


def spec_of(metadata: Mapping[str, Any] | None) -> dict[str, Any] | None:
    """The raw spec dict inside sweep metadata (``spec``, or ``spec.raw``), or None."""
    if not isinstance(metadata, Mapping):
        return None
    spec = metadata.get("spec")
    if isinstance(spec, Mapping) and isinstance(spec.get("raw"), Mapping):
        spec = spec["raw"]
    return dict(spec) if isinstance(spec, Mapping) else None
