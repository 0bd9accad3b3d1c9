"""``cosim report``: one self-contained HTML page about a results table.

Sections: the table and its sweep; counts by status (with the most common
failure messages); each objective's range and the designs at its extremes;
the Pareto front of the spec's objectives that have a sense; how strongly each
parameter drives each objective (:mod:`.sensitivity`); key figures as PNGs
embedded in base64, so the file can be mailed or archived alone.

Without metadata the page still works: every numeric column except the
bookkeeping ones counts as an objective, and sections that need the spec
(parameters, senses) say why they are empty.
"""

from __future__ import annotations

import base64
import html
import io
import math
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from cosim.analysis.pareto import pareto_mask
from cosim.analysis.plots import draw_front, new_figure, scatter_cloud
from cosim.analysis.sensitivity import influences
from cosim.analysis.table import ResultsTable
from cosim.errors import AnalysisError

MAX_CLOUDS = 6
MAX_FRONT_ROWS = 50

CSS = """
body{font-family:system-ui,sans-serif;margin:2em;max-width:70em;color:#222}
table{border-collapse:collapse;margin:.5em 0 1.5em}td,th{border:1px solid #ccc;padding:.2em .6em;text-align:right}
th{background:#f2f2f2}td.l,th.l{text-align:left}img{max-width:100%;border:1px solid #ddd;margin:.3em}
.note{color:#666}.warn{color:#a40000;font-weight:bold}figure{display:inline-block;margin:0 1em 1em 0;width:46%}figcaption{font-size:90%;color:#444}
"""


class Raw(str):
    """Markup built here, inserted into a cell without escaping."""


def fmt(value: Any) -> str:
    """A table cell: numbers with 6 significant digits, missing as an em dash."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "—"
    if isinstance(value, (float, np.floating)):
        return f"{float(value):.6g}"
    return html.escape(str(value))


def _table(header: Sequence[str], rows: Iterable[Sequence[Any]], left: int = 1, cls: str = "") -> str:
    head = "".join(f"<th class='{'l' if i < left else ''}'>{html.escape(h)}</th>" for i, h in enumerate(header))
    body = "".join("<tr>" + "".join(f"<td class='{'l' if i < left else ''}'>{v if isinstance(v, Raw) else fmt(v)}"
                                    "</td>" for i, v in enumerate(row)) + "</tr>" for row in rows)
    return f"<table class='{cls}'><tr>{head}</tr>{body}</table>"


def png_base64(fig) -> str:
    """The figure as an ``<img>`` with the PNG inlined."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    return "<img alt='figure' src='data:image/png;base64," + base64.b64encode(buf.getvalue()).decode() + "'>"


def roles(table: ResultsTable) -> tuple[list[str], list[str]]:
    """(parameter columns, objective columns): from the spec, or every non-bookkeeping numeric column."""
    if table.spec:
        return table.parameter_columns(), table.objective_columns()
    return [], [c for c in table.numeric_columns() if c not in ("run_time", "worker")]


def _kind_title(table: ResultsTable) -> str:
    """What the page reports on, by the folder's kind (metadata ``kind``): a sweep unless said otherwise."""
    titles: dict[object, str] = {"optimization": "Optimisation report", "sensitivity": "Sensitivity report"}
    return titles.get((table.metadata or {}).get("kind"), "Sweep report")


def _setting_text(value: Any) -> str:
    """A setting as a reader writes it: ``name: value`` pairs, items joined, "none" for nothing (no raw dicts)."""
    if isinstance(value, dict):
        return ", ".join(f"{k}: {_setting_text(v)}" for k, v in value.items()) or "none"
    if isinstance(value, (list, tuple)):
        return "; ".join(_setting_text(v) for v in value) or "none"
    return "none" if value is None else str(value)


