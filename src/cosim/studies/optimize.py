"""``cosim optimize``: multi-objective optimisation of a spec's design space, on the sweep's evaluate loop.

Optuna's ask-and-tell drives the search; cosim only translates:

- **Dimensions**: each design parameter of the spec (``design.parameters``)
  becomes an Optuna distribution: ``{min, max}`` a continuous float (an int
  range with int bounds), ``{min, max, step}`` a stepped one, ``{values}`` and
  ``{bool}`` categorical.  Array parameters give one dimension per element.
- **Objectives**: ``optimize.objectives`` (name -> sense), by default the
  spec's objectives that have a ``sense``.  Each must be one number per run.
- **Constraints**: the design ``constraint`` (a design violating it is never
  run: the optimiser is told the trial failed, no row is written, the budget
  is not charged) and the output constraints of ``optimize.constraints``:
  comparisons such as ``peak_tau_ratio <= 1``.  A comparison's violation is
  ``max(lhs - rhs)`` over the elements of an array (``rhs - lhs`` for >=);
  positive means infeasible.  Each violation is set on the trial
  (``Trial.set_constraint``), which NSGA-II, TPE, GP and surrogate take into account
  (random and qmc ignore it), and each row gets ``feasible``;
  infeasible rows stay in the table and are never on a Pareto front
  (``cosim pareto``, ``cosim report``).
- **Batches**: K designs are asked, evaluated in parallel through
  :class:`~cosim.parallel.point_stream.Evaluator` (isolation, timeouts, fault rows,
  as ``cosim sweep``), each row appended to the table as its point finishes,
  then told when the batch is done.
  A row not ``ok`` (failed, timeout, crashed) is told as a failed trial.
- **Table**: one row per evaluation in ``DIR/results.parquet``, with
  ``trial`` (Optuna's trial number), ``batch``, ``sampler`` and ``feasible``
  besides the sweep's columns; ``metadata.json`` has ``kind: optimization``.
- **Budget**: evaluations, i.e. rows.  A design asked again (samplers on
  stepped or categorical dimensions do that) is told the stored result and
  costs nothing; at most ``20 * budget`` trials are asked in all (``Stop.proposals_per_evaluation``).
- **Designs asked again**: once the optimum of a discrete space is found, TPE
  (and the others) propose evaluated designs batch after batch, each ask
  slower than the last.  So a batch that brings no design new to the run
  switches the search, with a one-line message, to the designs not yet
  evaluated in a random order (seeded; on a space of at most
  ``MAX_ENUMERATED`` designs: every stepped or categorical dimension), or to
  Optuna's random sampler on a space with a continuous dimension; their rows
  say ``random`` in ``sampler``.  The run stops, saying why, when every
  design of the space is evaluated or when a batch after the switch brings
  nothing new.  The switch happens at the same batch when a run is resumed.
- **Resume**: the table is the optimiser's memory.  With the same seed,
  sampler and batch, asking again from a fresh study proposes the same
  designs in the same order (Optuna's samplers are deterministic given their
  seed and the history told); designs already in the table are told their
  stored rows without running.  So an interrupted run resumed gives the same
  table as an uninterrupted one, and nothing is evaluated twice.  Should a
  sampler not replay (a proposal not in the table while stored rows are still
  unreplayed), the stored rows are added to the study as finished trials and
  the run goes on from there (the rest then differs from an uninterrupted run).
"""

from __future__ import annotations

import ast
import itertools
import math
import random
import re
import time
from contextlib import ExitStack
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence, TextIO

import numpy as np

from cosim.analysis.hypervolume import progress_hypervolume
from cosim.errors import OptimizeError, Problem, SpecError
from cosim.execution.point_row import PointRow
from cosim.studies.driver import now_utc, package_versions, results_writes
from cosim.studies.options import How, Show, Stop, Where, split_options
from cosim.studies.optuna_storage import Direction, default_study_name, open_storage_study, shown_url
from cosim.studies.progress import StatusLine
from cosim.studies.pruning import PRUNED, FrontKeeper, prune_settings, pruned_columns
from cosim.studies.runner import Study, metadata_of
from cosim.studies.sampler_names import SAMPLERS
from cosim.studies.storage_lock import locked_storage
from cosim.util import limits

if TYPE_CHECKING:  # optuna is imported where it is used: `import cosim.studies.optimize` stays cheap
    from optuna.distributions import BaseDistribution

DEFAULT_BUDGET = 200
DEFAULT_BATCH = {"nsga2": 20}  # a generation of NSGA-II is one batch; the others ask 8 at a time
# a told evaluation: (its objective values, its constraint violations, <= 0 where met)
Outcome = tuple[list[float], list[float]]
MAX_ENUMERATED = 200_000  # a discrete space up to this size is listed to find the designs not yet evaluated
_ELEMENT = re.compile(r"^(.*)\[(\d+)\]$")


# -- settings -----------------------------------------------------------------------


