"""Re-run one design point of a results table with full traces.

The values of a point come from its row: the spec's design parameters name
the columns (``target``, or ``target[1]``..``target[n]`` for an array).  The
spec is the one given, else ``spec_path`` from the sweep's metadata, else the
spec stored in the metadata itself (its relative paths then resolve against
the table's folder).  *Full recording* records every output of every unit
besides the spec's ``record`` list (:meth:`~cosim.system.builder.System.recording_all_outputs`).
"""

from __future__ import annotations

import json
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pandas as pd

from cosim.analysis.table import AnalysisError, ResultsTable


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
    from cosim.errors import did_you_mean

    starts = [i for i in ids if i.startswith(name)]
    return f" Did you mean '{starts[0]}'?" if len(starts) == 1 else did_you_mean(name, list(ids)[:5000])


def load_rerun_spec(table: ResultsTable | None, spec_path: str | Path | None):
    """The spec to re-run with (see the module docstring), as it is: without full recording.

    Raises AnalysisError when there is no spec to use, SpecError when it is broken.
    """
    from cosim.spec.loader import load_spec, spec_from_dict

    meta = (table.metadata or {}) if table is not None else {}
    if spec_path is None and meta.get("spec_path") and Path(meta["spec_path"]).exists():
        spec_path = meta["spec_path"]
    if spec_path is not None:
        return load_spec(spec_path)
    if table is not None and table.spec:
        return spec_from_dict(table.spec, table.path.parent / "spec.json")
    raise AnalysisError("re-running a design needs its spec: give --spec spec.json "
                        "(the table has no sweep metadata naming one)")


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

    ``full_record`` records every output of every unit besides the spec's
    record list.  Raises AnalysisError or SpecError when the spec or the
    values do not fit; a failing run is reported in the result's status instead.
    """
    from cosim.execution.point import run_point
    from cosim.system.builder import build_system

    if values is None and (table is None or row is None):
        raise TypeError("rerun needs a table and a row, or the values")
    spec = load_rerun_spec(table, spec_path)
    if values is None and table is not None and row is not None:
        values = point_values(table, row, [p.target for p in spec.design.parameters])
    system = build_system(spec)
    if full_record:
        system = system.recording_all_outputs()
    return run_point(system, values, record=True), values


@dataclass
class Rerun:
    """One design run again: its row in the table, ``point_id`` (the row number when the table has none), the
    values it ran with and the RunResult (``traces``: a DataFrame with ``time`` and the recorded columns)."""

    row: int
    point_id: str
    values: dict[str, Any]
    result: Any
    units: dict[str, str] = field(default_factory=dict)  # port ('robot.tau') -> its unit ('N.m'), where declared


def port_units(system: Any) -> dict[str, str]:
    """Each port of ``system`` that declares a unit, as the spec names it ('unit.port', after the spec's port
    mapping) -> that unit; an array's elements ('unit.port[i]') give their unit to the port too."""
    units: dict[str, str] = {}
    for name, system_unit in system.units.items():
        reverse = {actual: port for port, actual in system_unit.spec.ports.items()}
        for variable in system_unit.description.variables:
            if variable.unit:
                port = reverse.get(variable.name, variable.name)
                base = _ELEMENT.sub(r"\1", port)  # 'tau[3]' (an FMI 2.0 array's element) -> 'tau'
                units.setdefault(f"{name}.{base}", variable.unit)
    return units


def rerun_rows(table: ResultsTable, rows: Sequence[int], spec_path: str | Path | None = None) -> list[Rerun]:
    """Run the designs of ``rows`` again, one after the other, recording the spec's own ``record`` signals
    (every output of every unit when the spec records nothing), whatever the system.

    The spec is loaded and its system built once for all rows.  Raises AnalysisError or SpecError when the
    spec or a row's values do not fit; a failing run is reported in its result's status instead.
    """
    from cosim.execution.point import run_point
    from cosim.system.builder import build_system

    spec = load_rerun_spec(table, spec_path)
    system = build_system(spec)
    if not system.recorded:
        system = system.recording_all_outputs()
    targets = [p.target for p in spec.design.parameters]
    ids = table.df["point_id"].astype(str).to_numpy() if "point_id" in table.df.columns else None
    units = port_units(system)
    out = []
    for row in rows:
        values = point_values(table, int(row), targets)
        result = run_point(system, values, record=True)
        out.append(Rerun(int(row), str(ids[row]) if ids is not None else str(row), values, result, units))
    return out


_ELEMENT = re.compile(r"^(.*)\[(\d+)\]$")


