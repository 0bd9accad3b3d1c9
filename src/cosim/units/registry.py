"""The registry of unit kinds: what may stand under ``units`` in a spec.

A *unit kind* is the word that says what a unit is made of: ``"fmu"``,
``"python"``, ``"player"`` are built in (a model-exchange FMU is an ``fmu`` unit
with ``"interface": "model-exchange"``); a plug-in adds its own (a user's signal
generator, say) without editing cosim.  A
:class:`UnitKind` owns everything the engine needs to know about its units:

- ``fields``: its JSON Schema fragment (the kind's key and its options), which
  the spec check merges into the schema of a unit;
- ``create(unit_spec, folder)``: the picklable
  :class:`~cosim.units.protocol.UnitType` (blueprint) of one unit, whose
  ``describe()`` gives the ports and ``instantiate()`` the live units.

Kinds come from :func:`register_unit_kind` (explicit) and from the
``cosim.unit_kinds`` entry point group, read once when a kind is first looked
up: a distribution declares ``[project.entry-points."cosim.unit_kinds"]
sine = "cosim_sine:KIND"`` and its kind is usable in any spec, in ``cosim``
commands and in sweep workers.  See docs/architecture.md for a worked example.

``builtin:NAME_fmiN`` FMU references (FMUs cosim builds from its own C
sources) are resolved here, by the ``fmu`` kind, not by the FMU unit.
"""

from __future__ import annotations

import re
import threading
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping

from cosim.errors import InternalError, Problem, UserError
from cosim.util.archive import MEMBER_SEPARATOR

if TYPE_CHECKING:
    from cosim.units.protocol import UnitType

ENTRY_POINT_GROUP = "cosim.unit_kinds"
BUILTIN_PREFIX = "builtin:"


@dataclass(frozen=True)
class UnitSpec:
    """One unit of a system as its spec (or SSP) declares it: what a unit kind's ``create`` is given."""

    name: str
    kind: str  # a registered unit kind: "fmu", "python", "player" or a plug-in's (cosim.units.registry)
    source: str
    parameters: Mapping[str, Any] = field(default_factory=dict)
    start: Mapping[str, Any] = field(default_factory=dict)
    ports: Mapping[str, str] = field(default_factory=dict)
    options: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class UnitKind:
    """One kind of unit (see the module docstring).

    ``name`` is the spec key naming the unit's source (``{"fmu": "a.fmu"}``);
    ``fields`` maps every field the kind adds to a unit (its key first) to its
    JSON Schema; ``create(unit_spec, folder)`` returns the unit's blueprint,
    resolving relative paths against ``folder`` (the spec's folder) and
    raising UserError (or FileNotFoundError, ImportError, ValueError) when the
    source cannot be used; ``example`` shows the key in use, for messages.
    ``replays`` marks a kind whose units stand in for a recorded unit (the
    ``player``): the parameters, start values, incoming connections and design
    parameters of such a unit are not used, since the recording already holds
    what they gave.
    """

    name: str
    fields: Mapping[str, Any]
    create: Callable[[UnitSpec, str], "UnitType"]
    example: str = ""
    description: str = ""
    replays: bool = False

    @property
    def options(self) -> tuple[str, ...]:
        """The fields besides the kind's key (e.g. a player's ``columns``)."""
        return tuple(k for k in self.fields if k != self.name)


@dataclass
class _Registry:
    kinds: dict[str, UnitKind] = field(default_factory=dict)
    entry_points_loaded: bool = False
    lock: threading.RLock = field(default_factory=threading.RLock)


_REGISTRY = _Registry()


def register_unit_kind(kind: UnitKind, replace: bool = False) -> UnitKind:
    """Make ``kind`` usable in specs of this process; returns it (usable as a decorator-free one-liner).

    Raises InternalError when another kind already has the name (unless
    ``replace``) or when one of its fields is a common unit field.
    """
    if not re.fullmatch(r"[a-z][a-z0-9_]*", kind.name) or kind.name not in kind.fields:
        raise InternalError(f"unit kind '{kind.name}': the name must be lower-case letters, digits and '_', "
                            "and be one of its fields (the key naming a unit's source)")
    clash = sorted(set(kind.fields) & set(COMMON_FIELDS))
    if clash:
        raise InternalError(f"unit kind '{kind.name}' redefines the common unit field(s) {', '.join(clash)}")
    with _REGISTRY.lock:
        if kind.name in _REGISTRY.kinds and not replace and _REGISTRY.kinds[kind.name] is not kind:
            raise InternalError(f"a unit kind '{kind.name}' is already registered")
        _REGISTRY.kinds[kind.name] = kind
    _unit_schema_cache.clear()
    return kind