@dataclass
class OptimizeSettings:
    """What to optimise and how: from the spec's ``optimize`` section, overridden by the command line."""

    objectives: dict[str, Direction]  # column -> its sense
    constraints: list[str] = field(default_factory=list)
    sampler: str = "tpe"
    budget: int = DEFAULT_BUDGET
    batch: int = 8
    seed: int | None = None

    @classmethod
    def from_spec(cls, spec: Any, **overrides: Any) -> "OptimizeSettings":
        """Settings of ``spec`` (a Spec) with non-None ``overrides``; raises SpecError naming the field."""
        section = dict(spec.raw.get("optimize") or {})
        section.update({k: v for k, v in overrides.items() if v is not None})
        problems: list[Problem] = []
        objectives = section.get("objectives")
        known = {o.name: o for o in spec.objectives}
        if objectives is None:
            objectives = {o.name: o.sense for o in spec.objectives if o.sense}
            if len(objectives) == 0:
                problems.append(Problem(spec.path, "$.optimize.objectives", "no objective to optimise",
                                        "give objectives a 'sense', or list them: \"optimize\": "
                                        "{\"objectives\": {\"energy\": \"minimize\"}}"))
        for name in objectives:
            base = _ELEMENT.sub(r"\1", name)
            if base not in known:
                problems.append(Problem(spec.path, f"$.optimize.objectives.{name}", f"'{name}' is not an objective",
                                        "use names from 'objectives': " + ", ".join(known)))
        sampler = section.get("sampler", "tpe")
        if sampler not in SAMPLERS:
            problems.append(Problem(spec.path, "$.optimize.sampler", f"unknown sampler '{sampler}'",
                                    "use one of " + ", ".join(SAMPLERS)))
        for key in ("budget", "batch"):
            if key in section and (not isinstance(section[key], int) or section[key] < 1):
                problems.append(Problem(spec.path, f"$.optimize.{key}", f"{key} must be a whole number >= 1",
                                        f"write e.g. \"{key}\": 8"))
            elif key in section and section[key] > limits.limit("points"):  # 10^12 evaluations never end
                problems.append(Problem(spec.path, f"$.optimize.{key}", f"{key} {section[key]:,} is more than the "
                                        f"limit of {limits.limit('points'):,} design points",
                                        f"use a smaller {key}; {limits.raise_hint('points')}"))
        if problems:
            raise SpecError(problems)
        batch = section.get("batch", DEFAULT_BATCH.get(sampler, 8))
        if sampler == "nsga2" and batch < 2:
            raise SpecError([Problem(spec.path, "$.optimize.batch", "NSGA-II needs a batch (its population) of "
                                     "at least 2", "use a batch of 2 or more, e.g. 20")])
        return cls(objectives=dict(objectives), constraints=list(section.get("constraints", [])), sampler=sampler,
                   budget=int(section.get("budget", DEFAULT_BUDGET)), batch=int(batch), seed=section.get("seed"))


def optimization_space(spec: Any) -> Any:
    """The design space as the optimiser's dimensions (a range ``{min, max}`` is continuous and needs no step,
    with or without an ``optimize`` section); raises SpecError when a range is bad or nothing is to optimise."""
    from cosim.spec.design import DesignSpace

    space = DesignSpace.dimensions_of(spec)
    if not space.dimensions:
        raise SpecError([Problem(spec.path, "$.design.parameters", "nothing to optimise: no design parameters",
                                 "add parameters with ranges or value lists")])
    return space


def output_constraints(spec: Any, space: Any, texts: Sequence[str]) -> list["OutputConstraint"]:
    """The ``optimize.constraints`` of ``spec`` as OutputConstraints over its objectives and ``space``'s
    parameters; raises SpecError naming the constraint that does not parse or names unknown values."""
    from cosim.spec.design import expression_name

    names = {o.name for o in spec.objectives} | {expression_name(t) for t in space.targets} | set(space.targets)
    return [OutputConstraint(text, names | {expression_name(n) for n in names}, spec.path,
                             f"$.optimize.constraints[{i}]") for i, text in enumerate(texts)]


def check_optimization(system: Any) -> "OptimizeSettings":
    """What ``cosim optimize`` checks of a built system's spec before any evaluation (``cosim validate --for
    optimize``): the space, the settings of the ``optimize`` section (if any) and its constraints.

    Returns the settings; raises SpecError with the problem found."""
    space = optimization_space(system.spec)
    settings = OptimizeSettings.from_spec(system.spec)
    output_constraints(system.spec, space, settings.constraints)
    return settings


