"""The decision room's Surrogate tab: predicted surfaces between the simulated designs, and "simulate here".

Shown when the study's folder has surrogates (``cosim surrogate DIR`` wrote ``DIR/surrogate/models.json``):

- an objective and any two of the surrogates' parameters are chosen; the map is the surrogate's prediction (or
  its standard deviation) over a GRID x GRID grid spanning the box of the fitted designs in those two
  parameters, every other parameter **held at a design's values**: the first selected design (a click on the
  cloud or the ranking selects one), else the first ok design;
- the simulated ok designs are drawn on top (their values of the two parameters), the held design ringed;
- the objective's Q² (coefficient of prognosis) and the two parameters' own Q² (Q² x ST) are on screen, with a
  warning below 0.8, the level ``cosim surrogate`` warns at;
- a click on the map picks a predicted design (the held design with the two parameters at the clicked values):
  its prediction +- one standard deviation for every objective is listed, and **Simulate here** runs it
  (:func:`cosim.analysis.rerun.rerun`, with the spec a re-run uses) and adds it to the study as a row
  (:func:`add_row`: appended to the folder's table under its lock, as a sweep writes rows), after which the
  room shows the folder with that row.

Every string from the folder (objective and parameter names, design ids, messages) is escaped; the page gets
no script of ours (bokeh's callbacks run on the server).
"""

from __future__ import annotations

import html
import threading
from pathlib import Path
from typing import Any, Callable

import numpy as np
from bokeh.events import Tap
from bokeh.layouts import column, row
from bokeh.models import ColumnDataSource, LinearColorMapper
from bokeh.models.annotations import ColorBar
from bokeh.models.widgets import Select
from bokeh.plotting import figure

from cosim.analysis.room import views as V

GRID = 40  # predictions per side of the map
TRUST_BELOW = 0.8  # as cosim surrogate's warning
WHAT = [("mean", "prediction"), ("std", "standard deviation")]


def models_of(study: Any) -> Path | None:
    """The surrogates' ``models.json`` of the study's folder, None when there are none."""
    from cosim.analysis.surrogate import surrogate_folder

    path = Path(study.table.path)
    folder = path.parent if path.name == "results.parquet" else path.parent
    models = surrogate_folder(folder) / "models.json"
    return models if models.is_file() else None


