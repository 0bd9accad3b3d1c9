"""spec.json: read, check against the JSON Schema, and turn into frozen dataclasses.

:func:`load_spec` checks the *form* of a spec (JSON syntax, fields, types) and
reports every problem at once as a :class:`~cosim.errors.SpecError`.
Whether the units, ports and connections *fit together* needs the units
themselves and is checked by :func:`cosim.system.builder.build_system`.
Relative paths in a spec are relative to the spec's folder.
"""

from __future__ import annotations

import hashlib
import importlib.resources
import json
import logging
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

from cosim.errors import Problem, SpecError, did_you_mean, json_path
from cosim.master.loops import JACOBIANS as LOOP_JACOBIANS
from cosim.master.loops import METHODS as LOOP_METHODS
from cosim.master.loops import LoopSettings
from cosim.master.observers import REDUCERS
from cosim.master.registry import ALGORITHMS as MASTER_ALGORITHMS
from cosim.master.registry import DEFAULT_ALGORITHM
from cosim.units.kind import UnitSpec
from cosim.util import limits
from cosim.util.strict_json import read_spec_json  # strict JSON: no NaN, no key twice, bounded nesting

log = logging.getLogger("cosim.spec")
_NOTED_INITIALIZATION_ONLY: set[tuple[str, float]] = set()  # (file, start): a spec is often read twice


def _note_initialization_only(file: str, start: float) -> None:
    """Log once per spec and process that ``stop == start`` makes an initialization-only run (docs/spec.md)."""
    if (file, start) in _NOTED_INITIALIZATION_ONLY:
        return
    _NOTED_INITIALIZATION_ONLY.add((file, start))
    log.warning("%s: $.experiment: stop = start = %g s: an initialization-only run (the units are initialized, "
                "their outputs recorded once at t = %g s and the objectives reduced from that one sample; no step "
                "is taken); give a later 'stop' to simulate", file, start, start)

if TYPE_CHECKING:
    import jsonschema

# Shipped as package data beside this module, so an installed cosim finds it too.
SCHEMA_RESOURCE = ("cosim.spec", "spec.schema.json")
REDUCTIONS = tuple(REDUCERS)  # the names; the reductions themselves are in cosim.master.observers
ALGORITHMS = tuple(MASTER_ALGORITHMS)  # the names; the algorithms are in cosim.master.algorithms


@dataclass(frozen=True)
class ConnectionSpec:
    """``source`` ("unit.port") feeds ``target``; ``index`` is its place in the list."""

    source: str
    target: str
    index: int
    convert: bool = True  # False: pass values unchanged even when the two ends' units differ
    factor: float = 1.0  # the input receives factor * output + offset (Real only)
    offset: float = 0.0


@dataclass(frozen=True)
class ExperimentSpec:
    start: float
    stop: float
    step: float
    algorithm: str = DEFAULT_ALGORITHM
    stop_when: str | None = None
    early_stop: str = "ok"  # a unit ending the simulation before 'stop': "ok" (status ok) or "fail"
    loop_solver: LoopSettings = LoopSettings()  # how algebraic loops are solved (method, tolerance, max_iterations)
    # the adaptive algorithm's options (rtol, atol, min_step, max_step, base, restore), see cosim.master.adaptive
    adaptive: tuple[tuple[str, Any], ...] = ()
    coupled_model_exchange: bool = True  # connected model-exchange units integrated together (system/coupled_me)
    warm_start: float | None = None  # run once to this time, save, start every point there (execution/warm_start)
    kernel: str = "auto"  # what steps the system: "auto", "native" or "python" (system/kernel_choice.py)


@dataclass(frozen=True)
class ObjectiveSpec:
    """A reduction of a signal, or an expression of other objectives."""

    name: str
    signal: str | None = None
    reduce: str | None = None
    expr: str | None = None
    unit: str | None = None
    sense: str | None = None
    description: str = ""
    # "non-decreasing", "non-increasing" or "constant": the spec's word on the signal of a 'final' reduction,
    # which pruning may rely on (checked at every step while it prunes; cosim.spec.bounds)
    monotone: str | None = None


@dataclass(frozen=True)
class DesignParameterSpec:
    """How one parameter varies over the design space."""

    target: str
    min: Any = None
    max: Any = None
    step: Any = None
    values: tuple[Any, ...] | None = None
    is_bool: bool = False
    unit: str | None = None


