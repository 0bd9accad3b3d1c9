"""SSP (System Structure and Parameterization, Modelica Association) import and export.

``cosim validate | inspect | run | sweep system.ssp`` read an SSP through
:func:`ssp_raw_spec`, which flattens its system into the content of a
spec.json (see :mod:`.reader`); a spec.json with ``"system": "file.ssp"``
gets that content merged under its own (:func:`merge_system`).
:mod:`cosim.export.ssp` exports a spec as an SSP 2.0 archive.

Offers: ``ssp_raw_spec`` (an SSP read into a spec's content), ``merge_system``.
"""

from __future__ import annotations

import copy
import logging
from pathlib import Path
from typing import Any, Mapping

from cosim.errors import Problem, SpecError
from cosim.ssp.archive import is_ssp
from cosim.ssp.experiment import with_tool_defaults
from cosim.ssp.names import rename_prefix
from cosim.ssp.reader import SspSystem, read_ssp
from cosim.ssp.system_connectors import ConnectorSignal, connector_units
from cosim.units.registry import unit_kinds

__all__ = ["is_ssp", "merge_system", "read_ssp", "ssp_raw_spec", "SspSystem"]
log = logging.getLogger("cosim.ssp")


def ssp_raw_spec(path: str | Path, experiment: Mapping[str, Any] | None = None, variant: str | None = None) -> dict:
    """The spec content of the SSP at ``path`` (its ``variant``, if given), with ``experiment`` fields (command
    line) on top.

    Every system connector holding a value (a parameter connector, bound) is a parameter of its system's
    ``connectors`` unit, feeding what its parameter connections feed (``--set Root.k=V`` sets them all).
    The run records every component's outputs and the output connectors of the root system and its sub-systems
    (``Root.sub.connector``: a ``connectors`` unit per system, see :mod:`.system_connectors`, whose inputs are
    fed by the component outputs the connectors carry, scaled as their chains scale them).  An SSP with no
    component runs the constants its system connectors hold, recording them.  Raises SpecError for every problem
    of the SSP and when it has neither a component nor a constant; a stop time or step size that neither the SSP
    nor ``experiment`` gives is OMSimulator's default (:func:`~cosim.ssp.experiment.with_tool_defaults`).
    """
    system = read_ssp(path, variant)
    raw = system.raw
    if not raw["units"]:  # values on system connectors or parameter sets only: the constants are what runs
        constants = _constants(system)
        if not constants:
            raise SpecError([_nothing_to_run(system)])
        raw["units"], _ = connector_units(constants)
        raw["record"] = [c.name for c in constants]
    else:
        outputs = recorded_outputs(system, raw["units"])
        # every connector holding a value is a parameter of its system's connectors unit too, so that --set
        # (and an explore re-run) can set it, and with it the FMU parameters it feeds; recorded: the outputs
        constants = [c for c in _constants(system) if c.system not in raw["units"]]
        units, connections = connector_units(outputs + constants)
        raw["units"].update(units)
        raw["connections"].extend(connections)
        raw["record"].extend(c.name for c in outputs)
    raw["experiment"].update(experiment or {})
    raw["experiment"] = with_tool_defaults(raw["experiment"], str(path))  # as OMSimulator runs it, with a note
    return raw


def recorded_outputs(system: SspSystem, units: Mapping[str, Any]) -> list[ConnectorSignal]:
    """What the output connectors of the root system and its sub-systems carry, in document order, each a
    signal of its own (also one carrying a component output unchanged: a run records it by the connector's
    name); left out: a connector that carries nothing known (fed by nothing), and the connectors of a system
    named like one of ``units`` (a component, or a spec's own unit)."""
    signals = system.connector_signals
    return [signals[name] for name in system.output_connectors
            if name in signals and signals[name].system not in units]


def _constants(system: SspSystem) -> list[ConnectorSignal]:
    """The system connectors holding a constant, each once, in document order."""
    root = system.root_system
    return [c for name, c in system.connector_signals.items() if c.port is None and name == c.name
            and (name.startswith(root + ".") or not root)]


def _nothing_to_run(system: SspSystem) -> Problem:
    connectors = system.system_connectors
    return Problem(system.files.label(system.files.ssd), "/ssd:SystemStructureDescription/ssd:System",
                   "the SSP has no component (FMU or CSV table) and no system connector holding a value: nothing "
                   "to run" + (f" (its system connectors {', '.join(connectors[:6])} are fed by nothing)"
                               if connectors else ""),
                   "add the components (ssd:Component with an FMU or a CSV table) the values are for, or name the "
                   "SSP as \"system\" in a spec.json that adds units")