def unregister_unit_kind(name: str) -> None:
    """Forget the kind ``name`` (for tests and interactive sessions); built-in kinds cannot be removed."""
    if name in BUILTIN_KINDS:
        raise InternalError(f"the built-in unit kind '{name}' cannot be removed")
    with _REGISTRY.lock:
        _REGISTRY.kinds.pop(name, None)
    _unit_schema_cache.clear()


def unit_kinds() -> dict[str, UnitKind]:
    """Every kind usable now, built-in first, then plug-ins (entry points and explicit registrations)."""
    _load_entry_points()
    with _REGISTRY.lock:
        return dict(_REGISTRY.kinds)


def unit_kind(name: str) -> UnitKind:
    """The kind called ``name``; raises UserError naming the kinds there are."""
    kinds = unit_kinds()
    if name not in kinds:
        raise UserError(f"unknown unit kind '{name}'; known kinds: {', '.join(kinds)}",
                        fix="install the plug-in that provides it, or use one of the known kinds")
    return kinds[name]


def kind_of(raw_unit: Mapping[str, Any]) -> UnitKind | None:
    """The kind of a unit entry of a spec (its one kind key), or None when it has none."""
    kinds = unit_kinds()
    return next((kinds[k] for k in raw_unit if k in kinds), None)


def misplaced_fields(raw_unit: Mapping[str, Any]) -> list[tuple[str, list[str]]]:
    """The fields of a spec's unit entry that only other kinds take: ``[(field, [those kinds]), ...]``.

    Empty for a unit without exactly one kind key (the schema check reports that).
    """
    kinds = unit_kinds()
    own = [kinds[k] for k in raw_unit if k in kinds]
    if len(own) != 1:
        return []
    out = []
    for key in raw_unit:
        if key in own[0].fields or key in COMMON_FIELDS:
            continue
        owners = [k.name for k in kinds.values() if key in k.options]
        if owners:
            out.append((key, owners))
    return out


def replaying_units(units: Any) -> set[str]:
    """The names of the units (UnitSpecs) whose kind replays a recorded unit (see :attr:`UnitKind.replays`)."""
    kinds = unit_kinds()
    return {u.name for u in units if u.kind in kinds and kinds[u.kind].replays}


def _load_entry_points() -> None:
    """Register the kinds that installed distributions declare (once per process)."""
    with _REGISTRY.lock:
        if _REGISTRY.entry_points_loaded:
            return
        _REGISTRY.entry_points_loaded = True
        for entry in metadata.entry_points(group=ENTRY_POINT_GROUP):
            try:
                kind = entry.load()
                kind = kind() if callable(kind) and not isinstance(kind, UnitKind) else kind
            except Exception as exc:  # a broken plug-in must not break every spec
                raise UserError(f"the unit-kind plug-in '{entry.name}' ({entry.value}) cannot be loaded: "
                                f"{type(exc).__name__}: {exc}",
                                fix="fix or uninstall the distribution that declares it") from None
            if not isinstance(kind, UnitKind) or kind.name != entry.name:
                raise UserError(f"the entry point '{entry.name}' of group {ENTRY_POINT_GROUP} gives "
                                f"{kind!r}, not a UnitKind named '{entry.name}'",
                                fix="point the entry point at a UnitKind object with the same name")
            if entry.name not in _REGISTRY.kinds:  # an explicit registration wins
                register_unit_kind(kind)


# -- the schema of a unit ------------------------------------------------------------------

COMMON_FIELDS = ("parameters", "start", "ports", "feedthrough")  # fields of every unit, whatever its kind
COMMON_OPTIONS = ("feedthrough",)  # the common fields kept in UnitSpec.options
_unit_schema_cache: dict[str, dict] = {}


def unit_schema(base: Mapping[str, Any]) -> dict:
    """The JSON Schema of one unit: ``base`` (the spec schema's ``$defs.unit``) with every kind's fields.

    A unit has exactly one kind key; the fields of all kinds are known names
    (an unknown field is reported as such, with a suggestion).
    """
    kinds = unit_kinds()
    key = ",".join(kinds)
    if key not in _unit_schema_cache:
        schema = dict(base)
        properties = {k: v for k, v in base.get("properties", {}).items() if k in COMMON_FIELDS}
        for kind in kinds.values():
            for name, fragment in kind.fields.items():
                properties.setdefault(name, dict(fragment))
        schema["properties"] = properties
        schema["oneOf"] = [{"required": [name]} for name in kinds]
        _unit_schema_cache[key] = schema
    return _unit_schema_cache[key]


