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

The built-in kinds are declared the same way (:data:`BUILTIN_KINDS`, beside their
units: ``cosim.units.fmu.kind``, ``cosim.units.python.kind``, ``cosim.units.player``,
``cosim.units.connectors``) and loaded by name, first; the registry imports none of them.
"""

from __future__ import annotations

import importlib
import re
import threading
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any, Mapping

from cosim.errors import InternalError, UserError
from cosim.units.kind import UnitKind

ENTRY_POINT_GROUP = "cosim.unit_kinds"


@dataclass
class _Registry:
    kinds: dict[str, UnitKind] = field(default_factory=dict)
    builtins_loaded: bool = False
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
    _load_builtin_kinds()  # a built-in kind's name is taken even before a spec looked one up
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
    _load_builtin_kinds()
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


def _load_builtin_kinds() -> None:
    """Register the built-in kinds (:data:`BUILTIN_KINDS`), first and once per process."""
    with _REGISTRY.lock:
        if _REGISTRY.builtins_loaded:
            return
        for name, target in BUILTIN_KINDS.items():
            module, _, attribute = target.partition(":")
            _REGISTRY.kinds[name] = getattr(importlib.import_module(module), attribute)
        _REGISTRY.builtins_loaded = True  # only once all are in: a failed import is raised again next time


def _load_entry_points() -> None:
    """Register the kinds that installed distributions declare (once per process); the built-in kinds' own
    entry points are those already loaded."""
    with _REGISTRY.lock:
        if _REGISTRY.entry_points_loaded:
            return
        _REGISTRY.entry_points_loaded = True
        for entry in metadata.entry_points(group=ENTRY_POINT_GROUP):
            if entry.name in BUILTIN_KINDS and entry.value == BUILTIN_KINDS[entry.name]:
                continue
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

COMMON_FIELDS = ("parameters", "start", "ports", "feedthrough", "reuse")  # fields of every unit, whatever its kind
COMMON_OPTIONS = ("feedthrough", "reuse")  # the common fields kept in UnitSpec.options
_unit_schema_cache: dict[str, dict[str, Any]] = {}


def unit_schema(base: Mapping[str, Any]) -> dict[str, Any]:
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

# Each built-in kind sits beside its units and is declared as a plug-in's is, by the object's "module:attribute"
# (pyproject.toml's "cosim.unit_kinds" entry points name the same objects; tests/units/test_unit_kinds.py checks both
# lists agree). They are loaded by that name when first looked up, so the registry imports none of them.
BUILTIN_KINDS = {
    "fmu": "cosim.units.fmu.kind:KIND",
    "python": "cosim.units.python.kind:KIND",
    "player": "cosim.units.player:KIND",
    "connectors": "cosim.units.connectors:KIND",
}