def port_groups(columns: Sequence[str], limit: int = 12) -> list[tuple[str, list[str]]]:
    """Trace columns grouped by port, in their recorded order: ``[("arm.q", ["arm.q[1]", ...]), ...]``
    (``time`` left out; at most ``limit`` groups)."""
    groups: dict[str, list[str]] = {}
    for c in columns:
        if str(c) == "time":
            continue
        m = _ELEMENT.match(str(c))
        groups.setdefault(m.group(1) if m else str(c), []).append(str(c))
    return list(groups.items())[:limit]


def find_table_for(spec_path: str | Path, given: str | Path | None, digest: str | None = None,
                   point_id: str | None = None) -> Path:
    """The results table of ``cosim run SPEC --point ID``: ``given``, else the sweep of this spec.

    First where ``cosim sweep`` writes by default, ``results/<spec name>/``
    under the current directory, then under the spec's folder; else the one
    sweep folder ``results/*/`` (in the same two places) whose metadata names
    this spec file or its ``digest`` (e.g. one written with ``--out
    results/my_run``) and, when several do, the one holding ``point_id``.
    Raises AnalysisError when there is none, or when several hold the point
    (listing them: a guess could re-run another sweep's row).
    """
    if given is not None:
        return Path(given)
    from cosim.results.folder import default_folder

    default = default_folder(spec_path)
    candidates = [default / "results.parquet", Path(spec_path).resolve().parent / default / "results.parquet"]
    for c in candidates:
        if c.exists():
            return c
    sweeps = _sweeps_of(Path(spec_path), digest)
    if len(sweeps) > 1 and point_id is not None:
        holding = [t for t in sweeps if point_id in set(pd.read_parquet(t, columns=["point_id"])["point_id"])]
        if len(holding) > 1:
            raise AnalysisError(f"--point {point_id}: {len(holding)} sweeps of this spec hold the point: "
                                + ", ".join(str(t.parent) for t in holding) + "; choose one with --results DIR")
        sweeps = holding or sweeps
    if len(sweeps) == 1 or (sweeps and point_id is None):
        return sweeps[0]
    if sweeps:
        raise AnalysisError(f"--point {point_id}: none of the {len(sweeps)} sweeps of this spec holds the point ("
                            + ", ".join(str(t.parent) for t in sweeps) + "); check the id, or give --results DIR")
    raise AnalysisError("--point: no results table found at " + " or ".join(map(str, candidates))
                        + " nor a sweep of this spec in results/*/; give it with --results DIR")


def _sweeps_of(spec_path: Path, digest: str | None) -> list[Path]:
    """Tables of the sweep folders results/*/ (here and beside the spec) made from this spec, newest first."""
    target = spec_path.resolve()
    found = set()
    for root in (Path("results"), target.parent / "results"):
        for meta_path in root.glob("*/metadata.json"):
            try:
                meta = json.loads(meta_path.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                continue
            same_file = bool(meta.get("spec_path")) and Path(meta["spec_path"]) == target
            if (same_file or (digest and meta.get("spec_digest") == digest)) \
                    and (meta_path.parent / "results.parquet").exists():
                found.add((meta_path.parent / "results.parquet").resolve())
    return sorted(found, key=lambda p: p.stat().st_mtime, reverse=True)


def prepare_point_run(system: Any, point_id: str, results: str | Path | None, out: Path | None):
    """For ``cosim run SPEC --point ID``: (``system`` recording every output, the point's values, traces path).

    ``system`` is the checked system of SPEC (loaded and built once by the
    caller).  The traces go to ``out`` or, by default,
    ``<results folder>/points/<ID>.parquet``.  A spec changed since the sweep
    is run anyway, with a warning on stderr.  Raises AnalysisError when the
    table or the point cannot be found.
    """
    from cosim.analysis.table import load_results

    spec_path = system.spec.path
    table = load_results(find_table_for(spec_path, results, system.spec.digest, point_id))
    row = find_row(table, point_id)
    digest = (table.metadata or {}).get("spec_digest")
    if digest and digest != system.spec.digest:
        print(f"cosim: warning: {spec_path} changed since the sweep that wrote {table.path}; running the point's "
              "values with the spec as it is now", file=sys.stderr)
    values = point_values(table, row, [p.target for p in system.spec.design.parameters])
    print(f"point {point_id}: " + ", ".join(f"{t}={v}" for t, v in values.items()))
    traces = out if out is not None else table.path.parent / "points" / f"{point_id}.parquet"
    return system.recording_all_outputs(), values, traces