def one_kind_hint() -> tuple[str, str]:
    """(message, fix) for a unit without exactly one kind key, naming every kind."""
    kinds = list(unit_kinds().values())
    names = [f"'{k.name}'" for k in kinds]
    listed = ", ".join(names[:-1]) + f" or {names[-1]}" if len(names) > 1 else names[0]
    examples = [k.example for k in kinds if k.example]
    return (f"a unit needs exactly one of {listed}",
            "give one: " + ", ".join(examples[:-1]) + (f" or {examples[-1]}" if len(examples) > 1 else
                                                       (examples[0] if examples else "")))


# -- the built-in kinds ---------------------------------------------------------------------


def _relative(source: str, folder: str) -> Path:
    if MEMBER_SEPARATOR in source:  # a table inside an SSP archive (an SSP's CSV component), as resolve_fmu_path
        from cosim.util.archive import member_file

        return member_file(source)
    path = Path(source)
    return path if path.is_absolute() else Path(folder) / path


def resolve_fmu_path(reference: str, base_dir: str | Path | None = None) -> Path:
    """The file an FMU reference in a spec points to.

    ``builtin:NAME_fmiN`` names an FMU cosim ships as C source (built on first
    use, see :mod:`cosim.fmus.build`); ``archive.ssp!/resources/m.fmu`` a file inside
    an SSP archive; anything else is a path, relative to ``base_dir``.  Raises
    FileNotFoundError for an unknown builtin name and FmuProblems when a
    built-in FMU cannot be built (e.g. no C compiler).
    """
    if reference.startswith(BUILTIN_PREFIX):
        return _built_in_fmu(reference)
    if "!/" in reference:  # a member of an SSP archive (cosim.ssp names FMUs so)
        from cosim.util.archive import member_file

        return member_file(reference)
    path = Path(reference)
    if not path.is_absolute() and base_dir is not None:
        path = Path(base_dir) / path
    return path


def _built_in_fmu(reference: str) -> Path:
    from cosim.fmus.build import FmuBuildError, available_models, ensure_built  # local: compiling only when asked
    from cosim.units.fmu.description import FmuProblems

    stem = reference[len(BUILTIN_PREFIX):]
    m = re.match(r"^(?P<name>.+)_fmi(?P<version>[23])$", stem)
    if not m or m.group("name") not in available_models():
        names = ", ".join(f"builtin:{n}_fmi3" for n in sorted(available_models()))
        raise FileNotFoundError(f"no built-in FMU '{stem}'; available: {names} (or _fmi2)")
    try:
        return Path(ensure_built(m.group("name"), int(m.group("version"))))
    except FmuBuildError as exc:  # no compiler, or our C sources do not build here
        raise FmuProblems(reference, [Problem(reference, "", f"cannot build the built-in FMU: {exc}",
                                              "install gcc (apt-get install gcc), or set CC to a C compiler")]) \
            from None


def _create_fmu(spec: UnitSpec, folder: str) -> "UnitType":
    from cosim.units.fmu.description import FmuUnitType

    # whole-number parameters may be structural parameters that size FMI 3.0 arrays: the description needs them
    structural = {spec.ports.get(k, k): v for k, v in spec.parameters.items()
                  if isinstance(v, int) and not isinstance(v, bool)}
    settings = None
    if "tolerance" in spec.options or "max_step" in spec.options:  # the model-exchange solver (units/model_exchange)
        from cosim.units.fmu.model_exchange import SolverSettings

        settings = SolverSettings(**{k: spec.options[k] for k in ("tolerance", "max_step") if k in spec.options})
    return FmuUnitType(resolve_fmu_path(spec.source, folder), reference=spec.source, structural=structural,
                       interface=spec.options.get("interface"), solver_settings=settings)


def _create_python(spec: UnitSpec, folder: str) -> "UnitType":
    from cosim.units.python.unit import PythonUnitType

    return PythonUnitType(spec.source, folder)


def _create_player(spec: UnitSpec, folder: str) -> "UnitType":
    from cosim.units.player import PlayerUnitType

    o = spec.options
    return PlayerUnitType(_relative(spec.source, folder), o.get("columns"), o.get("interpolation", "linear"),
                          o.get("extrapolation", "hold"), o.get("units"), unit_name=spec.name,
                          all_real=o.get("all_real", False))


