"""Every problem of a spec at once: form (schema) and fit (units, ports, loops).

The schema check and the system check are separate layers
(:mod:`cosim.spec.loader`, :mod:`cosim.system.builder`).  To report the
problems of both layers in one go, entries that break the schema are set
aside and the rest of the spec still goes through the system check.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

from cosim.errors import SpecError, suggestions_bounded
from cosim.spec.loader import build_spec, load_spec, read_raw, schema_problems, spec_schema
from cosim.system.builder import System, build_system
from cosim.util.collector import collector_paused

# Where an error's JSON path points into one of these, the whole entry is set
# aside: (top-level key, depth of the entry).
_ENTRY_DEPTH = {"units": 2, "connections": 2, "record": 2, "objectives": 2}


def check_spec(path: str | Path, experiment: dict[str, Any] | None = None, variant: str | None = None,
               fixed: dict[str, Any] | None = None) -> System:
    """Load and check the spec (or SSP) at ``path``; returns the System when it is usable.

    ``experiment`` fields override the file's (see :func:`load_spec`); ``variant`` chooses an SSP's variant;
    ``fixed`` (``cosim sweep --set``) makes design parameters of one value (:func:`~cosim.spec.loader.read_raw`).
    Raises SpecError with every problem of form and fit found.
    """
    # millions of small acyclic objects for 10^5 connections (see cosim.util.collector); as many problems
    with collector_paused(), suggestions_bounded():
        try:
            return _check_spec(path, experiment, variant, fixed)
        except SpecError as exc:
            from cosim.ssp import is_ssp
            from cosim.ssp.locate import at_ssd_elements

            if not is_ssp(Path(path)):
                raise
            # an SSP run alone: its problems name SSD elements, not JSON paths of a spec the user never wrote
            raise SpecError(at_ssd_elements(exc.problems, path, variant)) from None


def _check_spec(path: str | Path, experiment: dict[str, Any] | None, variant: str | None,
                fixed: dict[str, Any] | None = None) -> System:
    try:
        return build_system(load_spec(path, experiment, variant, fixed))
    except SpecError as first:
        problems = list(first.problems)
        if any("malformed JSON" in p.message or p.path == "$" for p in problems):
            raise
        raw = read_raw(path, experiment, variant, fixed)
        if not schema_problems(raw, str(path)):
            raise  # the spec's form is fine: these already are all the problems
        sanitized, broken_units = _set_aside_broken_entries(raw, str(path))
        try:
            spec = build_spec(sanitized, Path(path))
            build_system(spec, frozenset(broken_units))
        except SpecError as second:
            known = {(p.path, p.message) for p in problems}
            problems.extend(p for p in second.problems if (p.path, p.message) not in known)
        except Exception:
            pass  # the sanitized spec is only a best effort for more messages
        raise SpecError(problems) from None


def check_design(system: System) -> None:
    """The checks ``cosim sweep`` makes of the design section: ranges and steps, repeated values, samplers, and
    the constraint's names and indices. Raises SpecError with the problem found.
    """
    from cosim.spec.design import DesignSpace

    DesignSpace.from_spec(system.spec).check()


def _set_aside_broken_entries(raw: Any, file: str) -> tuple[dict[str, Any], set[str]]:
    import jsonschema

    sanitized = copy.deepcopy(raw)
    broken_units: set[str] = set()
    removals: set[tuple[Any, ...]] = set()
    validator = jsonschema.Draft202012Validator(spec_schema())
    for error in validator.iter_errors(raw):
        parts = list(error.absolute_path)
        if not parts:
            continue
        top = parts[0]
        if top in _ENTRY_DEPTH and len(parts) >= _ENTRY_DEPTH[top]:
            removals.add(tuple(parts[: _ENTRY_DEPTH[top]]))
            if top == "units":
                broken_units.add(str(parts[1]))
        elif top == "design":
            removals.add(("design",))
        elif top == "experiment":
            sanitized["experiment"] = {"stop": 1.0, "step": 1.0}
    for entry in sorted(removals, key=lambda r: [str(x) for x in r], reverse=True):
        container = sanitized
        for key in entry[:-1]:
            container = container[key]
        last = entry[-1]
        if isinstance(container, list) and isinstance(last, int):
            container[last] = None  # keep indices stable for the paths of other problems
        elif isinstance(container, dict):
            container.pop(last, None)
    if "experiment" not in sanitized or not isinstance(sanitized.get("experiment"), dict):
        sanitized["experiment"] = {"stop": 1.0, "step": 1.0}
    if not sanitized.get("units"):
        sanitized["units"] = {}
    return sanitized, broken_units