@dataclass(frozen=True)
class DesignSpec:
    parameters: tuple[DesignParameterSpec, ...] = ()
    method: str = "grid"
    samples: int | None = None
    seed: int | None = None
    constraint: str | None = None


@dataclass(frozen=True)
class Spec:
    """A whole study; ``folder`` resolves relative paths, ``digest`` identifies it."""

    path: str
    folder: str
    name: str
    description: str
    units: tuple[UnitSpec, ...]
    connections: tuple[ConnectionSpec, ...]
    experiment: ExperimentSpec
    record: tuple[str, ...]
    objectives: tuple[ObjectiveSpec, ...]
    design: DesignSpec
    digest: str
    raw: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)

    def unit(self, name: str) -> UnitSpec:
        """The unit the spec declares as ``name``; raises KeyError when it declares none of that name."""
        for u in self.units:
            if u.name == name:
                return u
        raise KeyError(name)


def load_spec(path: str | Path, experiment: Mapping[str, Any] | None = None, variant: str | None = None,
              fixed: Mapping[str, Any] | None = None) -> Spec:
    """Read and check a spec: a spec.json, or an SSP (see :mod:`cosim.ssp`).

    ``experiment`` fields (e.g. ``{"step": 0.01}`` from the command line)
    override the file's.  Raises SpecError listing every problem of form
    found: unreadable file, malformed JSON (with line and column), values JSON
    does not allow (NaN, Infinity), keys given twice, too deep nesting, missing
    or unknown fields, wrong types, bad reduction or algorithm names, and every
    problem of an SSP the spec names.  ``variant`` chooses an SSP's variant (one of its SSDs) when ``path`` is
    an SSP.  ``fixed`` (``cosim sweep --set``): see :func:`read_raw`.
    """
    return spec_from_dict(read_raw(path, experiment, variant, fixed), path)


def read_raw(path: str | Path, experiment: Mapping[str, Any] | None = None, variant: str | None = None,
             fixed: Mapping[str, Any] | None = None) -> Any:
    """The content of a spec as parsed JSON, not yet checked.

    An SSP (``.ssp``, ``.ssd`` or a folder with SystemStructure.ssd) becomes
    the spec of its flattened system; an FMU the spec of it alone (:mod:`cosim.spec.fmu_alone`); a spec.json with ``"system"`` gets that
    SSP's units and connections merged under its own.  ``fixed`` (``{'unit.port': value}``, from
    ``cosim sweep --set``) makes each target a design parameter of that one value (in place of the design's
    own range for it, if any): every point runs with it, and the table has its column.  Raises SpecError.
    """
    from cosim.spec.fmu_alone import fmu_raw_spec, is_fmu
    from cosim.ssp import is_ssp, ssp_raw_spec

    path = Path(path)
    if is_ssp(path):
        return _with_fixed(ssp_raw_spec(path, experiment, variant), fixed)
    if is_fmu(path):  # an FMU alone: one unit, its default experiment, every output recorded
        return _with_fixed(fmu_raw_spec(path, experiment), fixed)
    return _with_fixed(_read_raw_json(path, experiment, variant), fixed)


def _with_fixed(raw: Any, fixed: Mapping[str, Any] | None) -> Any:
    """``raw`` with each of ``fixed`` as a one-value design parameter (see :func:`read_raw`)."""
    if not fixed or not isinstance(raw, dict):
        return raw
    design = dict(raw.get("design") or {}) if isinstance(raw.get("design") or {}, dict) else {}
    parameters = design.get("parameters") or {}
    parameters = dict(parameters) if isinstance(parameters, dict) else {}
    for target, value in fixed.items():
        parameters[target] = {"values": [value]}
    return {**raw, "design": {**design, "parameters": parameters}}


def _read_raw_json(path: Path, experiment: Mapping[str, Any] | None, variant: str | None) -> Any:
    """A spec.json's content (see :func:`read_raw`), its SSP system merged and ``experiment`` applied."""
    from cosim.ssp import merge_system

    if variant is not None:
        raise SpecError([Problem(str(path), "$.system", f"--variant {variant} chooses a variant of an SSP, and "
                                 f"{path.name} is a spec.json", "name the variant in the spec: \"system\": "
                                 f"{{\"ssp\": \"x.ssp\", \"variant\": \"{variant}\"}}")])
    raw = read_spec_json(path)
    if isinstance(raw, dict) and isinstance(raw.get("system"), (str, dict)):
        raw = merge_system(raw, path, experiment)
    if experiment and isinstance(raw, dict):
        raw["experiment"] = {**(raw.get("experiment") or {}), **experiment}
    return raw