def build_report(table: ResultsTable) -> str:
    """The HTML text of the report."""
    parameters, objectives = roles(table)
    ok = table.ok_mask()
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>cosim report: {html.escape(_name(table))}"
             f"</title><style>{CSS}</style></head><body>",
             f"<h1>{_kind_title(table)}: {html.escape(_name(table))}</h1>", _overview(table, parameters, objectives),
             # what the study was run for comes first: its indices or its optimisation, before the long tables
             # of every objective (70 rows for the Panda's)
             _sobol_section(table), _optimization_section(table),
             _status_section(table), _objective_section(table, parameters, objectives, ok),
             _pareto_section(table, parameters, ok & table.feasible_mask()),
             _sensitivity_section(table, parameters, objectives, ok), _surrogate_section(table),
             _figure_section(table, parameters, objectives, ok), "</body></html>"]
    return "\n".join(parts)


def write_report(table: ResultsTable, path: str | Path) -> Path:
    """Write the report to ``path`` (folders created); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(build_report(table), encoding="utf-8")
    return path


def _name(table: ResultsTable) -> str:
    return str((table.spec or {}).get("name") or table.path.parent.name or table.path.stem)


def shown_path(path: str | Path, here: str | Path | None = None) -> str:
    """A file's path as the page shows it: relative to ``here`` (default: the working directory, where the
    user typed it) when the file lies under it, else its folder's and its own name.

    The page is mailed and archived: an absolute path says where the author's home is and nothing a reader
    can open (the spec's digest beside it says which spec it was).
    """
    path = Path(path)
    if not path.is_absolute():
        return str(path)
    try:
        return str(path.relative_to(Path(here or Path.cwd()).resolve()))
    except ValueError:
        return str(Path(*path.parts[-2:])) if len(path.parts) > 2 else path.name


def _overview(table: ResultsTable, parameters: list[str], objectives: list[str]) -> str:
    meta = table.metadata or {}
    rows = [("table", shown_path(table.path)), ("rows", len(table.df)),
            ("parameters", ", ".join(parameters) or "(unknown: no sweep metadata)"),
            ("objectives", ", ".join(objectives))]
    for key in ("spec_path", "spec_digest", "design_method", "started", "ended"):
        if meta.get(key):
            rows.append((key, shown_path(meta[key]) if key == "spec_path" else str(meta[key])))
    return "<h2>Table</h2>" + _table(["of the table", "value"], rows, left=2)


def _status_section(table: ResultsTable) -> str:
    from cosim.results.columns import STATUSES

    if "status" not in table.df.columns:
        return "<h2>Status</h2><p class='note'>The table has no status column; every row counts as ok.</p>"
    counts = table.df["status"].astype(str).value_counts()
    order = list(STATUSES) + [s for s in counts.index if s not in STATUSES]
    total = max(len(table.df), 1)
    text = "<h2>Status</h2>" + _table(["status", "rows", "share"],
                                       [(s, int(counts.get(s, 0)), f"{100 * counts.get(s, 0) / total:.1f} %")
                                        for s in order])
    pruned = int(counts.get("pruned", 0))
    if pruned:  # their own class: proven off the front, not failures (docs/pruning.md)
        text += (f"<p class='pruned'>{pruned} pruned row(s): each was stopped once a finished design strictly "
                 "dominated every value it could still reach, so it cannot be on the front. Their objective "
                 "columns hold those <em>bounds</em>, not results (NaN where unbounded); <code>pruned_by</code> "
                 "names the dominating design. They are left out of every statistic and front below, like rows "
                 "not ok; <code>cosim run --point ID</code> runs one to its end.</p>")
    bad = table.df[~table.df["status"].astype(str).isin(["ok", "pruned"])]
    if len(bad) and "message" in bad.columns:
        common = bad["message"].astype(str).str.slice(0, 160).value_counts().head(5)
        text += "<p>Most common messages of rows not ok:</p>" + _table(
            ["message", "rows"], list(common.items()))
    return text


def _objective_section(table: ResultsTable, parameters: list[str], objectives: list[str], ok: np.ndarray) -> str:
    show = [c for c in ["point_id", *parameters] if c in table.df.columns]
    rows: list[tuple[object, ...]] = []  # a cell: text, a number (fmt writes it) or Raw html
    constant: list[str] = []
    for o in objectives:
        v = np.where(ok, table.values(o), np.nan)
        if not np.isfinite(v).any():
            rows.append((o, table.unit(o), "—", "—", "—", "—", "—"))
            continue
        lo, hi = int(np.nanargmin(v)), int(np.nanargmax(v))
        rows.append((o, table.unit(o), v[lo], _design(table, lo, show), v[hi], _design(table, hi, show),
                     float(np.nanmean(v))))
        if v[lo] == v[hi] and np.isfinite(v).sum() > 1 and "[" not in o:  # elements: joints that never move
            constant.append(f"<code>{html.escape(o)}</code> = {html.escape(fmt(v[lo]))}")
    # a flag that is the same for every design (e.g. every design violates a limit) is a finding, not a detail
    note = (f"<p class='warn'>The same in every ok row ({int(ok.sum())} rows): {', '.join(constant)}.</p>"
            if constant else "")
    return ("<h2>Objectives</h2><p>Range over the ok rows and the design at each extreme.</p>" + note
            + _table(["objective", "unit", "min", "design at min", "max", "design at max", "mean"], rows, left=2))


def _design(table: ResultsTable, index: int, columns: list[str]) -> str:
    return Raw(", ".join(f"{html.escape(c)}={fmt(table.df[c].iloc[index])}" for c in columns))


def _pareto_section(table: ResultsTable, parameters: list[str], ok: np.ndarray) -> str:
    senses = table.objective_senses()
    head = "<h2>Pareto front</h2>"
    if len(senses) < 2:
        why = "no sweep metadata" if not table.spec else f"{len(senses)} objective(s) with a sense in the spec"
        example = " ".join(f"--min {html.escape(o)}" for o in roles(table)[1][:2])
        return head + (f"<p class='note'>Needs two or more objectives with a sense ({why}): give a second objective "
                       f"a <code>sense</code> in the spec, or choose the objectives with <code>cosim report TABLE "
                       f"{example} -o report.html</code> (or <code>cosim pareto TABLE {example}</code>).</p>")
    names = list(senses)
    values = np.column_stack([np.where(ok, table.values(n), np.nan) for n in names])
    front = pareto_mask(values, [senses[n] for n in names])
    show = [c for c in ["point_id", *parameters] if c in table.df.columns]
    df = table.df.loc[front, show + names].sort_values(names[0], ascending=senses[names[0]] == "min")
    kind = "ok, feasible" if "feasible" in table.df.columns else "ok"
    text = head + (f"<p>{int(front.sum())} non-dominated of {int(ok.sum())} {kind} rows for "
                   + ", ".join(f"{senses[n]}imize {html.escape(n)}" for n in names) + ".</p>")
    text += _table(show + names, df.head(MAX_FRONT_ROWS).itertuples(index=False), left=1)
    if len(df) > MAX_FRONT_ROWS:
        text += f"<p class='note'>First {MAX_FRONT_ROWS} of {len(df)} rows; <code>cosim pareto --csv</code> gives all.</p>"
    fig = new_figure(6.5, 4.5)
    ax, _ = scatter_cloud(fig, table, names[0], names[1], active=ok, rows=None)
    draw_front(ax, table, names[0], names[1], front)
    return text + f"<figure>{png_base64(fig)}<figcaption>Pareto front of {html.escape(names[0])} and " \
                  f"{html.escape(names[1])} over all ok rows (greyed: not ok).</figcaption></figure>"


def _optimization_section(table: ResultsTable) -> str:
    """For an optimisation run: its settings and the hypervolume of the front against evaluations."""
    meta = table.metadata or {}
    if meta.get("kind") != "optimization":
        return ""
    from cosim.analysis.hypervolume import HV_REFERENCE, hypervolume_history

    settings = meta.get("optimize") or {}
    text = "<h2>Optimisation</h2>" + _table(["setting", "value"], [(k, _setting_text(settings.get(k))) for k in
                                                                  ("sampler", "budget", "batch", "seed", "objectives",
                                                                   "constraints")], left=2)
    senses = table.objective_senses()
    if not senses:
        return text
    names = list(senses)
    order = np.argsort(table.values("trial"), kind="stable") if "trial" in table.df.columns \
        else np.arange(len(table.df))
    values = np.column_stack([table.values(n) for n in names])[order]
    usable = (table.ok_mask() & table.feasible_mask())[order] & np.all(np.isfinite(values), axis=1)
    batches = table.values("batch")[order] if "batch" in table.df.columns else None
    history = hypervolume_history(values, [senses[n] for n in names], usable, batches)
    fig = new_figure(6.0, 4.0)
    ax = fig.add_subplot(111)
    ax.plot(np.arange(1, len(history) + 1), history, drawstyle="steps-post")
    ax.set_xlabel("evaluations")
    ax.set_ylabel("hypervolume")
    ax.grid(alpha=0.3)
    final = float(history[-1]) if len(history) else 0.0
    return text + (f"<p>Hypervolume of the feasible front after each evaluation: objectives scaled to [0, 1] "
                   f"between the ideal and nadir points of the final front, reference point {HV_REFERENCE} in "
                   f"each; final {final:.4f}.</p>"
                   f"<figure>{png_base64(fig)}<figcaption>Hypervolume against evaluations.</figcaption></figure>")


def _sobol_section(table: ResultsTable) -> str:
    """For a ``cosim sensitivity`` run: its indices with confidence half-widths, and their figure."""
    meta = table.metadata or {}
    settings = meta.get("sensitivity") or {}
    if meta.get("kind") != "sensitivity":
        return ""
    import pandas as pd

    head = (f"<h2>Sensitivity indices ({html.escape(str(settings.get('method')))}, n={settings.get('n')}, "
            f"{settings.get('samples')} samples, seed {settings.get('seed')})</h2>")
    path = table.path.parent / str(settings.get("table", "sensitivity.csv"))
    if not path.exists():
        return head + f"<p class='note'>{html.escape(str(path))} is missing; run cosim sensitivity again.</p>"
    indices = pd.read_csv(path)
    wide = indices.pivot_table(index=["objective", "parameter"], columns="index", values=["value", "conf"],
                               sort=False)
    names = list(dict.fromkeys(indices["index"]))
    rows = [[objective, parameter] + [Raw(f"{fmt(wide.loc[(objective, parameter), ('value', n)])} ± "
                                          f"{fmt(wide.loc[(objective, parameter), ('conf', n)])}") for n in names]
            for objective, parameter in wide.index]
    text = head + ("<p>Sobol: S1 is the share of the objective's variance due to the parameter alone, ST that "
                   "including all its interactions; Morris: mu* the mean absolute elementary effect (per unit of "
                   "the parameter's range), sigma their spread (interactions, non-linearity). ± is the 95 % "
                   "confidence half-width (bootstrap).</p>")
    text += _table(["objective", "parameter", *names], rows, left=2)
    figure = table.path.parent / str(settings.get("figure", "sensitivity.png"))
    if figure.exists():
        data = base64.b64encode(figure.read_bytes()).decode()
        text += f"<figure><img alt='indices' src='data:image/png;base64,{data}'><figcaption>Indices with " \
                "their confidence intervals.</figcaption></figure>"
    return text


def _surrogate_section(table: ResultsTable) -> str:
    """The surrogates ``cosim surrogate`` stored beside the table: Q² per objective, the parameters ranked by
    their total Sobol index, and each objective's simulated values against their k-fold predictions."""
    from cosim.analysis.surrogate import read, surrogate_folder
    from cosim.analysis.surrogate.ranking import parameter_q2

    head = "<h2>Surrogates and their prognosis quality</h2>"
    folder = surrogate_folder(table.path.parent)
    if not (folder / "models.json").is_file():
        return head + ("<p class='note'>None fitted yet: <code>cosim surrogate DIR</code> fits one per objective "
                       "and the next report shows them here.</p>")
    try:
        surrogates = read(folder)
    except AnalysisError as exc:
        return head + f"<p class='warn'>{html.escape(str(exc))}</p>"
    text = head + ("<p>Q² (coefficient of prognosis) is 1 - the squared error of each design's prediction by the "
                   "surrogate fitted without it (5-fold cross-validation) / the objective's variance: 1 is a "
                   "perfect prognosis, 0 no better than the mean. Parameters are ranked by the total Sobol index "
                   "ST of the surrogate (its variance due to the parameter with all its interactions); a "
                   "parameter's Q² is its coefficient of prognosis, Q² × ST: the share of the objective's variance "
                   "the surrogate predicts through that parameter.</p>")
    rows = [[name, s.fitted.candidate, s.fitted.q2, s.fitted.rmse, s.rows,
             ", ".join(f"{i.parameter} {i.total:.2f} ({parameter_q2(s.fitted.q2, i):.2f})" for i in s.ranking)]
            for name, s in surrogates.objectives.items()]
    text += _table(["objective", "surrogate", "Q²", "RMSE", "designs", "ranking: total Sobol index (Q² of the "
                    "parameter)"], rows)
    if surrogates.failures is not None:
        f = surrogates.failures
        text += (f"<p>Failed designs: {f.failed} of {f.total}; the classifier of where they fail has a 5-fold "
                 f"balanced accuracy of {f.balanced_accuracy:.3f} (0.5: guessing).</p>")
    figures = []
    for name, s in list(surrogates.objectives.items())[:MAX_CLOUDS]:
        if not s.fitted.simulated:
            continue
        fig = new_figure(4.5, 4.0)
        ax = fig.add_subplot(1, 1, 1)
        simulated, predicted = np.asarray(s.fitted.simulated), np.asarray(s.fitted.cross_validated)
        ax.scatter(simulated, predicted, s=8, alpha=0.6)
        low, high = float(min(simulated.min(), predicted.min())), float(max(simulated.max(), predicted.max()))
        ax.plot([low, high], [low, high], color="grey", linewidth=1)
        ax.set_xlabel(f"simulated {table.label(name)}")
        ax.set_ylabel("predicted (5-fold)")
        ax.set_title(f"{name}: Q² {s.fitted.q2:.4f}")
        figures.append(f"<figure>{png_base64(fig)}<figcaption>{html.escape(name)}: simulated against the "
                       "prediction of the surrogate fitted without the design.</figcaption></figure>")
    return text + "".join(figures)


def _sensitivity_section(table: ResultsTable, parameters: list[str], objectives: list[str], ok: np.ndarray) -> str:
    head = ("<h2>What drives each objective</h2><p>Spearman's rank correlation ρ (direction and strength of a "
            "monotonic trend) and the correlation ratio η² (share of the objective's variance explained by the "
            "parameter alone; the main-effect index on a grid).</p>")
    if not parameters:
        return head + "<p class='note'>The design parameters are unknown (no sweep metadata).</p>"
    found = {(i.parameter, i.objective): i for i in influences(table, parameters, objectives, ok)}
    header = ["objective"] + [f"{p}: ρ / η²" for p in parameters]
    rows = [[o] + [f"{fmt(found[p, o].spearman)} / {fmt(found[p, o].eta2)}" for p in parameters]
            for o in objectives]
    return head + _table(header, rows)


def _figure_section(table: ResultsTable, parameters: list[str], objectives: list[str], ok: np.ndarray) -> str:
    text = "<h2>Figures</h2>"
    shown = objectives[:MAX_CLOUDS]
    for o in shown:
        fig = new_figure(6.0, 4.5)
        if len(parameters) >= 2:
            x, y, caption = parameters[0], parameters[1], f"{o} over {parameters[0]} and {parameters[1]}"
        elif len(parameters) == 1:
            x, y, caption = parameters[0], o, f"{o} over {parameters[0]}"
        else:
            continue
        scatter_cloud(fig, table, x, y, color=o, active=ok)
        text += f"<figure>{png_base64(fig)}<figcaption>{html.escape(caption)}</figcaption></figure>"
    if not parameters:
        text += "<p class='note'>Clouds over the parameters need sweep metadata.</p>"
    elif len(objectives) > MAX_CLOUDS:
        text += f"<p class='note'>{len(objectives) - MAX_CLOUDS} more objectives: use <code>cosim plot</code>.</p>"
    return text