class SurrogateView:
    """The tab's models and callbacks; ``on_added(study)`` is called (in the document's lock) with the study
    re-read from its folder once a design simulated here is stored."""

    def __init__(self, doc: Any, study: Any, held: int | None, on_added: Callable[[Any], None]):
        from cosim.analysis.surrogate import read

        self.doc, self.study, self.on_added = doc, study, on_added
        self.surrogates = read(models_of(study))  # type: ignore[arg-type]
        self.parameters = list(self.surrogates.parameters)
        objectives = list(self.surrogates.objectives)
        self.held = self._default_held() if held is None else held
        self.pick: dict[str, float] | None = None
        first, second = self.parameters[0], self.parameters[1 % len(self.parameters)]
        self.objective = Select(title="objective", value=objectives[0], options=objectives,
                                name="surrogate-objective", width=220)
        self.what = Select(title="map of", value="mean", options=WHAT, name="surrogate-what", width=180)
        self.x = Select(title="x", value=first, options=self.parameters, name="surrogate-x", width=220)
        self.y = Select(title="y", value=second, options=self.parameters, name="surrogate-y", width=220)
        self.quality = V.text("", "surrogate-quality", width=900)
        self.held_text = V.text("", "surrogate-held", width=900)
        self.mapper = LinearColorMapper(palette="Viridis256")
        self.image = ColumnDataSource({"image": [np.zeros((2, 2))], "x": [0.0], "y": [0.0], "dw": [1.0], "dh": [1.0]},
                                      name="surrogate-image")
        self.designs = ColumnDataSource({"x": [], "y": []}, name="surrogate-designs")
        self.held_source = ColumnDataSource({"x": [], "y": []}, name="surrogate-held-design")
        self.pick_source = ColumnDataSource({"x": [], "y": []}, name="surrogate-pick")
        self.figure = fig = figure(width=620, height=520, name="surrogate-map", tools="pan,wheel_zoom,reset,save",
                                   toolbar_location="above")
        fig.image(image="image", x="x", y="y", dw="dw", dh="dh", source=self.image, color_mapper=self.mapper)
        fig.scatter("x", "y", source=self.designs, size=6, color="white", line_color="black",
                    legend_label="simulated designs")
        fig.scatter("x", "y", source=self.held_source, size=16, fill_alpha=0, line_color="red", line_width=2,
                    legend_label="held design")
        fig.scatter("x", "y", source=self.pick_source, size=14, marker="x", line_color="orange", line_width=3,
                    legend_label="picked")
        fig.legend.location = "top_left"
        fig.add_layout(ColorBar(color_mapper=self.mapper, width=12), "right")
        fig.on_event(Tap, self._on_tap)
        self.pick_text = V.text("<p>Click the map to pick a predicted design.</p>", "surrogate-pick-text",
                                width=900)
        self.simulate = V.button("Simulate here", "simulate-here", "primary")
        self.simulate.disabled = True
        self.status = V.text("", "simulate-status", width=900)
        for select in (self.objective, self.what, self.x, self.y):
            select.on_change("value", lambda attr, old, new: self.draw())
        self.simulate.on_click(self._on_simulate)
        self.layout = column(row(self.objective, self.what, self.x, self.y), self.quality, self.held_text,
                             self.figure, self.pick_text, row(self.simulate, self.status), name="surrogate-tab")
        self.draw()

    # -- what is shown --------------------------------------------------------------------------------------
    def _default_held(self) -> int:
        ok = np.flatnonzero(self.study.status == "ok")
        return int(ok[0]) if len(ok) else 0

    def hold(self, held: int | None) -> None:
        """Hold the other parameters at row ``held`` (None: the first ok design) and draw again."""
        self.held = self._default_held() if held is None else held
        self.draw()

    def reload(self, study: Any, held: int | None) -> None:
        self.study = study
        self.hold(held)

    def held_values(self) -> np.ndarray:
        """The held design's value of every surrogate parameter (the box's centre where it has none)."""
        out = []
        for j, name in enumerate(self.parameters):
            value = np.nan
            if name in self.study.table.df.columns:
                value = float(self.study.table.values(name)[self.held])
            if not np.isfinite(value):
                scaling = next(iter(self.surrogates.objectives.values())).fitted.model.scaling
                value = float(scaling.low[j] + scaling.span[j] / 2)
            out.append(value)
        return np.asarray(out)

    def grid(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x values, y values, designs): the GRID x GRID designs of the map, row-major with y outer."""
        model = self.surrogates.objectives[self.objective.value].fitted.model
        i, j = self.parameters.index(self.x.value), self.parameters.index(self.y.value)
        xs = np.linspace(model.scaling.low[i], model.scaling.low[i] + model.scaling.span[i], GRID)
        ys = np.linspace(model.scaling.low[j], model.scaling.low[j] + model.scaling.span[j], GRID)
        designs = np.tile(self.held_values(), (GRID * GRID, 1))
        gx, gy = np.meshgrid(xs, ys)
        designs[:, i], designs[:, j] = gx.ravel(), gy.ravel()
        return xs, ys, designs

    def draw(self) -> None:
        name, x, y = self.objective.value, self.x.value, self.y.value
        fitted = self.surrogates.objectives[name].fitted
        xs, ys, designs = self.grid()
        mean, std = fitted.model.predict(designs)
        values = (mean if self.what.value == "mean" else std).reshape(GRID, GRID)
        step_x, step_y = (xs[-1] - xs[0]) / (GRID - 1), (ys[-1] - ys[0]) / (GRID - 1)
        self.image.data = {"image": [values], "x": [xs[0] - step_x / 2], "y": [ys[0] - step_y / 2],
                           "dw": [xs[-1] - xs[0] + step_x], "dh": [ys[-1] - ys[0] + step_y]}
        self.mapper.low, self.mapper.high = float(values.min()), float(values.max())
        table, ok = self.study.table, self.study.status == "ok"
        have = x in table.df.columns and y in table.df.columns
        self.designs.data = {"x": table.values(x)[ok], "y": table.values(y)[ok]} if have else {"x": [], "y": []}
        held = self.held_values()
        self.held_source.data = {"x": [held[self.parameters.index(x)]], "y": [held[self.parameters.index(y)]]}
        self.figure.xaxis.axis_label, self.figure.yaxis.axis_label = table.label(x), table.label(y)
        self.figure.title.text = f"{name}: {dict(WHAT)[self.what.value]} of the surrogate"
        self._describe(name, x, y)

    def _describe(self, name: str, x: str, y: str) -> None:
        from cosim.analysis.surrogate.ranking import parameter_q2

        s = self.surrogates.objectives[name]
        own = {i.parameter: parameter_q2(s.fitted.q2, i) for i in s.ranking}
        warn = (f" <b style='color:#a40000'>Q² below {TRUST_BELOW}: the surrogate predicts new designs poorly; "
                "simulate before deciding.</b>") if not s.fitted.q2 >= TRUST_BELOW else ""
        self.quality.text = (f"<p>{html.escape(name)}: {html.escape(s.fitted.candidate)}, Q² {s.fitted.q2:.4f} "
                             f"(5-fold, {s.rows} designs), RMSE {s.fitted.rmse:.4g}; Q² of "
                             f"{html.escape(x)} {own.get(x, float('nan')):.3f}, of {html.escape(y)} "
                             f"{own.get(y, float('nan')):.3f}.{warn}</p>")
        others = [p for p in self.parameters if p not in (x, y)]
        held = self.held_values()
        shown = ", ".join(f"{html.escape(p)} = {held[self.parameters.index(p)]:.6g}" for p in others)
        self.held_text.text = (f"<p>Other parameters held at design <code>{html.escape(str(self.study.ids[self.held]))}"
                               f"</code> (select another on the Points or Decide tab){': ' + shown if shown else ''}"
                               "</p>")

    # -- picking and simulating ----------------------------------------------------------------------------
    def _on_tap(self, event: Any) -> None:
        if event.x is None or event.y is None:
            return
        values = self.held_values()
        values[self.parameters.index(self.x.value)] = float(event.x)
        values[self.parameters.index(self.y.value)] = float(event.y)
        self.pick = dict(zip(self.parameters, map(float, values)))
        self.pick_source.data = {"x": [float(event.x)], "y": [float(event.y)]}
        predicted = self.surrogates.predict(_frame(self.pick), "the picked design")
        lines = [f"<li>{html.escape(n)}: {float(predicted[n].iloc[0]):.6g} ± {float(predicted[n + '_std'].iloc[0]):.3g}"
                 "</li>" for n in self.surrogates.objectives]
        design = ", ".join(f"{html.escape(p)} = {v:.6g}" for p, v in self.pick.items())
        self.pick_text.text = f"<p><b>Picked design</b>: {design}</p><p>predicted:</p><ul>{''.join(lines)}</ul>"
        self.simulate.disabled = False
        self.status.text = ""

    def _on_simulate(self) -> None:
        if self.pick is None:
            return
        self.simulate.disabled = True
        self.status.text = "simulating the picked design …"
        threading.Thread(target=self._simulate, args=(dict(self.pick), self.held), daemon=True,
                         name="cosim-room-simulate-here").start()

    def _simulate(self, pick: dict[str, float], held: int) -> None:
        try:
            outcome: Any = add_row(self.study, held, pick)
        except Exception as exc:  # a bad spec or a busy folder is shown in the page, never a dead server
            outcome = exc
        self.doc.add_next_tick_callback(lambda: self._show(outcome))

    def _show(self, outcome: Any) -> None:
        self.simulate.disabled = False
        if isinstance(outcome, Exception):
            first = str(outcome).splitlines()[0] if str(outcome) else repr(outcome)
            self.status.text = f"<span style='color:#a40000'>simulate here failed: {html.escape(first)}</span>"
            return
        study, row = outcome
        values = ", ".join(f"{html.escape(n)} = {row[n]:.6g}" for n in self.surrogates.objectives
                           if isinstance(row.get(n), (int, float)))
        self.status.text = (f"added design <code>{html.escape(str(row['point_id']))}</code> to the study: "
                            f"{html.escape(str(row['status']))}" + (f"; simulated {values}" if values else ""))
        self.on_added(study)


def _frame(values: dict[str, float]) -> Any:
    import pandas as pd

    return pd.DataFrame([values])


def add_row(study: Any, held: int, pick: dict[str, float]) -> tuple[Any, dict[str, Any]]:
    """Simulate the design ``pick`` (surrogate parameter columns -> values; the spec's other design parameters
    at row ``held``'s values) and add it to the study's folder as a row; returns (the study re-read from its
    folder, the row).  Raises AnalysisError when the table is not a results folder or the spec's parameters
    do not fit, FolderInUse when a study is writing into the folder."""
    import time

    from cosim.analysis.rerun import load_rerun_spec, point_values, rerun
    from cosim.analysis.room.data import Study
    from cosim.analysis.table import AnalysisError, load_results
    from cosim.execution.point_row import PointRow
    from cosim.results.lock import FolderLock
    from cosim.results.store import ResultsStore
    from cosim.spec.design import DesignSpace

    table = study.table
    path = Path(table.path)
    if path.name != "results.parquet":
        raise AnalysisError(f"{path}: a design simulated here is added to a results folder; this table is a file")
    spec = load_rerun_spec(table, study.spec_path)
    values = point_values(table, held, [p.target for p in spec.design.parameters])
    for name, value in pick.items():
        _set(values, name, value)
    started = time.perf_counter()
    result, values = rerun(table, spec_path=study.spec_path, values=values, full_record=False)
    space = DesignSpace.dimensions_of(spec)
    point_id = space.point_id(values)
    point = PointRow.of(point_id, result, time.perf_counter() - started).on_worker("room: simulate here")
    row = point.to_dict(space.columns(values))
    if "sampler" in table.df.columns:  # an optimisation's table: say where the row came from
        row["sampler"] = "room"
    folder = path.parent
    lock = FolderLock(folder)
    lock.acquire("cosim explore (simulate here)")
    try:
        store = ResultsStore(folder)
        order = [*map(str, store.read()["point_id"]), point_id]
        store.append([row])
        store.compact(order=order)
    finally:
        lock.release()
    return Study(load_results(folder, study.spec_path), spec_path=study.spec_path), row


def _set(values: dict[str, Any], column: str, value: float) -> None:
    """Set a table column's value in a design's ``{target: value}`` (``target[i]`` an element of an array)."""
    from cosim.analysis.table import AnalysisError

    if column in values:
        values[column] = value
        return
    target, _, index = column.rpartition("[")
    if target in values and index.endswith("]") and index[:-1].isdigit() and isinstance(values[target], list):
        values[target][int(index[:-1]) - 1] = value
        return
    raise AnalysisError(f"the surrogates' parameter '{column}' is not a design parameter of the spec")
