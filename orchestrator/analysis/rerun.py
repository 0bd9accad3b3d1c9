"""Re-run one design point of a results table with full traces.

The values of a point come from its row: the spec's design parameters name
the columns (``target``, or ``target[1]``..``target[n]`` for an array).  The
spec is the one given, else ``spec_path`` from the sweep's metadata, else the
spec stored in the metadata itself (its relative paths then resolve against
the table's folder).  *Full recording* adds every output of every unit
(``unit.*``) to the spec's ``record`` list.
"""

from __future__ import annotations

import copy
import sys
from pathlib import Path
from typing import Any

import numpy as np

from .table import AnalysisError, ResultsTable


def find_row(table: ResultsTable, point_id: str) -> int:
    """Position of the row with ``point_id``; raises AnalysisError when absent."""
    if "point_id" not in table.df.columns:
        raise AnalysisError(f"{table.path} has no point_id column")
    ids = table.df["point_id"].astype(str)
    hits = np.flatnonzero((ids == str(point_id)).to_numpy())
    if not len(hits):
        raise AnalysisError(f"no point '{point_id}' in {table.path}.{_did_you_mean(point_id, ids)}")
    return int(hits[-1])


def _did_you_mean(name: str, ids) -> str:
    from ..problems import did_you_mean

    starts = [i for i in ids if i.startswith(name)]
    return f" Did you mean '{starts[0]}'?" if len(starts) == 1 else did_you_mean(name, list(ids)[:5000])


def load_rerun_spec(table: ResultsTable | None, spec_path: str | Path | None, full_record: bool = True):
    """The spec to re-run with (see the module docstring), recording every unit output when ``full_record``.

    Raises AnalysisError when there is no spec to use, SpecError when it is broken.
    """
    from ..spec import load_spec, spec_from_dict

    meta = (table.metadata or {}) if table is not None else {}
    if spec_path is None and meta.get("spec_path") and Path(meta["spec_path"]).exists():
        spec_path = meta["spec_path"]
    if spec_path is not None:
        raw, where = copy.deepcopy(dict(load_spec(spec_path).raw)), Path(spec_path)
    elif table is not None and table.spec:
        raw, where = copy.deepcopy(table.spec), table.path.parent / "spec.json"
    else:
        raise AnalysisError("re-running a design needs its spec: give --spec spec.json "
                            "(the table has no sweep metadata naming one)")
    if full_record:
        record = list(raw.get("record") or [])
        record += [f"{name}.*" for name in raw.get("units", {}) if f"{name}.*" not in record]
        raw["record"] = record
    return spec_from_dict(raw, where)


def point_values(table: ResultsTable, row: int, targets: list[str]) -> dict[str, Any]:
    """``{target: value}`` of the design parameters ``targets`` in row ``row`` (arrays from ``target[i]``).

    Raises AnalysisError when a parameter has no column or no value in that row.
    """
    out: dict[str, Any] = {}
    df = table.df
    for target in targets:
        if target in df.columns:
            out[target] = _python(df[target].iloc[row])
        else:
            elements = sorted((int(c[len(target) + 1:-1]), c) for c in map(str, df.columns)
                              if c.startswith(target + "[") and c.endswith("]") and c[len(target) + 1:-1].isdigit())
            if not elements:
                raise AnalysisError(f"the table has no column for design parameter '{target}'")
            out[target] = [_python(df[c].iloc[row]) for _, c in elements]
        values = out[target] if isinstance(out[target], list) else [out[target]]
        if any(v is None or (isinstance(v, float) and np.isnan(v)) for v in values):
            raise AnalysisError(f"row {row} has no value for '{target}'")
    return out


def _python(value: Any) -> Any:
    return value.item() if isinstance(value, np.generic) else value


def rerun(table: ResultsTable | None, row: int | None = None, spec_path: str | Path | None = None,
          values: dict[str, Any] | None = None, full_record: bool = True):
    """Run row ``row`` of ``table`` (or explicit ``values``) again; returns (RunResult, values).

    Raises AnalysisError or SpecError when the spec or the values do not fit;
    a failing run is reported in the result's status instead.
    """
    from ..execution import Execution
    from ..system import build_system

    spec = load_rerun_spec(table, spec_path, full_record)
    if values is None:
        targets = [p.target for p in spec.design.parameters]
        values = point_values(table, row, targets)  # type: ignore[arg-type]
    system = build_system(spec)
    overrides = [system.assignment_for(target, value) for target, value in values.items()]
    return Execution(system, overrides, record=True).run(), values


def find_table_for(spec_path: str | Path, given: str | Path | None) -> Path:
    """The results table of ``cosim run SPEC --point ID``: ``given``, else where ``cosim sweep`` writes by default.

    The default folder is ``results/<spec name>/`` under the current directory,
    then under the spec's folder.  Raises AnalysisError when none exists.
    """
    if given is not None:
        return Path(given)
    try:
        from ..sweep_cli import _default_out

        default = _default_out(str(spec_path))
    except ImportError:  # pragma: no cover - sweep not installed
        default = Path("results") / Path(spec_path).stem
    candidates = [default / "results.parquet", Path(spec_path).resolve().parent / default / "results.parquet"]
    for c in candidates:
        if c.exists():
            return c
    raise AnalysisError("--point: no results table found at " + " or ".join(map(str, candidates))
                        + "; give it with --results DIR/results.parquet")


def prepare_point_run(spec_path: str, point_id: str, results: str | None, out: Path | None):
    """For ``cosim run SPEC --point ID``: (system with full recording, overrides, traces path).

    The traces go to ``out`` or, by default, ``<results folder>/points/<ID>.parquet``.
    A spec changed since the sweep is run anyway, with a warning on stderr.
    """
    from ..system import build_system
    from .table import load_results

    table = load_results(find_table_for(spec_path, results))
    row = find_row(table, point_id)
    spec = load_rerun_spec(None, spec_path, full_record=True)
    digest = (table.metadata or {}).get("spec_digest")
    from ..spec import load_spec

    if digest and digest != load_spec(spec_path).digest:
        print(f"cosim: warning: {spec_path} changed since the sweep that wrote {table.path}; running the point's "
              "values with the spec as it is now", file=sys.stderr)
    values = point_values(table, row, [p.target for p in spec.design.parameters])
    system = build_system(spec)
    overrides = [system.assignment_for(t, v) for t, v in values.items()]
    print(f"point {point_id}: " + ", ".join(f"{t}={v}" for t, v in values.items()))
    return system, overrides, out if out is not None else table.path.parent / "points" / f"{point_id}.parquet"