def spec_from_dict(raw: Any, path: str | Path = "spec.json") -> Spec:
    """Check a parsed spec and build the Spec; relative paths resolve against ``path``'s folder.

    Raises SpecError with every problem of form found.
    """
    path = Path(path)
    problems = schema_problems(raw, str(path))
    if problems:
        raise SpecError(problems)
    return build_spec(raw, path)


def spec_schema() -> dict[str, Any]:
    """The JSON Schema of a spec: spec.schema.json (beside this module) with the fields of every registered unit kind."""
    from cosim.units.registry import unit_schema

    package, name = SCHEMA_RESOURCE
    schema: dict[str, Any] = json.loads(importlib.resources.files(package).joinpath(name).read_text(encoding="utf-8"))
    schema["$defs"]["unit"] = unit_schema(schema["$defs"]["unit"])
    algorithm = schema["$defs"]["experiment"]["properties"]["algorithm"]
    algorithm.update(enum=list(ALGORITHMS), default=DEFAULT_ALGORITHM)  # the file repeats them for editors
    method = schema["$defs"]["experiment"]["properties"]["loop_solver"]["properties"]["method"]
    method.update(enum=list(LOOP_METHODS), default=LoopSettings().method)
    jacobian = schema["$defs"]["experiment"]["properties"]["loop_solver"]["properties"]["jacobian"]
    jacobian.update(enum=list(LOOP_JACOBIANS), default=LoopSettings().jacobian)
    return schema


_schema = spec_schema  # the old private name, for callers not yet moved


def schema_problems(raw: Any, file: str) -> list[Problem]:
    """Every way ``raw`` breaks the JSON Schema or the field-level rules, as problems."""
    import jsonschema  # here, not at the top: a sweep's worker children unpickle specs without checking them

    schema = spec_schema()
    validator = jsonschema.Draft202012Validator(schema)
    problems: list[Problem] = []
    seen: set[tuple[str, str]] = set()
    checked, positions = _without_plain_connections(raw, schema)
    errors = list(validator.iter_errors(checked))
    for error in errors:  # paths into the shortened connections list point at the spec's own entries again
        path = error.path  # the top-level error's own path: its absolute path, and its context errors' base
        if positions is not None and len(path) >= 2 and path[0] == "connections" and isinstance(path[1], int):
            path[1] = positions[path[1]]
    for error in sorted(errors, key=lambda e: [str(p) for p in e.absolute_path]):
        for problem in _explain(error, schema, file):
            key = (problem.path, problem.message)
            if key not in seen:
                seen.add(key)
                problems.append(problem)
    if isinstance(raw, dict):
        problems.extend(_value_problems(raw, file, seen))
    return problems


def _without_plain_connections(raw: Any, schema: dict[str, Any]) -> tuple[Any, list[int] | None]:
    """``raw`` with the connections that plainly fit the schema left out, and the places of those kept.

    jsonschema takes about half a millisecond per connection; an SSP or a generated spec with 10^5
    element connections took minutes.  A plain connection (``from`` and ``to`` matching the schema's
    port pattern, ``convert`` a boolean, ``factor`` and ``offset`` numbers, nothing else) cannot
    break the schema, so only the others are handed to jsonschema.  Returns (raw, None) when
    nothing is left out.
    """
    connections = raw.get("connections") if isinstance(raw, dict) else None
    if not isinstance(connections, list) or len(connections) < 100:
        return raw, None
    port = re.compile(schema["$defs"]["port"]["pattern"])
    definition = schema["$defs"]["connection"]
    allowed = set(definition["properties"])
    required = set(definition["required"])

    def plain(c: Any) -> bool:
        if not isinstance(c, dict) or not required <= c.keys() <= allowed:
            return False
        if not all(isinstance(c[k], str) and port.search(c[k]) for k in ("from", "to")):
            return False
        if "convert" in c and not isinstance(c["convert"], bool):
            return False
        return all(isinstance(c[k], (int, float)) and not isinstance(c[k], bool) for k in ("factor", "offset")
                   if k in c)

    kept = [i for i, c in enumerate(connections) if not plain(c)]
    return {**raw, "connections": [connections[i] for i in kept]}, kept