class OutputConstraint:
    """One comparison ``lhs OP rhs`` (OP one of < <= > >=) of objectives and parameters.

    :meth:`violation` is ``max(lhs - rhs)`` (``max(rhs - lhs)`` for > and >=)
    over array elements: <= 0 when met.  Raises SpecError on construction when
    the text is not one such comparison or names unknown values.
    """

    def __init__(self, text: str, names: set[str], file: str, path: str):
        from cosim.errors import ExpressionError
        from cosim.spec.expressions import Expression

        self.text = text
        fix = "write one comparison such as 'peak_tau_ratio <= 1' (names: objectives and parameters)"
        try:
            tree = ast.parse(text.strip(), mode="eval").body
        except SyntaxError as exc:
            raise SpecError([Problem(file, path, f"cannot parse '{text}': {exc.msg}", fix)]) from None
        if not (isinstance(tree, ast.Compare) and len(tree.ops) == 1
                and isinstance(tree.ops[0], (ast.Lt, ast.LtE, ast.Gt, ast.GtE))):
            raise SpecError([Problem(file, path, f"'{text}' is not one comparison with <, <=, > or >=", fix)])
        try:
            self.lhs = Expression(ast.unparse(tree.left))
            self.rhs = Expression(ast.unparse(tree.comparators[0]))
        except ExpressionError as exc:
            raise SpecError([Problem(file, path, str(exc), fix)]) from None
        self.sign = 1.0 if isinstance(tree.ops[0], (ast.Lt, ast.LtE)) else -1.0
        unknown = sorted((self.lhs.free_names | self.rhs.free_names) - names)
        if unknown:
            raise SpecError([Problem(file, path, f"unknown name(s) in '{text}': {', '.join(unknown)}",
                                     "known: " + ", ".join(sorted(names)))])

    def violation(self, values: Mapping[str, Any]) -> float:
        """How far ``values`` are from meeting the constraint (<= 0: met; NaN when it cannot be evaluated)."""
        with np.errstate(invalid="ignore"):
            diff = self.sign * (np.asarray(self.lhs.evaluate(values), dtype=float)
                                - np.asarray(self.rhs.evaluate(values), dtype=float))
        return float(np.max(diff)) if diff.size else float("nan")


def scope_of(columns: Mapping[str, Any]) -> dict[str, Any]:
    """Flat table columns as expression values: ``a[1]..a[n]`` also as the array ``a``; parameter names
    as the design constraint writes them (``traj.q[2]`` -> ``traj_q_2``)."""
    from cosim.spec.design import expression_name

    scope: dict[str, Any] = {}
    arrays: dict[str, dict[int, Any]] = {}
    for name, value in columns.items():
        m = _ELEMENT.match(name)
        if m:
            arrays.setdefault(m.group(1), {})[int(m.group(2))] = value
        scope[name] = value
        scope[expression_name(name)] = value
    for name, elements in arrays.items():
        array = [elements[i] for i in sorted(elements)]
        scope.setdefault(name, array)
        scope.setdefault(expression_name(name), array)
    return scope


# -- Optuna -------------------------------------------------------------------------


def distributions(space: Any) -> dict[str, BaseDistribution]:
    """One Optuna distribution per dimension of ``space`` (a DesignSpace), keyed by flat name."""
    from optuna.distributions import CategoricalDistribution, FloatDistribution, IntDistribution

    out: dict[str, BaseDistribution] = {}
    for name, dim in space.dimensions:
        if dim.lo is None:  # a value list or a boolean
            scalar = all(v is None or isinstance(v, (bool, int, float, str)) for v in dim.values)
            out[name] = CategoricalDistribution(list(dim.values) if scalar else list(range(len(dim.values))))
        elif dim.integer:
            out[name] = IntDistribution(int(dim.lo), int(dim.hi), step=int(dim.step or 1))
        elif dim.step is not None:
            steps = math.floor((dim.hi - dim.lo) / dim.step + 1e-9)
            out[name] = FloatDistribution(float(dim.lo), float(dim.lo + steps * dim.step), step=float(dim.step))
        else:
            out[name] = FloatDistribution(float(dim.lo), float(dim.hi))
    return out


def design_values(space: Any, params: Mapping[str, Any]) -> dict[str, Any]:
    """``{target: value}`` of a trial's ``params`` (categorical indices mapped back to their values)."""
    flat = []
    for name, dim in space.dimensions:
        value = params[name]
        if dim.lo is None and not all(v is None or isinstance(v, (bool, int, float, str)) for v in dim.values):
            value = dim.values[value]
        elif dim.step is not None and not dim.integer:
            value = round(value, 12)  # Optuna's stepped floats carry representation noise
        flat.append(value)
    return space.values_of(flat)


def finite_choices(dists: Mapping[str, Any]) -> dict[str, list[Any]] | None:
    """Every value of each distribution (Optuna's params), or None when one is continuous."""
    from optuna.distributions import CategoricalDistribution, FloatDistribution, IntDistribution

    out: dict[str, list[Any]] = {}
    for name, dist in dists.items():
        if isinstance(dist, CategoricalDistribution):
            out[name] = list(dist.choices)
        elif isinstance(dist, IntDistribution) and not dist.log:
            out[name] = list(range(dist.low, dist.high + 1, dist.step))
        elif isinstance(dist, FloatDistribution) and dist.step is not None:
            n = round((dist.high - dist.low) / dist.step)
            out[name] = [dist.low + k * dist.step for k in range(n + 1)]
        else:
            return None
    return out


