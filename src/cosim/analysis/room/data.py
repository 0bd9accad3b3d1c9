"""What the decision room's views draw, as plain columns: no bokeh here, so it is tested without a browser.

A :class:`Study` is a results table read once (one per server, shared read-only by every browser tab) with
what its folder says about it: the kind of study (``sweep``, ``optimization`` or ``sensitivity``, from
``metadata.json``), the default axes, the hypervolume history of an optimisation and the indices of a
sensitivity analysis.  The functions below turn a :class:`cosim.analysis.decision.Decision` (one per tab)
into the columns of the views.
"""

from __future__ import annotations

import base64
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
import pandas as pd

from cosim.analysis.decision import Decision
from cosim.analysis.table import ResultsTable

STATUS_COLOURS = {"failed": "#d62728", "timeout": "#ff7f0e", "crashed": "#9467bd",
                  "pruned": "#8c8c8c"}  # 'ok' rows use the colour map; pruned: proven off the front (bounds)
OTHER_STATUS = "#8c564b"  # a status cosim does not write (a foreign table)
SIZE_PX = (4.0, 16.0)  # marker sizes when sized by a column; 6 px otherwise
PLAIN_SIZE = 6.0
HISTOGRAM_BINS = 40


@dataclass
class Study:
    """A results table and what its folder says about it (module docstring)."""

    table: ResultsTable
    spec_path: str | None = None  # a spec.json given on the command line (re-runs, units), else the metadata's
    kind: str = field(init=False)
    ids: np.ndarray = field(init=False, repr=False)
    status: np.ndarray = field(init=False, repr=False)
    messages: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        df = self.table.df
        meta = self.table.metadata or {}
        self.kind = str(meta.get("kind") or "sweep")
        self.ids = df["point_id"].astype(str).to_numpy() if "point_id" in df.columns \
            else np.array([str(i) for i in range(len(df))])
        self.status = df["status"].astype(str).to_numpy() if "status" in df.columns \
            else np.full(len(df), "ok", dtype=object)
        self.messages = df["message"].fillna("").astype(str).to_numpy() if "message" in df.columns \
            else np.full(len(df), "", dtype=object)

    @property
    def name(self) -> str:
        spec = self.table.spec or {}
        return str(spec.get("name") or self.table.path.parent.name)

    def default_axes(self, decision: Decision) -> tuple[str, str, str | None]:
        """(x, y, colour): the first two objectives of the decision when it has two, else the first design
        parameters; the colour the first objective not on an axis (None when there is none)."""
        columns = decision.filters.columns
        objectives = [c for c, _ in decision.objectives]
        params = [c for c in self.table.parameter_columns() if c in columns]
        spec_objectives = [c for c in self.table.objective_columns() if c in columns]
        axes = objectives if len(objectives) >= 2 else params + spec_objectives + columns
        x = axes[0]
        y = next(c for c in axes + columns if c != x)
        colour = next((c for c in objectives + spec_objectives if c not in (x, y)), None)
        return x, y, colour

    # -- what the folder holds beside the table ---------------------------------------------------------------
    def hypervolume(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(evaluations 1..n, hypervolume after each) of an optimisation folder (cosim.analysis.hypervolume),
        else None."""
        if self.kind != "optimization":
            return None
        from cosim.analysis.hypervolume import hypervolume_history

        senses = self.table.objective_senses()
        if not senses:
            return None
        names = list(senses)
        order = np.argsort(self.table.values("trial"), kind="stable") if "trial" in self.table.df.columns \
            else np.arange(len(self.table.df))
        values = np.column_stack([self.table.values(n) for n in names])[order]
        usable = (self.table.ok_mask() & self.table.feasible_mask())[order] & np.all(np.isfinite(values), axis=1)
        batches = self.table.values("batch")[order] if "batch" in self.table.df.columns else None
        history = hypervolume_history(values, [senses[n] for n in names], usable, batches)
        return np.arange(1, len(history) + 1), history

    def sensitivity(self) -> pd.DataFrame | None:
        """The indices of a sensitivity folder (``objective, parameter, index, value, conf``; conf is the 95 %
        confidence half-width), else None; None too when the file named in the metadata is missing."""
        meta = self.table.metadata or {}
        if self.kind != "sensitivity":
            return None
        path = self.table.path.parent / str((meta.get("sensitivity") or {}).get("table", "sensitivity.csv"))
        if not path.exists():
            return None
        return pd.read_csv(path)


# -- the point cloud ----------------------------------------------------------------------------------------


def scaled_sizes(values: np.ndarray) -> np.ndarray:
    """Marker sizes in SIZE_PX over the finite range of ``values`` (the smallest size where missing)."""
    lo_px, hi_px = SIZE_PX
    finite = np.isfinite(values)
    out = np.full(len(values), lo_px)
    if finite.any():
        lo, hi = values[finite].min(), values[finite].max()
        out[finite] = lo_px + (hi_px - lo_px) * ((values[finite] - lo) / (hi - lo) if hi > lo else 0.5)
    return out


def status_palette(status: np.ndarray) -> tuple[list[str], list[str]]:
    """(the statuses other than 'ok' in the table, their colours) for a categorical colour map."""
    factors = sorted({str(s) for s in pd.unique(status)} - {"ok"})  # pd.unique hashes: 10^6 rows in ms
    return factors, [STATUS_COLOURS.get(s, OTHER_STATUS) for s in factors]


def status_codes(status: np.ndarray, factors: Sequence[str]) -> np.ndarray:
    """Each row's index into ``factors`` (-1 for 'ok' and anything not listed)."""
    codes = pd.Categorical(status, categories=list(factors)).codes
    return np.asarray(codes, dtype=np.int64)


def points(study: Study, decision: Decision, x: str, y: str, colour: str | None, size: str | None
           ) -> dict[str, Any]:
    """The columns of the point cloud, one entry per table row: x, y, c (the colour column, NaN without one)
    and s (marker size).  Strings are what makes the page slow to load: the designs' ids go in one text
    (:func:`ids_text`), the statuses with the designs not ok only (:func:`not_ok_points`), the messages in the
    table of designs not ok."""
    f = decision.filters
    n = len(study.ids)
    return {"x": f.values(x), "y": f.values(y),
            "c": f.values(colour) if colour else np.full(n, np.nan),
            "s": scaled_sizes(f.values(size)) if size else np.full(n, PLAIN_SIZE)}


def not_ok_rows(study: Study) -> np.ndarray:
    """The rows of the designs not ok (failed, timed out, crashed), in table order."""
    return np.flatnonzero(study.status != "ok")


def not_ok_points(study: Study, points: dict[str, Any], rows: np.ndarray) -> dict[str, Any]:
    """The cloud's crosses: x, y and s of ``points`` (the cloud's columns) at ``rows`` (:func:`not_ok_rows`),
    with each design's status and id."""
    return {"x": points["x"][rows], "y": points["y"][rows], "s": points["s"][rows],
            "status": list(study.status[rows]), "point_id": list(study.ids[rows])}


def ids_text(study: Study) -> str:
    """The designs' ids in table order, one per line: the cloud's hover finds a point's id by its row.  One
    string costs the server and the page one item, where a column of 17061 ids cost ~0.1 s in each (the
    first document's size: 0.34 MB of its 0.44 MB)."""
    return "\n".join(str(i).replace("\n", " ") for i in study.ids)


def masks(study: Study, decision: Decision) -> dict[str, np.ndarray]:
    """Which rows each layer of the cloud draws: ``greyed`` (filtered out), ``ok`` (active ok rows, coloured by
    the colour map), ``not_ok`` (active rows of another status, in its colour), ``front`` (the Pareto front)."""
    active = decision.active()
    ok = study.status == "ok"
    return {"greyed": ~active, "ok": active & ok, "not_ok": active & ~ok, "front": decision.pareto()}


def failures(study: Study, limit: int) -> dict[str, list]:
    """The first ``limit`` designs not ok: point_id, status, message (a 10^6-row table may have 10^4 of them:
    strings are what makes a page slow)."""
    rows = np.flatnonzero(study.status != "ok")[:limit]
    return {"point_id": list(study.ids[rows]), "status": list(study.status[rows]),
            "message": list(study.messages[rows])}


def histogram(values: np.ndarray, active: np.ndarray, bins: int = HISTOGRAM_BINS) -> dict[str, np.ndarray]:
    """Counts of every row and of the active rows over the same bins of the finite values: left, right, all,
    active."""
    finite = np.isfinite(values)
    if not finite.any():
        return {"left": np.zeros(0), "right": np.zeros(0), "all": np.zeros(0), "active": np.zeros(0)}
    lo, hi = values[finite].min(), values[finite].max()
    edges = np.linspace(lo, hi, bins + 1) if hi > lo else np.array([lo - 0.5, lo + 0.5])
    every, _ = np.histogram(values[finite], edges)
    shown, _ = np.histogram(values[finite & active], edges)
    return {"left": edges[:-1], "right": edges[1:], "all": every, "active": shown}


# -- decision support ----------------------------------------------------------------------------------------


def ranking_rows(study: Study, decision: Decision, top: int) -> dict[str, list]:
    """The ``top`` best candidates: rank, row, point_id, score, each design parameter's value (``p0``, ``p1``,
    ...: :func:`ranking_parameters`) and each objective's (``o0``, ...): a design is shown by what it is and
    what it does, not by its id alone."""
    score = decision.scores()
    order = decision.ranking(top, score)
    data: dict[str, list] = {"rank": list(range(1, len(order) + 1)), "row": [int(r) for r in order],
                             "point_id": [str(study.ids[r]) for r in order],
                             "score": [float(score[r]) for r in order]}
    for k, name in enumerate(ranking_parameters(study, decision)):
        values = decision.filters.values(name)
        data[f"p{k}"] = [float(values[r]) for r in order]
    for k, (name, _) in enumerate(decision.objectives):
        values = decision.filters.values(name)
        data[f"o{k}"] = [float(values[r]) for r in order]
    return data


def ranking_parameters(study: Study, decision: Decision) -> list[str]:
    """The design parameters the ranking shows: the spec's numeric ones, in spec order."""
    numeric = set(decision.filters.columns)
    return [c for c in study.table.parameter_columns() if c in numeric]


def ranking_columns(study: Study, decision: Decision) -> list[tuple[str, str]]:
    """(field, title) of the ranking's value columns, plain text (the view escapes them): each parameter
    and each objective with its unit from the results metadata, the objectives with their sense
    (``e_total [J] (min)``)."""
    label = study.table.label
    return [(f"p{k}", label(name)) for k, name in enumerate(ranking_parameters(study, decision))] + \
        [(f"o{k}", f"{label(name)} ({sense})") for k, (name, sense) in enumerate(decision.objectives)]


def radar(decision: Decision, rows: Sequence[int]) -> dict[str, Any]:
    """Closed polygons of the selected designs' utilities (1 best, on the unit circle) on one spoke per
    objective, first spoke up, clockwise: xs, ys (lists per design) and the spokes' end points and labels.

    A design that is not a candidate (filtered out, failed) has no polygon.
    """
    k = len(decision.objectives)
    angles = np.pi / 2 - 2 * np.pi * np.arange(k) / max(k, 1)
    profile = decision.profile(rows)
    xs, ys, kept = [], [], []
    for row, u in zip(rows, profile):
        if k >= 2 and np.all(np.isfinite(u)):
            r = 0.1 + 0.9 * u  # 0 (worst) is a small circle, not the centre: polygons stay readable
            xs.append(list(np.append(r * np.cos(angles), r[0] * np.cos(angles[0]))))
            ys.append(list(np.append(r * np.sin(angles), r[0] * np.sin(angles[0]))))
            kept.append(int(row))
    return {"xs": xs, "ys": ys, "rows": kept, "spoke_x": list(np.cos(angles)), "spoke_y": list(np.sin(angles)),
            "labels": [f"{name} ({sense})" for name, sense in decision.objectives]}


# -- export ----------------------------------------------------------------------------------------------------


def data_url(text: str, media_type: str) -> str:
    """``text`` as a data: URL (base64), what a download link of the page points to."""
    return f"data:{media_type};base64," + base64.b64encode(text.encode("utf-8")).decode("ascii")


def trace_columns(traces: pd.DataFrame) -> list[str]:
    """The numeric trace columns (time left out): String and Binary signals are recorded but not plotted."""
    return [str(c) for c in traces.columns if str(c) != "time" and
            (pd.api.types.is_numeric_dtype(traces[c]) or pd.api.types.is_bool_dtype(traces[c]))]
