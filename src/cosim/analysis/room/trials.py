"""The Study tab of an optimisation (a folder written by ``cosim optimize``): what optuna-dashboard shows, drawn
from cosim's own results table (issue 39.2).

- **history** (``history``): each trial's value of one objective against its trial number (usable trials, ok
  and feasible, in blue ``history-values``; infeasible ones grey ``history-infeasible``) and the best value so
  far (``history-best``, a step line);
- **parameter importances** (``importances``): each design parameter's share of the objective's variance,
  by optuna's fANOVA evaluator (:class:`optuna.importance.FanovaImportanceEvaluator`, optuna-dashboard's
  default, seed 0) on an optuna study rebuilt in memory from the table's usable trials (:func:`importances`):
  the optimiser's own study is not kept on disk, the table is.  Its forest is smaller than optuna's default
  (:data:`FOREST`: 16 trees of depth 8, not 64 of depth 64, which took 198 s for the 1000 trials of
  examples/pick_and_place_free_pose/results_optimize on the loaded 2-core machine; this one 0.9 s, with the
  same two parameters first and their shares within 0.03);
- **slice plots** (``slice:<parameter>``): the objective against each parameter, coloured by trial number;
- **contour** (``contour``): the objective over two parameters (``contour-x``, ``contour-y``; by default the
  two most important), interpolated linearly between the trials (scipy's ``griddata``; blank outside their
  hull), with the trials drawn over it.

``study-objective`` chooses the objective the four views show.  The functions above :class:`TrialViews` are
plain numpy (tested without a browser); names and units reach the page only as axis labels, titles and
factors, which bokeh draws as text.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
from bokeh.layouts import column, gridplot, row
from bokeh.models import ColumnDataSource, FactorRange, HoverTool, LinearColorMapper
from bokeh.models.annotations import ColorBar
from bokeh.models.widgets import Select
from bokeh.palettes import Viridis256
from bokeh.plotting import figure

from cosim.analysis.table import ResultsTable

GRID = 60  # contour cells per axis
FOREST = {"n_trees": 16, "max_depth": 8}  # fANOVA's random forest (module docstring)
MAX_IMPORTANCE_TRIALS = 2000  # a larger table's importances come from a random sample (seed 0) of this many
MAX_SLICES = 12
SLICE = 250  # px of one slice plot


def is_optimisation(table: ResultsTable) -> bool:
    """A folder of ``cosim optimize``: its metadata's kind, and a trial column to order by."""
    return str((table.metadata or {}).get("kind")) == "optimization" and "trial" in table.df.columns


def usable(table: ResultsTable) -> np.ndarray:
    """Trials the optimiser learnt a value from: ok and feasible."""
    return table.ok_mask() & table.feasible_mask()


def history(table: ResultsTable, objective: str, sense: str) -> dict[str, np.ndarray]:
    """``trial``, ``value`` (NaN where not usable), ``usable`` and ``best`` (the best usable value up to and
    including each trial, NaN before the first), in trial order."""
    order = np.argsort(table.values("trial"), kind="stable")
    value = table.values(objective)[order]
    good = usable(table)[order] & np.isfinite(value)
    masked = np.where(good, value, np.inf if sense == "min" else -np.inf)
    best = np.minimum.accumulate(masked) if sense == "min" else np.maximum.accumulate(masked)
    best = np.where(np.isfinite(best), best, np.nan)
    return {"trial": table.values("trial")[order], "value": np.where(good, value, np.nan), "usable": good,
            "best": best, "row": order}


def parameters(table: ResultsTable, numeric: Sequence[str]) -> list[str]:
    """The design parameters that vary over the usable trials (a constant one has no importance)."""
    ok = usable(table)
    out = []
    for name in table.parameter_columns():
        if name in numeric:
            v = table.values(name)[ok]
            v = v[np.isfinite(v)]
            if v.size and v.max() > v.min():
                out.append(name)
    return out