def _value_problems(raw: dict[str, Any], file: str, seen: set[tuple[str, str]]) -> list[Problem]:
    """Rules the schema does not express well: reductions, experiment times."""
    problems = []
    objectives = raw.get("objectives")
    if isinstance(objectives, dict):
        for name, objective in objectives.items():
            if isinstance(objective, dict) and isinstance(objective.get("reduce"), str):
                reduce = objective["reduce"]
                if reduce not in REDUCTIONS:
                    problems.append(Problem(file, json_path(["objectives", name, "reduce"]),
                                            f"unknown reduction '{reduce}'.{did_you_mean(reduce, REDUCTIONS)}",
                                            "use one of: " + ", ".join(REDUCTIONS)))
            if isinstance(objective, dict) and "monotone" in objective and objective.get("reduce") != "final":
                problems.append(Problem(file, json_path(["objectives", name, "monotone"]),
                                        "'monotone' declares the signal of a 'final' reduction, and this objective "
                                        f"has {'an expression' if 'expr' in objective else 'reduce ' + repr(objective.get('reduce'))}",
                                        "remove 'monotone', or declare it on an objective with \"reduce\": \"final\""))
    units = raw.get("units")
    for name, unit in (units.items() if isinstance(units, dict) else ()):
        from cosim.units.registry import (
            misplaced_fields,  # a field of another kind (e.g. an FMU's tolerance on a player)
        )

        for key, owners in misplaced_fields(unit) if isinstance(unit, dict) else ():
            kinds = " or ".join(owners)
            problems.append(Problem(file, json_path(["units", name, key]), f"'{key}' applies to {kinds} units only",
                                    f"remove it, or make the unit a {kinds} unit"))
    experiment = raw.get("experiment")
    if isinstance(experiment, dict):
        # Any: the checks below find out what the file holds
        start: Any = experiment.get("start", 0)
        stop: Any = experiment.get("stop")
        step: Any = experiment.get("step")
        numbers = {k: v for k, v in (("start", start), ("stop", stop), ("step", step))
                   if isinstance(v, (int, float)) and not isinstance(v, bool)}
        for key, value in numbers.items():
            if not math.isfinite(value):  # only from the Python API: the JSON reader refuses these
                problems.append(Problem(file, f"$.experiment.{key}", f"{value} is not a finite number",
                                        "write a finite number"))
        if len(numbers) == 3 and all(math.isfinite(v) for v in numbers.values()):
            if stop < start:
                problems.append(Problem(file, "$.experiment.stop", f"stop ({stop}) must not be before start ({start})",
                                        "make 'stop' at least 'start' (equal: an initialization-only run)"))
            elif stop == start:
                _note_initialization_only(file, start)
            elif step > 0 and (stop - start) / step > limits.limit("steps"):
                problems.append(Problem(file, "$.experiment.step", f"(stop - start) / step is "
                                        f"{(stop - start) / step:.3g} steps, more than the limit of "
                                        f"{limits.limit('steps'):.3g} for one run",
                                        f"use a larger step or a shorter time span; {limits.raise_hint('steps')}"))
        problems.extend(_adaptive_problems(experiment, file))
        problems.extend(_warm_start_problems(experiment, numbers, file))
    return [p for p in problems if (p.path, p.message) not in seen]


def _adaptive_problems(experiment: dict[str, Any], file: str) -> list[Problem]:
    """``experiment.adaptive``: options that cannot work together, or given without the adaptive algorithm."""
    from cosim.master.adaptive import option_problems

    options = experiment.get("adaptive")
    if not isinstance(options, dict):
        return []
    if experiment.get("algorithm", DEFAULT_ALGORITHM) != "adaptive":
        return [Problem(file, "$.experiment.adaptive", "options of the adaptive algorithm, but 'algorithm' is "
                        f"'{experiment.get('algorithm', DEFAULT_ALGORITHM)}'",
                        "set \"algorithm\": \"adaptive\", or remove 'adaptive'")]
    return [Problem(file, json_path(["experiment", "adaptive", key] if key else ["experiment", "adaptive"]),
                    message, fix) for key, message, fix in option_problems(options)]