def merge_system(spec: dict, spec_path: Path, overrides: Mapping[str, Any] | None = None) -> dict:
    """A spec.json whose ``"system"`` names an SSP (a path, or ``{"ssp": path, "variant": name}``), with the
    SSP's units and connections merged in.

    The spec's own entries win: a unit of the same name has its fields
    replaced (``parameters`` and ``start`` merged value by value), a spec
    connection into an input the SSP already feeds replaces the SSP's, and
    the spec's experiment fields override the SSP's (and ``overrides``, the command line's, override both; a stop
    time or step size none gives is OMSimulator's default).  The spec's connections
    come first, so JSON paths of problems in them match the spec file.
    Raises SpecError for problems of the SSP.
    """
    given: Any
    variant: Any
    given, variant, where = spec["system"], None, "$.system"
    if isinstance(given, dict):  # {"ssp": "x.ssp", "variant": "Variant-B"}
        given, variant, where = given.get("ssp"), given.get("variant"), "$.system.ssp"
    if not isinstance(given, str) or (variant is not None and not isinstance(variant, str)):
        raise SpecError([Problem(str(spec_path), "$.system", "\"system\" is neither an SSP's path nor "
                                 "{\"ssp\": path, \"variant\": name}",
                                 "write \"system\": \"x.ssp\" or \"system\": {\"ssp\": \"x.ssp\", \"variant\": \"B\"}")])
    source = Path(given)
    if not source.is_absolute():
        source = spec_path.resolve().parent / source
    if not source.exists():
        raise SpecError([Problem(str(spec_path), where, f"'{given}' not found",
                                 "name an .ssp archive, an .ssd file or a folder with SystemStructure.ssd, "
                                 "relative to the spec's folder")])
    if not is_ssp(source):
        raise SpecError([Problem(str(spec_path), where, f"'{given}' is not an SSP",
                                 "name an .ssp archive, an .ssd file or a folder with SystemStructure.ssd")])
    system = read_ssp(source, variant)
    ssp = system.raw
    merged = copy.deepcopy(spec)
    units = copy.deepcopy(ssp["units"])
    for name, own in (spec.get("units") or {}).items():
        if name in units and isinstance(own, dict):
            base = units[name]
            kinds = unit_kinds()  # the spec's own kind replaces the SSP's (fmu, python, player or a plug-in's)
            if any(k in own for k in kinds):
                base = {k: v for k, v in base.items() if k not in kinds}
            for key, value in own.items():
                if key in ("parameters", "start") and isinstance(value, dict):
                    base[key] = {**base.get(key, {}), **value}
                else:
                    base[key] = value
            units[name] = base
        else:
            units[name] = own
    merged["units"] = units
    own_connections = list(spec.get("connections") or [])
    fed = {c.get("to") for c in own_connections if isinstance(c, dict)}
    merged["connections"] = own_connections + [c for c in ssp["connections"] if c["to"] not in fed]
    own_experiment = spec.get("experiment")
    if isinstance(own_experiment, dict) or own_experiment is None:
        # what neither the spec, the command line nor the SSP gives: OMSimulator's defaults, with a note
        merged["experiment"] = with_tool_defaults({**ssp["experiment"], **(own_experiment or {}),
                                                   **(overrides or {})}, given)
    else:  # not an object: the spec's problem, reported at its JSON path
        merged["experiment"] = own_experiment
    implied: list[ConnectorSignal] = []
    if "record" not in spec and units:  # recorded as the SSP alone records: its units' ports and output connectors
        implied = recorded_outputs(system, units)
        merged["record"] = ssp["record"] + [c.name for c in implied]
    merged.setdefault("name", ssp["name"])
    problems = _name_connectors(merged, system, str(spec_path), implied)
    if problems:
        raise SpecError(problems)
    return merged