def make_sampler(name: str, seed: int, batch: int, dists: Mapping[str, Any] | None = None) -> Any:
    """The Optuna sampler ``name`` (see SAMPLERS), seeded; ``dists``: the distributions every trial is asked with
    (the surrogate sampler needs them; the others learn them from the trials).  Raises OptimizeError when the
    sampler cannot be had."""
    import optuna

    if name == "tpe":
        # constant_liar: designs asked in one batch see each other as running, so a batch spreads out
        return optuna.samplers.TPESampler(seed=seed, multivariate=True, constant_liar=True)
    if name == "nsga2":
        return optuna.samplers.NSGAIISampler(seed=seed, population_size=batch)
    if name == "gp":
        try:
            import torch  # noqa: F401  (Optuna's GP sampler is written in PyTorch)
        except ImportError:
            raise OptimizeError("the gp sampler needs PyTorch, which is not installed: install cosim's gp extra "
                                "(pip install 'cosim[gp]', or pip install -e '.[gp]' in a source checkout; it "
                                "pins the CPU build of torch the project is tested with), or use tpe, nsga2, "
                                "random or qmc") from None
        return optuna.samplers.GPSampler(seed=seed)
    if name == "surrogate":
        from cosim.studies.surrogate_sampler import SurrogateSampler

        if dists is None:
            raise OptimizeError("the surrogate sampler needs the design space's distributions")
        return SurrogateSampler(dists, seed, batch)
    if name == "random":
        return optuna.samplers.RandomSampler(seed=seed)
    if name == "qmc":
        import warnings

        with warnings.catch_warnings():  # "experimental" since Optuna 3.0; we pin the interface by tests
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            return optuna.samplers.QMCSampler(qmc_type="sobol", scramble=True, seed=seed)
    raise OptimizeError(f"unknown sampler '{name}': use one of {', '.join(SAMPLERS)}")


# -- the driver -------------------------------------------------------------------


class Progress:
    """The optimisation's status line: evaluations done, not ok, front size, hypervolume, rate
    (see :class:`cosim.studies.progress.StatusLine`)."""

    def __init__(self, budget: int, stream: TextIO | None):
        self.budget = budget
        self._line = StatusLine(budget, stream)

    def show(self, done: int, not_ok: int, front: int, hv: float) -> None:
        rate = done / max(self._line.elapsed(), 1e-9)
        self._line.show(done, f"{done}/{self.budget} evaluations, {not_ok} not ok, front {front}, "
                              f"hypervolume {hv:.4f}, {rate:.1f}/s")

    def close(self) -> None:
        self._line.close()