def _warm_start_problems(experiment: dict[str, Any], numbers: dict[str, Any], file: str) -> list[Problem]:
    """``experiment.warm_start``: inside (start, stop), on the step grid, with a fixed-step algorithm."""
    warm = experiment.get("warm_start")
    if not isinstance(warm, (int, float)) or isinstance(warm, bool) or len(numbers) < 3 or not math.isfinite(warm):
        return []  # a wrong type is the schema's to report; no span to check it against
    start, stop, step = numbers["start"], numbers["stop"], numbers["step"]
    path = "$.experiment.warm_start"
    if experiment.get("algorithm") == "adaptive":
        return [Problem(file, path, "a warm start needs a fixed communication step; 'algorithm' is 'adaptive'",
                        "use gauss-seidel or jacobi with warm_start, or remove warm_start")]
    if not start < warm < stop:
        return [Problem(file, path, f"{warm:g} is not between start ({start:g}) and stop ({stop:g})",
                        "choose a time after the start and before the stop")]
    ratio = (warm - start) / step if step > 0 else 0.0
    if step > 0 and abs(ratio - round(ratio)) > 1e-9 * max(1.0, abs(ratio)):
        below = start + math.floor(ratio) * step
        return [Problem(file, path, f"{warm:g} is not a communication point (start + k * step, step {step:g})",
                        f"use a multiple of the step, e.g. {below:g} or {below + step:g}")]
    return []


_ONE_OF_HINTS = {  # the unit's hint names the registered kinds (cosim.units.registry.one_kind_hint)
    "objective": ("an objective needs either 'signal' and 'reduce', or 'expr'",
                  "e.g. {\"signal\": \"energy.e_total\", \"reduce\": \"final\"} or {\"expr\": \"a / b\"}"),
    "design_parameter": ("a design parameter needs 'min' and 'max' (with 'step' for a grid), or 'values', "
                         "or 'bool'", "e.g. {\"min\": 0, \"max\": 1, \"step\": 0.1} or {\"values\": [1, 2]}"),
}


def _explain(error: jsonschema.ValidationError, schema: dict[str, Any], file: str) -> list[Problem]:
    path = json_path(error.absolute_path)
    validator = error.validator
    if validator == "additionalProperties":
        allowed = sorted(error.schema.get("properties", {}))
        extra = [k for k in error.instance if k not in error.schema.get("properties", {})]
        return [Problem(file, json_path([*error.absolute_path, k]),
                        f"unknown field '{k}'.{did_you_mean(k, allowed)}",
                        "remove it; allowed here: " + ", ".join(allowed)) for k in extra]
    if validator == "required":
        missing = error.message.split("'")[1] if "'" in error.message else error.message
        return [Problem(file, path, f"missing field '{missing}'", f"add '{missing}'")]
    if validator == "oneOf":
        kind = _def_name(error.schema, schema)
        if kind == "unit":
            from cosim.units.registry import one_kind_hint

            message, fix = one_kind_hint()
        else:
            message, fix = _ONE_OF_HINTS.get(kind, (error.message, ""))
        return [Problem(file, path, message, fix)]
    if validator == "type":
        expected = error.validator_value
        expected = " or ".join(expected) if isinstance(expected, list) else expected
        return [Problem(file, path, f"expected {expected}, got {type(error.instance).__name__} "
                                    f"{json.dumps(error.instance)[:60]}", f"write a {expected} here")]
    if validator == "enum":
        options = [str(o) for o in error.validator_value]
        return [Problem(file, path, f"'{error.instance}' is not allowed.{did_you_mean(str(error.instance), options)}",
                        "use one of: " + ", ".join(options))]
    if validator == "pattern":
        return [Problem(file, path, f"'{error.instance}' is not a valid name here",
                        _pattern_fix(error.absolute_path))]
    if validator == "propertyNames":
        return [Problem(file, path, f"'{error.instance}' is not a valid name",
                        "names start with a letter or '_' and contain only letters, digits and '_'")]
    if validator in ("exclusiveMinimum", "exclusiveMaximum", "minimum", "maximum"):
        bound = {"exclusiveMinimum": "above", "exclusiveMaximum": "below", "minimum": "at least",
                 "maximum": "at most"}[validator]
        return [Problem(file, path, f"{json.dumps(error.instance)} is out of range",
                        f"use a number {bound} {error.validator_value}")]
    if validator == "minProperties":
        return [Problem(file, path, "must not be empty", "add at least one entry")]
    return [Problem(file, path, error.message, "")]


