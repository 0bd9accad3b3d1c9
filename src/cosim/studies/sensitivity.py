"""``cosim sensitivity``: variance-based (Sobol) or elementary-effects (Morris) indices of a spec's objectives.

SALib does the statistics; cosim runs the sample:

1. The design space's dimensions (:meth:`DesignSpace.dimensions_of`) become
   SALib's problem: a range is its interval (snapped to ``step`` and rounded
   for integer ranges when given: the indices are then those of the stepped
   model); a value list or boolean is drawn by its index (``[0, n)``, floored).
2. SALib draws the sample: ``sobol`` -- Saltelli's scheme on a scrambled
   Sobol' sequence, ``n * (D + 2)`` runs for D dimensions (first-order and
   total indices); ``morris`` -- ``n`` trajectories of ``D + 1`` runs on a
   4-level grid.
3. The sample runs as a sweep (:class:`~cosim.studies.sweep.Sweep` of kind
   ``sensitivity`` with this sample as its points: Dask, isolation, timeouts,
   fault rows, resuming a sensitivity folder only): the sensitivity design is the study's point source
   (:class:`~cosim.studies.sweep.DesignGrid` over the sample).
   Two sample rows that round to the same design run once.
4. SALib analyses each objective: Sobol gives ``S1`` and ``ST`` with their
   95 % bootstrap confidence half-widths; Morris gives ``mu_star`` (with its
   confidence half-width) and ``sigma``.  A sample whose run is not ok leaves
   a gap the estimators cannot bridge: that objective's indices are NaN.

Output in the results folder: ``results.parquet`` (one row per distinct
design, as a sweep), ``metadata.json`` (``kind: sensitivity`` and the
settings), ``sensitivity.csv`` (objective, parameter, index, value, conf) and
``sensitivity.png``; ``cosim report`` shows both.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Iterator, Mapping, Sequence

import numpy as np

from cosim.errors import Problem, SensitivityError, SpecError
from cosim.studies.options import PYTHON_WORDS

METHODS = ("sobol", "morris")
DEFAULT_N = {"sobol": 256, "morris": 20}
DEFAULT_SEED = 1
MORRIS_LEVELS = 4
INDICES = {"sobol": ("S1", "ST"), "morris": ("mu_star", "sigma")}
TABLE_NAME, FIGURE_NAME = "sensitivity.csv", "sensitivity.png"


class SampleSpace:
    """The design points of a SALib sample, in sample order, each distinct design once.

    Offers what :class:`~cosim.studies.sweep.Sweep` needs of a design space.
    ``row_ids`` gives the point id of every sample row (rows may share one).
    """

    def __init__(self, space: Any, sample: np.ndarray, method: str):
        self.space, self.targets, self.method = space, space.targets, method
        self.row_ids: list[str] = []
        self._points: dict[str, Any] = {}
        for row in sample:
            values = space.values_of([_to_value(dim, x) for (_, dim), x in zip(space.dimensions, row)])
            pid = space.point_id(values)
            self.row_ids.append(pid)
            self._points.setdefault(pid, values)

    def __iter__(self) -> Iterator[Any]:
        from cosim.spec.design import Point

        for index, (pid, values) in enumerate(self._points.items()):
            yield Point(index, pid, values)

    def __len__(self) -> int:
        return len(self._points)

    def head(self, n: int) -> list[Any]:
        return [p for _, p in zip(range(n), self)]

    def columns(self, values: dict[str, Any]) -> dict[str, Any]:
        return self.space.columns(values)


def _to_value(dim: Any, x: float) -> Any:
    """SALib's number for one dimension -> the design value (see the module docstring)."""
    if dim.lo is None:
        return dim.values[min(int(math.floor(x)), len(dim.values) - 1)]
    if dim.step is not None:
        k = min(max(round((x - dim.lo) / dim.step), 0), int((dim.hi - dim.lo) // dim.step + 1e-9))
        x = dim.lo + k * dim.step
        x = round(x, 12)
    return int(round(x)) if dim.integer else float(x)


def salib_problem(space: Any) -> dict[str, Any]:
    """SALib's problem dict for the dimensions of ``space`` (a DesignSpace from ``dimensions_of``)."""
    names, bounds = [], []
    for name, dim in space.dimensions:
        names.append(name)
        bounds.append([0.0, float(len(dim.values))] if dim.lo is None else [float(dim.lo), float(dim.hi)])
    return {"num_vars": len(names), "names": names, "bounds": bounds}


def draw(problem: dict[str, Any], method: str, n: int, seed: int) -> np.ndarray:
    """The SALib sample (rows = runs) for ``method`` with base size ``n``."""
    if method == "sobol":
        from SALib.sample import sobol

        return sobol.sample(problem, n, calc_second_order=False, seed=seed)
    from SALib.sample import morris

    return morris.sample(problem, n, num_levels=MORRIS_LEVELS, seed=seed)


def analyse(problem: dict[str, Any], method: str, sample: np.ndarray, y: np.ndarray, seed: int) -> dict[str, Any]:
    """SALib's indices of outputs ``y`` (one per sample row); NaN everywhere when any output is missing."""
    d = problem["num_vars"]
    if not np.all(np.isfinite(y)):
        nan = np.full(d, np.nan)
        return {k: nan for k in ("S1", "S1_conf", "ST", "ST_conf", "mu_star", "mu_star_conf", "sigma")}
    if method == "sobol":
        from SALib.analyze import sobol

        return sobol.analyze(problem, y, calc_second_order=False, conf_level=0.95, seed=seed)
    from SALib.analyze import morris

    return morris.analyze(problem, sample, y, conf_level=0.95, num_levels=MORRIS_LEVELS, seed=seed)


def index_rows(problem: dict[str, Any], method: str, objective: str, result: dict[str, Any]) -> list[dict]:
    """Long-format rows (objective, parameter, index, value, conf) of one objective's SALib result."""
    rows = []
    for i, name in enumerate(problem["names"]):
        for index in INDICES[method]:
            conf = result.get(f"{index}_conf")
            rows.append({"objective": objective, "parameter": name, "index": index,
                         "value": float(result[index][i]),
                         "conf": float(conf[i]) if conf is not None else float("nan")})
    return rows


#: a Sobol index this far outside [0, 1], or a 95 % half-width this wide, is the sampling's noise, not the model
SOBOL_SLACK, SOBOL_WIDE_CONF = 0.05, 0.25


def unreliable_indices(indices: Any, method: str, n: int, words: Mapping[str, str] = PYTHON_WORDS) -> str:
    """A warning when Sobol indices cannot be trusted (some outside [0, 1] by more than SOBOL_SLACK, or with
    confidence half-widths above SOBOL_WIDE_CONF), naming the worst ones and the base size ``n``; else ``""``.

    Estimated indices are unbiased but noisy: with a small ``n`` they leave [0, 1] (issue 28: -n 8 gave 1.21 and
    -0.31 with no word said).  Morris indices have no such bound: ``""``.  ``words`` name the option ``n``
    (:data:`cosim.studies.options.PYTHON_WORDS` by default).
    """
    if method != "sobol" or indices is None or not len(indices):
        return ""
    values, conf = indices["value"].astype(float), indices["conf"].astype(float)
    outside = indices[(values < -SOBOL_SLACK) | (values > 1 + SOBOL_SLACK)]
    wide = indices[conf > SOBOL_WIDE_CONF]
    if outside.empty and wide.empty:
        return ""
    said = []
    if not outside.empty:
        worst = outside.assign(off=(outside["value"] - outside["value"].clip(0, 1)).abs()).nlargest(3, "off")
        said.append("outside [0, 1]: " + ", ".join(f"{r.index} of {r.parameter} for {r.objective} = {r.value:.2f}"
                                                  for r in worst.itertuples()))
    if not wide.empty:
        said.append(f"95 % confidence half-widths up to {float(wide['conf'].max()):.2f}")
    return (f"Sobol indices with n = {n} are not reliable ({'; '.join(said)}): the sample is too small for "
            f"them; run again with a larger {words.get('n', 'n')} (each doubling halves the variance; e.g. "
            f"{words.get('n_is', 'n=')}{max(4 * n, 256)})")


def choose_objectives(spec: Any, asked: Sequence[str] | None) -> list[str]:
    """Objectives analysed: those asked, else those with a sense (or in ``optimize``), else all."""
    names = [o.name for o in spec.objectives]
    if asked:
        unknown = [a for a in asked if a.split("[")[0] not in names]
        if unknown:
            raise SensitivityError(f"not an objective of {spec.path}: {', '.join(unknown)}; "
                                   f"known: {', '.join(names)}")
        return list(asked)
    optimized = list((spec.raw.get("optimize") or {}).get("objectives") or {})
    return optimized or [o.name for o in spec.objectives if o.sense] or names


def sensitivity_space(spec: Any) -> Any:
    """The design space as the dimensions a sensitivity study samples (ranges need no step): what ``cosim
    sensitivity`` and ``cosim validate --for sensitivity`` check.  Raises SpecError for a constraint (the
    whole box is sampled), a bad range, or no parameters."""
    from cosim.spec.design import DesignSpace

    space = DesignSpace.dimensions_of(spec)
    if space.constraint is not None:
        raise SpecError([Problem(spec.path, "$.design.constraint", "a sensitivity study samples the whole box of "
                                 "the parameter ranges", "remove the constraint, or narrow the ranges instead")])
    if not space.dimensions:
        raise SpecError([Problem(spec.path, "$.design.parameters", "no design parameters to study",
                                 "add parameters with ranges or value lists")])
    return space


class SensitivityStudy:
    """A prepared study of the spec at ``spec_path``; :meth:`run` samples, runs, analyses and writes.

    Raises SpecError for a bad spec (or a design constraint: SALib's schemes
    need the whole box), SensitivityError for bad settings.
    """

    def __init__(self, spec_path: str | Path, out: str | Path, method: str = "sobol", n: int | None = None,
                 seed: int | None = None, objectives: Sequence[str] | None = None, **sweep_options: Any):
        """``sweep_options``: the study's options records or their fields, as :class:`cosim.studies.sweep.Sweep`
        takes them (``workers``, ``scheduler``, ``cluster``, ``timeout``, ``resume``, ``quiet`` ...)."""
        from cosim.studies.sweep import Sweep

        if method not in METHODS:
            raise SensitivityError(f"unknown method '{method}': use {' or '.join(METHODS)}")
        self.method, self.n = method, n or DEFAULT_N[method]
        if self.n < 2:
            raise SensitivityError(f"n must be at least 2, got {self.n}")
        self.out = Path(out)
        self.seed = DEFAULT_SEED if seed is None else seed  # fixed by default: a resume draws the same sample
        self.sample_space: SampleSpace  # drawn by space_of, which the Sweep below calls as it plans its points

        def space_of(spec: Any) -> SampleSpace:
            space = sensitivity_space(spec)
            self.problem = salib_problem(space)
            self.sample = draw(self.problem, method, self.n, self.seed)
            self.sample_space = SampleSpace(space, self.sample, f"{method} (SALib, n={self.n}, seed={self.seed})")
            return self.sample_space

        # the sensitivity design is the point source: its sample, run as a sweep of kind "sensitivity"
        self.sweep = Sweep(spec_path, out=self.out, design=space_of, kind="sensitivity", **sweep_options)
        self.objectives = choose_objectives(self.sweep.spec, objectives)
        previous = self.sweep.store.metadata() if self.sweep.where.resume else None
        if previous and previous.get("design_method") != self.sample_space.method:
            word = self.sweep.show.word
            raise SensitivityError(f"{self.out} holds the sample '{previous.get('design_method')}', not "
                                   f"'{self.sample_space.method}': resume with the same {word('method')}, "
                                   f"{word('n')} and {word('seed')}")

    def run(self) -> tuple[dict[str, int], "Any"]:
        """Run the sample (as a sweep) and write the indices; returns (counts by status, indices DataFrame)."""
        import pandas as pd

        counts = self.sweep.run_to_disk()
        table = self.sweep.store.table()
        indices = self.indices(table)
        indices.to_csv(self.out / TABLE_NAME, index=False)
        write_figure(indices, self.out / FIGURE_NAME, self.method)
        meta = self.sweep.store.metadata() or {}
        meta.update(sensitivity={
            "method": self.method, "n": self.n, "seed": self.seed, "samples": len(self.sample),
            "designs": len(self.sample_space), "objectives": self.objectives,
            "parameters": self.problem["names"], "bounds": self.problem["bounds"],
            "table": TABLE_NAME, "figure": FIGURE_NAME})
        self.sweep.store.write_metadata(meta)
        return counts, pd.DataFrame(indices)

    def indices(self, table: Any) -> Any:
        """The indices of every chosen objective from the results ``table`` (one row per design)."""
        import pandas as pd

        ok = table["status"] == "ok"
        rows = []
        for objective in self.objectives:
            columns = [objective] if objective in table.columns else \
                [c for c in table.columns if c.startswith(objective + "[")]
            for column in columns:
                by_id = dict(zip(table["point_id"], np.where(ok, table[column].astype(float), np.nan)))
                y = np.array([by_id.get(pid, np.nan) for pid in self.sample_space.row_ids], dtype=float)
                rows += index_rows(self.problem, self.method, column, analyse(self.problem, self.method,
                                                                              self.sample, y, self.seed))
        return pd.DataFrame(rows, columns=["objective", "parameter", "index", "value", "conf"])


def write_figure(indices: Any, path: Path, method: str, max_objectives: int = 6) -> Path:
    """Bar charts of the indices with their confidence half-widths as error bars, one panel per objective."""
    from cosim.analysis.plots import new_figure, save

    objectives = list(dict.fromkeys(indices["objective"]))[:max_objectives]
    first, second = INDICES[method]
    fig = new_figure(4.2 * max(len(objectives), 1), 3.8)
    for k, objective in enumerate(objectives):
        ax = fig.add_subplot(1, len(objectives), k + 1)
        part = indices[indices["objective"] == objective]
        names = list(dict.fromkeys(part["parameter"]))
        x = np.arange(len(names))
        for offset, index in ((-0.2, first), (0.2, second)):
            rows = part[part["index"] == index].set_index("parameter").loc[names]
            ax.bar(x + offset, rows["value"], width=0.4, label=index,
                   yerr=np.nan_to_num(rows["conf"].to_numpy(float)), capsize=3)
        ax.set_xticks(x, names, rotation=45, ha="right", fontsize=8)
        ax.set_title(objective, fontsize=10)
        ax.grid(axis="y", alpha=0.3)
        if k == 0:
            ax.legend(fontsize=8)
    fig.tight_layout()
    save(fig, path)
    return path

