"""A starter spec for a model someone hands over (``cosim new spec.json --from model.fmu|system.ssp``).

:func:`starter_spec` turns the checked system of an FMU run alone, or of an SSP, into the content of a spec.json
that ``cosim validate`` accepts and ``cosim run`` / ``cosim sweep`` run as it stands: the model (the FMU as a
unit, or the SSP as the ``system``), the experiment the model gives, every port recorded, one example objective
(the final value of the first numeric output) and one example design parameter (three values around the first
numeric parameter's value, inside its declared range).  JSON holds no comments, so what each part is for is
said by :func:`explanation`, which the command prints.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.system.builder import System
from cosim.units.protocol import Variable

NUMERIC = ("Real", "Integer")


@dataclass(frozen=True)
class Starter:
    """A starter spec's content and what was chosen for it (for the printed explanation)."""

    content: dict[str, Any]
    objective: str | None  # 'name: signal' of the example objective, None when the model has no numeric output
    design: str | None  # 'unit.param: values' of the example design parameter, None when it has no parameter
    recorded: int


def starter_spec(system: System, source: Path, spec_path: Path, ssp: bool, variant: str | None = None) -> Starter:
    """The starter spec of ``system`` (read from ``source``, an FMU run alone or an SSP when ``ssp``) to be
    written at ``spec_path``: paths are relative to the spec's folder, so the two may move together."""
    where = _relative(source, spec_path.parent)
    content: dict[str, Any] = {"name": _name(spec_path.stem),
                               "description": f"starter spec of {source.name}, written by cosim new"}
    if ssp:
        content["system"] = {"ssp": where, "variant": variant} if variant else where
    else:
        [unit] = system.units
        content["units"] = {unit: {"fmu": where}}
    experiment = system.spec.experiment
    content["experiment"] = {"start": experiment.start, "stop": experiment.stop, "step": experiment.step,
                             "algorithm": experiment.algorithm}
    record = _ports(system)
    content["record"] = record
    objective = _example_objective(system)
    if objective is not None:
        name, signal = objective
        entry: dict[str, Any] = {"signal": signal, "reduce": "final"}
        measure = system.signal(signal).variable.unit
        if measure:
            entry["unit"] = measure
        content["objectives"] = {name: entry}
    design = _example_design(system)
    if design is not None:
        target, values = design
        content["design"] = {"parameters": {target: {"values": values}}, "method": "grid"}
    return Starter(content, f"{objective[0]}: final value of {objective[1]}" if objective else None,
                   f"{design[0]} in {design[1]}" if design else None, len(record))


def explanation(starter: Starter, spec_path: Path) -> str:
    """What the command prints after writing the starter spec: each part and what to do next."""
    content = starter.content
    model = f"the SSP {content['system']!r} ('system')" if "system" in content else \
        f"the FMU as unit '{next(iter(content['units']))}' ('units')"
    experiment = content["experiment"]
    lines = [f"wrote {spec_path}: a starter spec of {model}",
             f"  experiment: {experiment['start']:g} .. {experiment['stop']:g} s, step {experiment['step']:g} s, "
             f"{experiment['algorithm']} (the model's own; change 'experiment')",
             f"  record: {starter.recorded} port(s), every input and output (what cosim run --out writes)"]
    lines.append(f"  objectives: one example, {starter.objective} (add your own: docs/spec.md#objectives)"
                 if starter.objective else "  objectives: none (the model has no numeric output)")
    lines.append(f"  design: one example parameter, {starter.design} (the range to sweep: docs/spec.md#design-space)"
                 if starter.design else "  design: none (the model has no numeric parameter to vary)")
    lines += ["next:", f"  cosim validate {spec_path}", f"  cosim run {spec_path} --out traces.csv",
              f"  cosim sweep {spec_path}" + ("" if starter.design else "   (after adding a design parameter)")]
    return "\n".join(lines)


def _relative(path: Path, folder: Path) -> str:
    """``path`` relative to ``folder`` when they share a root (else absolute), with forward slashes."""
    try:
        return Path(os.path.relpath(path.resolve(), folder.resolve())).as_posix()
    except ValueError:  # another drive (Windows)
        return path.resolve().as_posix()


def _name(stem: str) -> str:
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", stem).strip("._-")
    return name or "study"