def _pattern_fix(parts: Any) -> str:
    parts = [str(p) for p in parts]
    if parts and parts[0] in ("connections", "record", "objectives", "experiment", "design"):
        return "write 'unit.port' or 'unit.port[i]' (i counts from 1)"
    if parts and parts[0] == "units":
        return "write 'package.module:Class' or 'file.py:Class'"
    return "see specs/README.md"


def _def_name(sub_schema: dict[str, Any], schema: dict[str, Any]) -> str:
    definitions: dict[str, Any] = schema.get("$defs", {})
    for name, definition in definitions.items():
        if definition is sub_schema or definition == sub_schema:
            return name
    return ""


def _loop_settings(raw: dict[str, Any]) -> LoopSettings:
    """experiment.loop_solver (its form already checked) as LoopSettings; a missing field keeps its default."""
    default = LoopSettings()
    return LoopSettings(method=raw.get("method", default.method),
                        tolerance=float(raw.get("tolerance", default.tolerance)),
                        max_iterations=int(raw.get("max_iterations", default.max_iterations)),
                        jacobian=raw.get("jacobian", default.jacobian))


def build_spec(raw: dict[str, Any], path: Path) -> Spec:
    """The Spec of a parsed spec whose form is already checked (see :func:`spec_from_dict`).

    Relative paths resolve against ``path``'s folder.  Entries set to None
    (set aside by :mod:`cosim.system.validate`) are skipped.
    """
    from cosim.units.registry import COMMON_OPTIONS, kind_of

    folder = str(path.resolve().parent)
    units = []
    for name, u in raw["units"].items():
        kind = kind_of(u)  # the schema check made sure there is exactly one
        assert kind is not None
        options = {k: u[k] for k in (*kind.options, *COMMON_OPTIONS) if k in u}
        units.append(UnitSpec(name=name, kind=kind.name, source=u[kind.name], parameters=dict(u.get("parameters", {})),
                              start=dict(u.get("start", {})), ports=dict(u.get("ports", {})), options=options))
    # None marks an entry set aside by cosim.system.validate; indices stay those of the file
    connections = tuple(ConnectionSpec(c["from"], c["to"], i, c.get("convert", True), float(c.get("factor", 1.0)),
                                       float(c.get("offset", 0.0)))
                        for i, c in enumerate(raw.get("connections", [])) if c is not None)
    e = raw["experiment"]
    experiment = ExperimentSpec(start=float(e.get("start", 0.0)), stop=float(e["stop"]), step=float(e["step"]),
                                algorithm=e.get("algorithm", DEFAULT_ALGORITHM), stop_when=e.get("stop_when"),
                                early_stop=e.get("early_stop", "ok"), loop_solver=_loop_settings(e.get("loop_solver", {})),
                                adaptive=tuple(sorted((e.get("adaptive") or {}).items())),
                                coupled_model_exchange=e.get("coupled_model_exchange", True),
                                warm_start=float(e["warm_start"]) if e.get("warm_start") is not None else None,
                                kernel=e.get("kernel", "auto"))
    objectives = tuple(
        ObjectiveSpec(name=n, signal=o.get("signal"), reduce=o.get("reduce"), expr=o.get("expr"),
                      unit=o.get("unit"), sense=o.get("sense"), description=o.get("description", ""),
                      monotone=o.get("monotone"))
        for n, o in raw.get("objectives", {}).items())
    d = raw.get("design", {})
    design = DesignSpec(
        parameters=tuple(
            DesignParameterSpec(target=t, min=p.get("min"), max=p.get("max"), step=p.get("step"),
                                values=tuple(p["values"]) if "values" in p else None,
                                is_bool=bool(p.get("bool", False)), unit=p.get("unit"))
            for t, p in d.get("parameters", {}).items()),
        method=d.get("method", "grid"), samples=d.get("samples"), seed=d.get("seed"),
        constraint=d.get("constraint"))
    canonical = json.dumps(raw, sort_keys=True, separators=(",", ":"))
    return Spec(path=str(path), folder=folder, name=raw.get("name", path.stem),
                description=raw.get("description", ""), units=tuple(units), connections=connections,
                experiment=experiment, record=tuple(r for r in raw.get("record", []) if r is not None), objectives=objectives,
                design=design, digest=hashlib.sha256(canonical.encode()).hexdigest(), raw=raw)


_build = build_spec  # the old private name, for callers not yet moved