def _create_connectors(spec: UnitSpec, folder: str) -> "UnitType":
    from cosim.units.connectors import SystemConnectorsType

    return SystemConnectorsType(spec.source, spec.options.get("inputs"), spec.parameters)


FMU = UnitKind("fmu", {
    "fmu": {"type": "string", "description": "Path to an .fmu (relative to the spec's folder) or "
                                             "'builtin:NAME_fmi3' / 'builtin:NAME_fmi2'."},
    "interface": {"enum": ["co-simulation", "model-exchange"],
                  "description": "fmu only: how the FMU runs. Default: co-simulation when the FMU offers it, else "
                                 "model exchange (integrated by cosim with CVode inside each step)."},
    "tolerance": {"type": "number", "exclusiveMinimum": 0, "exclusiveMaximum": 1,
                  "description": "fmu, model exchange only: relative tolerance of the solver (CVode; absolute "
                                 "tolerance = tolerance x nominal). Default 1e-6."},
    "max_step": {"type": "number", "exclusiveMinimum": 0,
                 "description": "fmu, model exchange only: largest internal solver step in seconds. Default: the "
                                "communication step."},
    "record_events": {"type": "boolean",
                      "description": "fmu, model exchange only: the traces get two extra rows at every event the "
                                     "solver handles inside a step (time, state and step events): the unit's "
                                     "recorded signals just before the event and just after it, the other "
                                     "signals as at the last row (default false). Traces only; objectives reduce "
                                     "the communication points."},
    "coupled_model_exchange": {"type": "boolean",
                               "description": "fmu, model exchange only: false integrates this unit alone inside "
                                              "each communication step even when it is connected to other "
                                              "model-exchange units (default true: integrated together with "
                                              "them by one solver)."},
}, _create_fmu, example='"fmu": "model.fmu"',
    description="an FMI 2.0 or 3.0 FMU: co-simulation, or model exchange integrated by cosim")

PYTHON = UnitKind("python", {
    "python": {"type": "string", "pattern": "^[^:]+:[A-Za-z_][A-Za-z0-9_.]*$",
               "description": "'package.module:Class' or 'file.py:Class'."},
}, _create_python, example='"python": "module:Class"', description="a PythonUnit subclass")

PLAYER = UnitKind("player", {
    "player": {"type": "string", "description": "A recorded table (.parquet or .csv, as written by 'cosim run "
                                                "--out') played back as outputs."},
    "columns": {"type": "array", "items": {"type": "string"},
                "description": "player only: the columns to play (default: all but 'time')."},
    "interpolation": {"enum": ["linear", "hold", "nearest"],
                      "description": "player only: how values between samples are found."},
    "extrapolation": {"enum": ["hold", "error"],
                      "description": "player only: beyond the recorded time range, hold the end values or fail."},
    "units": {"type": "object", "additionalProperties": {"type": "string"},
              "description": "player only: unit of measure of played columns or arrays, e.g. {\"speed\": \"rpm\"}."},
    "all_real": {"type": "boolean",
                 "description": "player only: play every column as Real (interpolated), whatever its recorded type "
                                "(a CSV column of whole numbers reads as Integer, held). An SSP's table component "
                                "is played so."},
}, _create_player, example='"player": "traces.parquet"', description="recorded signals played back", replays=True)

CONNECTORS = UnitKind("connectors", {
    "connectors": {"type": "string", "description": "The system whose connectors the unit holds (an SSP's "
                                                   "system, e.g. 'default.sub'): its inputs hold what is connected "
                                                   "to them, its parameters constants; it computes nothing. Written "
                                                   "by cosim for an SSP's system connectors."},
    "inputs": {"type": "object", "additionalProperties": {"type": "string"},
               "description": "connectors only: the connectors fed by a connection, each with its unit of measure "
                              "('' for none)."},
    "feeds": {"type": "object",
              "additionalProperties": {"type": "array", "items": {
                  "type": "object", "required": ["to"], "additionalProperties": False,
                  "properties": {"to": {"type": "string"}, "factor": {"type": "number"},
                                 "offset": {"type": "number"}}}},
              "description": "connectors only: the unit parameters each parameter connector sets (an SSP's "
                             "parameter connections): a value given to the connector by a design parameter or "
                             "--set sets each 'to' to factor x value + offset (default 1 and 0)."},
}, _create_connectors, example='"connectors": "default.sub"',
    description="the connectors of an SSP's system, as signals of their own")

BUILTIN_KINDS = {kind.name: kind for kind in (FMU, PYTHON, PLAYER, CONNECTORS)}
_REGISTRY.kinds.update(BUILTIN_KINDS)