class Optimiser:
    """The point source of an optimisation: Optuna's ask-and-tell over the spec's design space, batch by batch,
    until the budget of evaluations (``Stop.budget``) is in the table (see the module docstring).

    ``objectives`` ({name: 'minimize' | 'maximize'}), ``sampler``, ``batch`` and ``seed`` override the spec's
    ``optimize`` section; ``storage`` (an Optuna storage URL) also receives the trials, as ``study_name``.
    ``prune``: stop a design once a finished one strictly dominates its bound (docs/pruning.md); its trial is
    told to Optuna as PRUNED (see :meth:`_tell`).  Raises SpecError for a bad ``optimize`` section, OptimizeError
    when a resume would change the stored settings.
    """

    kind, command, error = "optimization", "optimize", OptimizeError
    to_resume, go_on, can_recompute = "continue that optimisation", "go on", False

    def __init__(self, objectives: Mapping[str, str] | None = None, sampler: str | None = None,
                 batch: int | None = None, seed: int | None = None, storage: str | None = None,
                 study_name: str | None = None):
        self.given = {"sampler": sampler, "batch": batch, "seed": seed, "objectives": objectives}
        self.storage, self._study_name = storage, study_name
        self._outcomes: dict[tuple[Any, Any], Outcome | None] = {}  # (point id, status) -> _outcome: each row read once
        self.stop_reason: str | None = None  # why the run ended before its budget (None: the budget was spent)
        self.sampler: Any = None  # the Optuna sampler, once the run started
        self.sampler_seconds = 0.0  # time spent in the sampler's ask, over the whole run
        self.trials_asked = 0
        self._storage_lock: ExitStack | None = None  # held from start to release_storage when there is a storage

    def system(self, spec_path: str | Path) -> Any:
        from cosim.system.validate import check_spec

        return check_spec(spec_path)

    def plan(self, study: Any) -> None:
        self.spec = study.spec
        self.space = optimization_space(self.spec)

    def bind(self, study: Any) -> None:
        """The settings: the stored run's when resuming (a resume replays it), the spec's, the ones given."""
        self.study, self.store, self.out, self.folder = study, study.store, study.out, study.folder
        self.quiet, self.progress_stream, self.timeout = study.show.quiet, study.show.progress, study.how.timeout
        stored = (study.folder.previous or {}).get("optimize", {})
        given = {"budget": study.stop.budget, **self.given}
        for key in ("sampler", "batch", "seed", "objectives"):  # a resume replays the stored run: these must not change
            if stored.get(key) is not None and given[key] is not None and given[key] != stored[key]:
                raise OptimizeError(f"{self.out} was optimised with {key} {stored[key]}; resume with the same "
                                    f"{key} (or leave it out), or start afresh in another {study.show.word('out')}")
            if given[key] is None and key in stored:
                given[key] = stored[key]
        self.settings = OptimizeSettings.from_spec(self.spec, **given)
        if self.settings.seed is None:  # a resume must replay the same proposals: the seed is chosen and kept
            self.settings.seed = random.SystemRandom().randrange(2**31)
        self.seed: int = self.settings.seed
        self.constraints = output_constraints(self.spec, self.space, self.settings.constraints)
        self.prune = prune_settings(study.system, list(self.settings.objectives.items()),
                                    self.settings.constraints) if study.how.prune else None
        self.keeper = FrontKeeper(self.prune) if self.prune is not None else None
        # the trials also in an Optuna storage, for Optuna's tools (see cosim.studies.optuna_storage)
        self.study_name = self._study_name or default_study_name(self.out)
        self._sampler_label = self.settings.sampler  # "random" once the search switched (see _switch)
        self.max_trials = study.stop.proposals_per_evaluation * self.settings.budget

    def start(self, study: Any) -> tuple[int, int]:
        """Read the stored rows (when resuming) and open the Optuna study; (budget, evaluations stored)."""
        import optuna

        optuna.logging.set_verbosity(optuna.logging.WARNING)
        self.stored = {r["point_id"]: r for r in self.store.read().to_dict("records")} if study.where.resume else {}
        s = self.settings
        self.dists = distributions(self.space)
        self.sampler = sampler = make_sampler(s.sampler, self.seed, s.batch, self.dists)
        if self.storage:
            # the study is this run's while it writes (cosim.studies.storage_lock): released by release_storage
            self._storage_lock = ExitStack()
            storage = self._storage_lock.enter_context(
                locked_storage(self.storage, self.study_name, self.out, study.show.words))
            self.optuna_study = open_storage_study(self.storage, self.study_name, list(s.objectives.values()),
                                                   list(s.objectives), sampler, study.where.resume, self.out,
                                                   words=study.show.words, storage=storage)
        else:
            self.optuna_study = optuna.create_study(directions=list(s.objectives.values()), sampler=sampler)
        return s.budget, len(self.stored)

    def release_storage(self) -> None:
        """Release the storage study's lock taken by :meth:`start` (nothing when none)."""
        lock, self._storage_lock = self._storage_lock, None
        if lock is not None:
            lock.close()

    def nothing_to_do(self, study: Any) -> str | None:
        return None  # the loop itself finds the budget spent (and a resume of a finished run tells its trials)

    def opening(self, study: Any, n_workers: int, link: str, board: Any) -> str:
        s = self.settings
        return (f"cosim optimize {self.spec.name}: {s.sampler}, budget {s.budget}, batch {s.batch}, "
                f"seed {s.seed}, {len(self.stored)} evaluations stored; {n_workers} worker(s); dashboard: "
                f"{link} ({board.describe()}); results: {self.out}")

    def evaluate(self, run: Any) -> None:
        from cosim.parallel.point_stream import Evaluator

        study = run.study
        with Evaluator(run.client, study.payload, run.n_workers, self.timeout, study=self.spec.name,
                       board=run.board, prune=self.keeper.order if self.keeper else None) as evaluator, \
                run.board.running():
            self._loop(self.optuna_study, self.dists, evaluator, self.stored)

    def evaluate_with(self, evaluator: Any) -> None:
        """Evaluate through ``evaluator`` instead of Dask (anything with Evaluator's ``evaluate``)."""
        self._loop(self.optuna_study, self.dists, evaluator, self.stored)

    def _say(self, text: str) -> None:
        self.study.say(text)

    # -- rows and trials ------------------------------------------------------------
    def _table_row(self, values: dict[str, Any], row: PointRow, trial: int, batch: int) -> dict[str, Any]:
        out: dict[str, Any] = {"point_id": row.point_id, **self.space.columns(values), **row.objectives,
                               "trial": trial, "batch": batch, "sampler": self._sampler_label}
        outcome = self._outcome({**out, "status": row.status})  # as before the tail is added
        out["feasible"] = outcome is not None and all(v <= 0 for v in outcome[1])
        if self.prune is not None:
            out.update(pruned_columns(row))
        out.update(row.tail())
        return out

    def _outcome(self, row: Mapping[str, Any]) -> Outcome | None:
        """(objective values, constraint violations) of a table row; None when it cannot be told."""
        key = (row.get("point_id"), row.get("status"))
        if key not in self._outcomes:
            self._outcomes[key] = self._compute_outcome(row)
        return self._outcomes[key]

    def _compute_outcome(self, row: Mapping[str, Any]) -> Outcome | None:
        if row.get("status") != "ok":
            return None
        values: list[float] = []
        for name in self.settings.objectives:
            value = row.get(name)
            if value is None or not np.isfinite(float(value)):
                return None
            values.append(float(value))
        scope = scope_of(row)
        violations = [c.violation(scope) for c in self.constraints]
        violations = [v if np.isfinite(v) else 1.0 for v in violations]  # cannot be evaluated: infeasible
        return values, violations

    def _tell(self, study: Any, trial: Any, row: Mapping[str, Any] | None) -> None:
        from optuna.trial import TrialState

        if row is None:  # no row: the evaluation failed
            study.tell(trial, state=TrialState.FAIL)
            return
        outcome = self._outcome(row)
        # which row of the table the trial is, in an Optuna storage's tools
        trial.set_user_attr("point_id", row.get("point_id"))
        trial.set_user_attr("status", row.get("status"))
        if row.get("status") == PRUNED:
            # Proven dominated, with no final values: Optuna's multi-objective samplers take a PRUNED trial without
            # values (NSGA-II and GP leave it out of their populations like a failed one; TPE ranks it below every
            # complete trial). Its bounds are optimistic, so telling them as values would mislead the sampler.
            study.tell(trial, state=TrialState.PRUNED)
            return
        if self.keeper is not None and outcome is not None:
            self.keeper.add(str(row.get("point_id")), row)
        if outcome is None:
            study.tell(trial, state=TrialState.FAIL)
            return
        values, violations = outcome
        for constraint, violation in zip(self.constraints, violations):
            trial.set_constraint(constraint.text, violation)
        study.tell(trial, values)

    # -- the run ------------------------------------------------------------------
    def _loop(self, study: Any, dists: dict[str, Any], evaluator: Any, stored: dict[str, dict]) -> None:
        s = self.settings
        rows: dict[str, dict] = {}  # point id -> table row, of every evaluation told in this run
        unreplayed = set(stored)
        progress = Progress(s.budget, self.progress_stream) if not self.quiet else None
        batch_index, trials_asked = 0, 0
        queue: list[dict[str, Any]] | None = None  # after the switch on a finite space: the designs not yet run
        switched = False
        while len(rows) < s.budget:
            if trials_asked >= self.max_trials:
                self._stop(f"stopped after {trials_asked} proposals: the sampler keeps proposing designs already "
                           f"evaluated or outside the design constraint ({len(rows)} evaluations)")
                break
            wanted = min(s.batch, s.budget - len(rows))
            if queue is not None:
                picked: list[dict[str, Any]] = []
                while queue and len(picked) < wanted:
                    params = queue.pop()  # stored rows added meanwhile (see _absorb) are not asked again
                    if self.space.point_id(design_values(self.space, params)) not in rows:
                        picked.append(params)
                if not picked:
                    self._stop(f"stopped: every design of the space is evaluated ({len(rows)} designs; the budget "
                               f"of {s.budget} is not spent)")
                    break
                wanted = len(picked)
                for params in picked:
                    study.enqueue_trial(params)
            clock = time.perf_counter()
            trials = [study.ask(dists) for _ in range(wanted)]
            self.sampler_seconds += time.perf_counter() - clock
            trials_asked += len(trials)
            self.trials_asked = trials_asked
            plan: list[tuple[Any, str | None]] = []  # per trial: its point id (None: outside the constraint)
            to_run: dict[str, dict[str, Any]] = {}
            known = len(rows)
            for trial in trials:
                values = design_values(self.space, trial.params)
                if not self.space.accepts(values):
                    plan.append((trial, None))
                    continue
                pid = self.space.point_id(values)
                plan.append((trial, pid))
                if pid in rows or pid in to_run:
                    continue  # asked again: told the same result
                if pid in stored:
                    rows[pid] = stored[pid]
                    unreplayed.discard(pid)
                else:
                    to_run[pid] = values
            if to_run and unreplayed:
                self._absorb(study, dists, stored, unreplayed, rows)
            if to_run:
                written: dict[str, dict] = {}

                def store(ran: list[PointRow]) -> None:  # each row as its point finishes: a stop keeps it
                    new = [self._table_row(to_run[r.point_id], r, self._trial_of(plan, r.point_id), batch_index)
                           for r in ran if r.point_id not in written]
                    with results_writes(self.out, self.study.show.words):
                        self.store.append(new)
                    written.update((r["point_id"], r) for r in new)

                if getattr(evaluator, "streams_rows", False):
                    ran = evaluator.evaluate(list(to_run.items()), on_rows=store)
                else:
                    ran = evaluator.evaluate(list(to_run.items()))
                store(ran)  # rows not given before
                rows.update((pid, written[pid]) for pid in to_run)
            for trial, pid in plan:
                self._tell(study, trial, rows.get(pid) if pid is not None else None)
            batch_index += 1
            if progress is not None:
                progress.show(len(rows), *self._front_summary(rows))
            if len(rows) == known and len(rows) < s.budget:  # the batch brought no design new to the run
                if switched:
                    self._stop(f"stopped: batch {batch_index} of random designs brought none not yet evaluated "
                               f"({len(rows)} evaluations; the budget of {s.budget} is not spent)")
                    break
                switched = True
                queue = self._switch(study, dists, rows, batch_index)
        if progress is not None:
            progress.close()

    def _stop(self, reason: str) -> None:
        self.stop_reason = reason
        per_trial = self.sampler_seconds / max(self.trials_asked, 1)
        self._say(f"{reason}; the sampler took {per_trial * 1e3:.1f} ms per proposal")

    def _switch(self, study: Any, dists: dict[str, Any], rows: dict[str, dict],
                batch_index: int) -> list[dict[str, Any]] | None:
        """Batch ``batch_index`` brought nothing new: go on with the designs not yet evaluated, in a seeded random
        order (returned, for a space of at most MAX_ENUMERATED designs), or with Optuna's random sampler (None)."""
        import optuna

        s = self.settings
        rng = random.Random(s.seed)
        study.sampler = optuna.samplers.RandomSampler(seed=s.seed)
        self._sampler_label = "random"
        choices = finite_choices(dists)
        if choices is None or math.prod(len(c) for c in choices.values()) > MAX_ENUMERATED:
            self._say(f"batch {batch_index} brought no design not yet evaluated ({s.sampler} proposes designs "
                      f"already evaluated): going on with random designs")
            return None
        names = list(choices)
        queue = []
        for combo in itertools.product(*(choices[n] for n in names)):
            params = dict(zip(names, combo))
            values = design_values(self.space, params)
            if self.space.accepts(values) and self.space.point_id(values) not in rows:
                queue.append(params)
        rng.shuffle(queue)
        self._say(f"batch {batch_index} brought no design not yet evaluated ({s.sampler} proposes designs already "
                  f"evaluated): going on with the {len(queue)} designs of the space not yet evaluated, in random "
                  "order")
        return queue

    @staticmethod
    def _trial_of(plan: list[tuple[Any, str | None]], pid: str) -> int:
        return next(trial.number for trial, p in plan if p == pid)

    def _absorb(self, study: Any, dists: dict[str, Any], stored: dict[str, dict], unreplayed: set[str],
                rows: dict[str, dict]) -> None:
        """The sampler did not replay the stored run: add the stored rows not yet told as finished trials."""
        import optuna

        self._say(f"note: the sampler did not replay the stored run; its {len(unreplayed)} other stored "
                  "evaluations are added as they are (the rest differs from an uninterrupted run)")
        for pid in sorted(unreplayed, key=lambda p: stored[p].get("trial", 0)):
            row = stored[pid]
            outcome = self._outcome(row)
            values, violations = outcome if outcome is not None else (None, [])
            params = {name: row[name] for name in dists if name in row}
            if len(params) != len(dists):
                continue  # a row without all dimensions (another design space): nothing to tell
            state = optuna.trial.TrialState.COMPLETE if values is not None else optuna.trial.TrialState.FAIL
            if row.get("status") == PRUNED:
                state = optuna.trial.TrialState.PRUNED
            trial = optuna.trial.create_trial(params=params, distributions=dists, values=values, state=state)
            for constraint, violation in zip(self.constraints, violations):
                trial.set_constraint(constraint.text, violation)
            study.add_trial(trial)
            rows[pid] = row
        unreplayed.clear()

    def _front_summary(self, rows: dict[str, dict]) -> tuple[int, int, float]:
        """(rows not ok, size of the feasible front, its hypervolume in the optimisation's fixed scale: the
        figure the report and the decision room show, never decreasing; see analysis.hypervolume)."""
        from cosim.analysis.pareto import pareto_mask

        not_ok = sum(r.get("status") != "ok" for r in rows.values())
        ordered = sorted(rows.values(), key=lambda r: r.get("trial", 0))
        good = [self._outcome(r) for r in ordered]
        kept = [(o[0], r.get("batch", 0)) for o, r in zip(good, ordered) if o is not None and all(x <= 0 for x in o[1])]
        if not kept:
            return not_ok, 0, 0.0
        values = np.array([v for v, _ in kept], dtype=float)
        senses = list(self.settings.objectives.values())
        signs = np.array([1.0 if s.startswith("min") else -1.0 for s in senses])
        front = pareto_mask(values * signs)
        hv = progress_hypervolume(values, senses, np.ones(len(values), dtype=bool), np.array([b for _, b in kept]))
        return not_ok, int(front.sum()), hv

    def metadata(self, study: Any, run: dict[str, Any]) -> dict[str, Any]:
        info = {**run, "budget": self.settings.budget}
        if self.storage:
            info["optuna_storage"] = {"url": shown_url(self.storage), "study_name": self.study_name}
        return metadata_of(study, info, optimize=asdict(self.settings), packages=package_versions("optuna"),
                           points=self.settings.budget, unit_checksums=study.folder.checksums,
                           data_file_checksums=study.folder.data_checksums,
                           design_method=f"optimize ({self.settings.sampler})")

    def order(self, study: Any) -> Any:
        # rows in trial order (the order an uninterrupted run asks for them; they are stored as they finish)
        stored = self.store.read()
        return list(stored.sort_values("trial", kind="stable")["point_id"]) if "trial" in stored.columns else None

    def missing(self, study: Any) -> str:
        return f"run it again with {study.show.word('resume')} to evaluate their designs again"