def importances(table: ResultsTable, names: Sequence[str], objectives: dict[str, str]) -> dict[str, dict[str, float]]:
    """objective -> {parameter: importance} (they sum to 1), by optuna's fANOVA on a study rebuilt in memory
    from the usable trials that have every objective (a trial per row: its parameters as float distributions
    over their range in the table, its objectives as values; above :data:`MAX_IMPORTANCE_TRIALS` such trials, a
    random sample of that many, seed 0).  An objective with fewer than 2 such trials, or no parameter that
    varies, gets {}."""
    import optuna
    from optuna.distributions import FloatDistribution
    from optuna.importance import FanovaImportanceEvaluator, get_param_importances

    senses = list(objectives.items())
    values = np.column_stack([table.values(o) for o, _ in senses]) if senses else np.zeros((len(table.df), 0))
    params = np.column_stack([table.values(p) for p in names]) if names else np.zeros((len(table.df), 0))
    rows = np.flatnonzero(usable(table) & np.all(np.isfinite(values), axis=1) & np.all(np.isfinite(params), axis=1))
    if len(rows) < 2 or not names or not senses:
        return {o: {} for o, _ in senses}
    if len(rows) > MAX_IMPORTANCE_TRIALS:  # the forest's cost grows with the trials; the shares settle long before
        rows = np.sort(np.random.default_rng(0).choice(rows, MAX_IMPORTANCE_TRIALS, replace=False))
    distributions = {p: FloatDistribution(float(params[rows, k].min()), float(params[rows, k].max()))
                     for k, p in enumerate(names)}
    before = optuna.logging.get_verbosity()
    optuna.logging.set_verbosity(optuna.logging.WARNING)  # "A new study created in memory" is not news here
    try:
        study = optuna.create_study(directions=["minimize" if s == "min" else "maximize" for _, s in senses])
        study.add_trials([optuna.trial.create_trial(
            params={p: float(params[r, k]) for k, p in enumerate(names)}, distributions=distributions,
            values=[float(v) for v in values[r]]) for r in rows])
        out = {}
        for k, (name, _) in enumerate(senses):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # optuna's ExperimentalWarning about target=, for each objective
                got = get_param_importances(study, evaluator=FanovaImportanceEvaluator(seed=0, **FOREST),
                                            target=lambda t, k=k: t.values[k])
            out[name] = {p: float(v) for p, v in got.items()}
        return out
    finally:
        optuna.logging.set_verbosity(before)


def contour(x: np.ndarray, y: np.ndarray, z: np.ndarray, cells: int = GRID) -> dict[str, Any]:
    """``z`` over a grid of ``cells`` x ``cells`` spanning the finite points (x, y), interpolated linearly
    (scipy ``griddata`` on coordinates scaled to the unit square, NaN outside the points' hull): ``image`` (rows
    bottom first), ``x0``, ``y0``, ``dw``, ``dh``.  Fewer than 3 points, or points on a line: an all-NaN image."""
    from scipy.interpolate import griddata

    good = np.isfinite(x) & np.isfinite(y) & np.isfinite(z)
    x, y, z = x[good], y[good], z[good]
    x0, x1 = (float(x.min()), float(x.max())) if x.size else (0.0, 1.0)
    y0, y1 = (float(y.min()), float(y.max())) if y.size else (0.0, 1.0)
    dw, dh = (x1 - x0) or 1.0, (y1 - y0) or 1.0
    image = np.full((cells, cells), np.nan)
    if x.size >= 3:
        centres = (np.arange(cells) + 0.5) / cells
        gx, gy = np.meshgrid(centres, centres)
        try:
            image = griddata(np.column_stack([(x - x0) / dw, (y - y0) / dh]), z, (gx, gy), method="linear")
        except Exception:  # scipy's Qhull refuses points on a line (QhullError): no surface to draw
            pass
    return {"image": image, "x0": x0, "y0": y0, "dw": dw, "dh": dh}