def _recordable(variable: Variable, connectors: bool) -> bool:
    if variable.type == "Clock":
        return False  # FMI 3.0 clocks tick, they hold no value to record
    if connectors:  # a system connector of an SSP: every one is a signal (inputs carry, parameters hold)
        return variable.causality in ("input", "output", "parameter", "calculatedParameter")
    return variable.causality in ("input", "output")


def _ports(system: System) -> list[str]:
    """Every input and output of every unit (and every system connector of an SSP), as 'unit.port'."""
    # a system connector carrying a component's output unchanged stands for that output (listed already)
    unchanged = {(c.target.unit, c.target.variable.name) for c in system.connections if not c.transforms
                 and system.units[c.target.unit].spec.kind == "connectors"}
    record = []
    for name, unit in system.units.items():
        connectors = unit.spec.kind == "connectors"
        record += [f"{name}.{v.name}" for v in unit.description.variables
                   if _recordable(v, connectors) and (name, v.name) not in unchanged]
    return record


def _example_objective(system: System) -> tuple[str, str] | None:
    """(objective name, signal) of a final value: what an SSP's outermost system hands out (the output its
    output connector carries), else the first numeric output of the last unit stepped (a chain's end), an
    array's first element."""
    exported = sorted((c.target.unit.count("."), i) for i, c in enumerate(system.connections)
                      if system.units[c.target.unit].spec.kind == "connectors"
                      and system.units[c.source.unit].spec.kind != "connectors" and c.source.variable.type in NUMERIC)
    outputs = [(system.connections[i].source.unit, system.connections[i].source.variable) for _, i in exported]
    for name in reversed(system.order):
        if system.units[name].spec.kind != "connectors":
            outputs += [(name, v) for v in system.units[name].description.variables
                        if v.causality == "output" and v.type in NUMERIC]
    if not outputs:
        return None
    name, v = outputs[0]
    objective = re.sub(r"\W+", "_", v.name, flags=re.ASCII).strip("_") + "_final"
    return (objective if objective[0].isalpha() else f"y_{objective}"), f"{name}.{v.name}" + ("[1]" if v.is_array else "")


def _example_design(system: System) -> tuple[str, list[Any]] | None:
    """('unit.param', values) of a parameter to sweep: an SSP's parameter connector feeding FMU parameters
    first (the knob the tool's users turn), else the first scalar numeric parameter no such connector sets."""
    fed: set[str] = set()
    for name, unit in system.units.items():
        for targets in (unit.spec.options.get("feeds") or {}).values():
            fed.update(t["to"] for t in targets)
    candidates = []
    for name, unit in system.units.items():
        feeds = unit.spec.options.get("feeds") or {}
        for v in unit.description.variables:
            target = f"{name}.{v.name}" + ("[1]" if v.is_array else "")  # an array: its first element
            if v.causality != "parameter" or v.type not in NUMERIC or target in fed:
                continue
            if unit.spec.kind == "connectors" and v.name not in feeds:
                continue  # a connector that sets nothing: a design value would change no unit
            base = unit.spec.parameters.get(v.name, v.start)
            if v.is_array:
                base = next(iter(base), None) if isinstance(base, (list, tuple)) else base
            values = _values_around(base, v)
            if values is not None:
                candidates.append((unit.spec.kind != "connectors", target, values))
    if not candidates:
        return None
    _, target, values = min(candidates, key=lambda c: c[0])  # connectors first, then in the units' order
    return target, values


def _values_around(base: Any, v: Variable) -> list[Any] | None:
    """Three values around ``base`` inside ``v``'s range (half, as is, one and a half; 0 -> 0, 1, 2)."""
    if isinstance(base, bool) or not isinstance(base, (int, float)) or not math.isfinite(base):
        return None
    low = float(v.min) if isinstance(v.min, (int, float)) else -math.inf
    high = float(v.max) if isinstance(v.max, (int, float)) else math.inf
    raw: list[float] = [base * 0.5, base, base * 1.5] if base else [0.0, 1.0, 2.0]
    if v.type == "Integer":
        raw = [base - 1, base, base + 1] if base else [0.0, 1.0, 2.0]
    values = []
    for x in sorted(raw):
        x = min(max(x, low), high)
        x = int(round(x)) if v.type == "Integer" else float(f"{x:.12g}")  # 0.15, not 0.15000000000000002
        if x not in values:
            values.append(x)
    return values if len(values) > 1 else None