class Optimization(Study):
    """A prepared optimisation of the spec at ``spec_path`` into ``out``: an :class:`Optimiser` run by the study
    runner (:class:`cosim.studies.runner.Study`; see the module docstring).

    Options: the records ``where``, ``how``, ``stop``, ``show`` (:mod:`cosim.studies.options`), or their fields
    as keyword arguments (``resume``, ``workers``, ``scheduler``, ``cluster``, ``timeout``, ``budget``,
    ``quiet``, ``explore``, ``prune`` ...); the point source ``optimiser`` (an :class:`Optimiser`), or its
    options as keyword arguments: ``objectives``, ``sampler``, ``batch``, ``seed``, ``storage``,
    ``study_name``.  Raises SpecError for a bad spec, design space or ``optimize``
    section, OptimizeError when ``out`` cannot be used as asked.
    """

    OPTIMISER_OPTIONS = ("objectives", "sampler", "batch", "seed", "storage", "study_name")  # the optimiser's own

    def __init__(self, spec_path: str | Path, out: str | Path, where: Where | None = None, how: How | None = None,
                 stop: Stop | None = None, show: Show | None = None, optimiser: Optimiser | None = None,
                 **options: Any):
        own = {name: options.pop(name) for name in self.OPTIMISER_OPTIONS if name in options}
        if optimiser is not None and own:
            raise TypeError(f"give {', '.join(own)} to the Optimiser, not beside it")
        self.optimiser = optimiser or Optimiser(**own)
        super().__init__(spec_path, self.optimiser, split_options(where, how, stop, show, out=out, **options))

    @property
    def settings(self) -> OptimizeSettings:
        """What is optimised and how (the spec's ``optimize`` section with the options given, or the stored run's)."""
        return self.optimiser.settings

    @property
    def space(self) -> Any:
        """The design space as the optimiser's dimensions."""
        return self.optimiser.space

    @property
    def sampler(self) -> Any:
        """The Optuna sampler, once the run started (None before)."""
        return self.optimiser.sampler

    @property
    def stop_reason(self) -> str | None:
        """Why the run ended before its budget (None: the budget was spent)."""
        return self.optimiser.stop_reason

    @property
    def sampler_seconds(self) -> float:
        """Time spent in the sampler's ask, over the whole run."""
        return self.optimiser.sampler_seconds

    @property
    def trials_asked(self) -> int:
        """Trials asked of the sampler, over the whole run."""
        return self.optimiser.trials_asked

    def run(self, evaluator: Any = None) -> dict[str, int]:
        """Optimise until ``budget`` evaluations are in the table; returns the counts by status.

        Ctrl-C stops it; the rows so far stay and a resume continues.  Raises OptimizeError when no Dask workers
        are reachable, FolderInUse when another cosim process writes into the same folder, OutputError (exit
        2) when the folder cannot be written (read-only, full).  ``evaluator`` replaces the Dask evaluator
        (anything with Evaluator's ``evaluate``; benchmarks answer from a stored table with it; one whose
        ``streams_rows`` is true gets ``on_rows``, as :class:`~cosim.parallel.point_stream.Evaluator` does, and
        its rows are stored as their points finish, so a stop keeps every finished point of a batch).
        """
        if evaluator is None:
            return self.run_to_disk()
        with self.folder.locked():
            try:
                self.optimiser.start(self)
                self.folder.write_metadata(self.optimiser.metadata(self, self._run_info(now_utc(), "", 0)))
                self.optimiser.evaluate_with(evaluator)
                return self.finish()
            finally:
                self.optimiser.release_storage()

    def run_to_disk(self) -> dict[str, int]:
        """As the runner's, and the storage study's lock (taken when the optimiser starts) released after it."""
        try:
            return super().run_to_disk()
        finally:
            self.optimiser.release_storage()


def optimize(spec_path: str | Path, out: str | Path, **options: Any) -> "Any":
    """Optimise the spec's design space; returns the results table (one row per evaluation).

    Options as :class:`Optimization` (budget, sampler, batch, seed, resume,
    workers, scheduler, cluster, timeout, progress, quiet, explore: the decision room of ``out`` served while
    it runs).  Raises SpecError for a bad
    spec, OptimizeError when ``out`` or the cluster cannot be used.
    """
    run = Optimization(spec_path, out, **options)
    run.run()
    return run.store.table()