class TrialViews:
    """The Study tab's views of an optimisation (module docstring); ``layout`` goes into the tab."""

    def __init__(self, table: ResultsTable, numeric: Sequence[str]):
        self.table = table
        self.senses = {o: s for o, s in table.objective_senses().items() if o in numeric}
        self.names = parameters(table, numeric)
        self.importance = importances(table, self.names, self.senses)
        objectives = list(self.senses)
        self.objective = Select(title="objective", value=objectives[0] if objectives else "",
                                options=objectives, name="study-objective", width=260)
        ranked = self._ranked(self.objective.value)
        self.contour_x = Select(title="contour: x", value=ranked[0] if ranked else "", options=self.names,
                                name="contour-x", width=220)
        self.contour_y = Select(title="y", value=ranked[1] if len(ranked) > 1 else "", options=self.names,
                                name="contour-y", width=220)
        self.layout = column(name="trials")
        self._draw()
        for select in (self.objective, self.contour_x, self.contour_y):
            select.on_change("value", lambda attr, old, new: self._draw())

    def _ranked(self, objective: str) -> list[str]:
        """The parameters by importance for ``objective``, most important first (table order without it)."""
        got = self.importance.get(objective) or {}
        return sorted(self.names, key=lambda p: -got.get(p, 0.0)) if got else list(self.names)

    def _draw(self) -> None:
        objective = self.objective.value
        if not objective:
            self.layout.children = []
            return
        label = self.table.label
        views: list = [row(self.objective), self._history(objective, label(objective)),
                       self._importances(objective)]
        if self.names:
            views.append(self._slices(objective, label(objective)))
        if len(self.names) >= 2 and self.contour_x.value and self.contour_y.value:
            views += [row(self.contour_x, self.contour_y), self._contour(objective, label(objective))]
        self.layout.children = views

    def _history(self, objective: str, label: str) -> Any:
        h = history(self.table, objective, self.senses[objective])
        fig = figure(name="history", width=760, height=300, x_axis_label="trial", y_axis_label=label,
                     title=f"optimisation history of {objective}: every trial and the best so far",
                     tools="pan,wheel_zoom,box_zoom,reset,save")
        bad = ~h["usable"]
        fig.scatter(h["trial"][bad], self.table.values(objective)[h["row"]][bad], size=5, color="#bbbbbb",
                    legend_label="not usable (failed or infeasible)", name="history-infeasible")
        fig.scatter(h["trial"][h["usable"]], h["value"][h["usable"]], size=5, color="#1f77b4", alpha=0.7,
                    legend_label="trial", name="history-values")
        fig.step(h["trial"], h["best"], mode="after", line_width=2, color="#e31a1c", legend_label="best so far",
                 name="history-best")
        fig.legend.location = "top_right"
        fig.legend.click_policy = "hide"
        return fig

    def _importances(self, objective: str) -> Any:
        got = self.importance.get(objective) or {}
        names = [p for p in reversed(self._ranked(objective))]  # most important on top
        value = [got.get(p, 0.0) for p in names]
        fig = figure(name="importances", width=760, height=80 + 26 * max(len(names), 1),
                     y_range=FactorRange(*names) if names else FactorRange("(no parameter varies)"),
                     x_axis_label="importance (fANOVA, sums to 1)", tools="save",
                     title=f"parameter importances for {objective} (optuna's fANOVA on the table's trials)")
        source = ColumnDataSource({"parameter": names, "importance": value}, name="importances-source")
        fig.hbar(y="parameter", right="importance", height=0.7, source=source, color="#1f77b4")
        fig.add_tools(HoverTool(tooltips=[("parameter", "@parameter"), ("importance", "@importance{0.000}")]))
        return fig

    def _slices(self, objective: str, label: str) -> Any:
        ok = usable(self.table)
        z = self.table.values(objective)
        trial = self.table.values("trial")
        mapper = LinearColorMapper(palette=Viridis256, low=float(np.nanmin(trial)), high=float(np.nanmax(trial)))
        panels = []
        for k, name in enumerate(self._ranked(objective)[:MAX_SLICES]):
            fig = figure(name=f"slice:{name}", width=SLICE, height=SLICE, x_axis_label=self.table.label(name),
                         y_axis_label=label if k % 3 == 0 else None, tools="pan,wheel_zoom,reset,save",
                         min_border=4)
            fig.scatter("x", "y", size=4, alpha=0.7, color={"field": "trial", "transform": mapper},
                        source=ColumnDataSource({"x": self.table.values(name)[ok], "y": z[ok], "trial": trial[ok]},
                                                name=f"slice-source:{name}"))
            fig.axis.major_label_text_font_size = "7pt"
            panels.append(fig)
        # on the first row's last panel: a wider panel elsewhere would widen its column of the grid
        panels[min(2, len(panels) - 1)].add_layout(ColorBar(color_mapper=mapper, title="trial", width=8), "right")
        grid = gridplot(panels, ncols=3, toolbar_location="right", merge_tools=True)
        return column(figure_title(f"slice plots of {objective} (colour: trial)"), grid)

    def _contour(self, objective: str, label: str) -> Any:
        ok = usable(self.table)
        px, py = self.table.values(self.contour_x.value)[ok], self.table.values(self.contour_y.value)[ok]
        z = self.table.values(objective)[ok]
        grid = contour(px, py, z)
        finite = grid["image"][np.isfinite(grid["image"])]
        lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        mapper = LinearColorMapper(palette=Viridis256, low=lo, high=hi if hi > lo else lo + 1.0,
                                   nan_color=(0, 0, 0, 0))
        fig = figure(name="contour", width=620, height=520, x_axis_label=self.table.label(self.contour_x.value),
                     y_axis_label=self.table.label(self.contour_y.value), tools="pan,wheel_zoom,reset,save",
                     title=f"{objective} over two parameters (interpolated between the trials)",
                     x_range=(grid["x0"], grid["x0"] + grid["dw"]), y_range=(grid["y0"], grid["y0"] + grid["dh"]))
        fig.image(image="image", x="x", y="y", dw="dw", dh="dh", color_mapper=mapper, name="contour-image",
                  source=ColumnDataSource({"image": [grid["image"]], "x": [grid["x0"]], "y": [grid["y0"]],
                                           "dw": [grid["dw"]], "dh": [grid["dh"]]}, name="contour-source"))
        fig.scatter(px, py, size=4, color="#000000", alpha=0.6, name="contour-trials")
        fig.add_layout(ColorBar(color_mapper=mapper, title=label, width=10), "right")
        return fig


def figure_title(text: str) -> Any:
    """A bold line of text above a grid of plots (bokeh's Div escapes nothing: ``text`` is escaped here)."""
    import html

    from bokeh.models import Div

    return Div(text=f"<b>{html.escape(text)}</b>", width=760, disable_math=True)