def _name_connectors(spec: dict, system: SspSystem, file: str, implied: list[ConnectorSignal]) -> list[Problem]:
    """Signals in ``record``, objectives and ``stop_when`` that name the SSP's system connectors
    (``Root.SuT.speed``, as a tool's users write them) or a unit with the root system's name in front
    (``Root.SuT.motor.y``), rewritten to what they mean: a connector carrying a unit port unchanged is that port;
    one scaling it or holding a constant is a port of the ``connectors`` unit of its system (added to the spec
    with the connections feeding it, see :func:`~cosim.ssp.system_connectors.connector_units`); a spec without
    any unit runs the SSP's constants.  ``implied``: the output connectors recorded for a spec without ``record``
    (:func:`recorded_outputs`), kept by their own names.  Design parameters naming a system's parameter
    connector become that port of its ``connectors`` unit, which ``feeds`` the FMU parameters the connector sets.
    A problem for a ``connectors`` unit whose name a spec unit has, and for a design parameter naming a connector
    fed by a component output."""
    units = [u for u in spec.get("units") or {} if isinstance(u, str)]
    signals, root = system.connector_signals, system.root_system
    problems: list[Problem] = []
    named: dict[str, ConnectorSignal] = {c.name: c for c in implied}
    implied_names = set(named)

    def names_unit(text: str) -> bool:
        return any(text.startswith(u + ".") for u in units)

    def resolve(text: Any, where: str) -> Any:
        if isinstance(text, str):  # the SSP's own spelling ('DC-Motor.SuT.phiB') -> cosim's (cosim.ssp.names)
            text = rename_prefix(text, system.renamed)
        if not isinstance(text, str) or names_unit(text):
            return text
        if text in signals:
            carried = signals[text]
            if carried.unchanged:
                log.warning("%s: %s '%s' is the SSP's system connector carrying '%s': recorded as '%s'",
                            file, where, text, carried.port, carried.port)
                return carried.port
            if carried.system in units:
                problems.append(Problem(file, where, f"'{text}' is the SSP's system connector {carried.name}, but "
                                        f"the spec has a unit named '{carried.system}' as the system is",
                                        f"rename the unit '{carried.system}'"))
                return text
            named.setdefault(carried.name, carried)
            return carried.name
        if root and text.startswith(root + ".") and names_unit(text[len(root) + 1:]):
            return text[len(root) + 1:]  # OMSimulator's result names carry the root system's name
        return text

    def design_target(key: str, where: str) -> str:
        """A design parameter naming a system connector: a parameter connector is a parameter of its system's
        ``connectors`` unit, which sets the FMU parameters the connector feeds; one fed by a component output
        (an output, or an input of a sub-system) has no value to set before the run: a problem."""
        key = rename_prefix(key, system.renamed)
        if names_unit(key):
            return key
        if key not in signals:
            full = key if key in every_connector else f"{root}.{key}"
            if full in every_connector:  # a system connector that holds no value and is fed by nothing
                problems.append(Problem(file, where, f"'{key}' is a connector of the SSP's system "
                                        f"'{full.rsplit('.', 1)[0]}' that holds no value: cosim sets the "
                                        "parameters a parameter connector feeds from the value bound to it",
                                        f"bind a value to {full} in the SSP (ssd:ParameterBinding of its system), "
                                        "or name the unit parameters it feeds"))
                return key
            return resolve(key, where)
        carried = signals[key]
        output = carried.name in outputs
        if output or carried.port is not None:
            what = "an output connector" if output else "a connector"
            carries = f", which carries {carried.port}" if carried.port is not None else ""
            problems.append(Problem(file, where, f"'{key}' is {what} of the SSP's system '{carried.system}'"
                                    f"{carries}: a design parameter sets a value before the run, which only a "
                                    "parameter connector (kind=\"parameter\") of a system takes",
                                    "name a system's parameter connector, or a unit's parameter (unit.parameter)"))
            return key
        if not carried.feeds:  # fed by another connector, connected to nothing, or beaten by direct bindings
            problems.append(Problem(file, where, f"'{key}' is a connector of the SSP's system '{carried.system}' "
                                    "that sets no unit parameter through a parameter connection of its own (it is "
                                    "connected to none, takes its value from another connector, or the "
                                    "parameters keep a direct binding of a higher system)",
                                    "name the parameter connector the value comes from, or the unit parameters"))
            return key
        return resolve(key, where)

    outputs = set(system.output_connectors)
    every_connector = set(system.system_connectors)
    design = spec.get("design")
    if isinstance(design, dict) and isinstance(design.get("parameters"), dict):
        design["parameters"] = {design_target(key, f"$.design.parameters.{key}") if isinstance(key, str) else key:
                                value for key, value in design["parameters"].items()}
    if isinstance(spec.get("record"), list):
        spec["record"] = [r if r in implied_names else resolve(r, f"$.record[{i}]")
                          for i, r in enumerate(spec["record"])]
    for name, objective in (spec.get("objectives") or {}).items() if isinstance(spec.get("objectives"), dict) \
            else ():
        if isinstance(objective, dict) and "signal" in objective:
            objective["signal"] = resolve(objective["signal"], f"$.objectives.{name}.signal")
    experiment = spec.get("experiment")
    if isinstance(experiment, dict) and "stop_when" in experiment:
        experiment["stop_when"] = resolve(experiment["stop_when"], "$.experiment.stop_when")
    if not units and not named:  # the SSP has no component and the spec adds none: its constants run
        named = {c.name: c for c in _constants(system)}
        if not named:
            problems.append(_nothing_to_run(system))
        if "record" not in spec or not spec.get("record"):
            spec["record"] = list(named)
    if named and not problems:
        added, connections = connector_units(list(named.values()))
        spec["units"] = {**(spec.get("units") or {}), **added}
        spec["connections"] = [*(spec.get("connections") or []), *connections]
    return problems
