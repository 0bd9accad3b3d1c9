"""Export a spec's system as an SSP 2.0 archive.

:func:`export_ssp` writes ``SystemStructure.ssd`` with one flat root system:
one ``ssd:Component`` per unit (FMUs copied to ``resources/``; Python units
built into FMI 2.0 FMUs with pythonfmu, see :mod:`cosim.export.fmu`; a
``connectors`` unit as the system connectors it stands for, see
:mod:`cosim.export.system_connectors`),
its connectors and ``implementation`` (``CoSimulation`` or ``ModelExchange``, as the unit runs), one
``resources/<unit>.ssv`` per unit with the spec's
parameter and start values (written with 17 significant digits, so they read
back bit for bit), the connections (a factor or offset as a
``LinearTransformation``; ``suppressUnitConversion`` because cosim itself does
not convert), ``DefaultExperiment`` and the fixed step size as OMSimulator
2's ``FixedStepMaster``, OMSimulator 3's ``oms_ma`` solver and OSP's
``FixedStepAlgorithm`` annotation, a model-exchange unit's ``tolerance`` and
``max_step`` as an OMSimulator 3 ``cvode`` solver assigned to its component,
and cosim's own master algorithm and experiment options (and a unit's
``record_events`` and ``coupled_model_exchange``) as ``org.cosim``
annotations: reading the archive back gives the same experiment.
Array ports are connected element by element (``x[1]`` .. ``x[n]``: the
scalar variables of an FMI 2.0 FMU, as tools reading FMI 2.0 expect; the
elements of an FMI 3.0 array).  Next to the
archive, ``<name>.spec.json`` keeps what an SSP cannot hold (objectives,
design space, recorded signals, ``stop_when``) and names the archive as its
``system``.  The written SSD is checked against the official schema.
"""

from __future__ import annotations

import json
import shutil
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lxml import etree

from cosim.errors import Problem, SpecError
from cosim.export.system_connectors import (
    export_problems,
    fed_parameters,
    fed_value_problems,
    is_connectors_target,
    root_name,
    write_system_connectors,
)
from cosim.ssp.annotations import COSIM_UNIT_OPTIONS
from cosim.ssp.experiment import COSIM_EXPERIMENT_FLAGS, COSIM_EXPERIMENT_GROUPS
from cosim.ssp.xml import NS, schema_problems
from cosim.system.builder import System

OMS_NS = "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd"
OSP_NS = "http://opensimulationplatform.com/SSP/OSPAnnotations"
COSIM_NS = "urn:cosim:ssp"
_SSC_TYPE = {"Real": "Real", "Integer": "Integer", "Boolean": "Boolean", "String": "String"}


def _e(parent: Any, prefix: str, element_tag: str, **attributes: Any) -> Any:
    """A child element ``prefix:element_tag`` with the attributes that are not None."""
    namespace = {"oms": OMS_NS, "osp": OSP_NS, "cosim": COSIM_NS}.get(prefix) or NS[prefix]
    element = etree.SubElement(parent, f"{{{namespace}}}{element_tag}")
    for key, value in attributes.items():
        if value is not None:
            element.set(key, value if isinstance(value, str) else _number(value))
    return element


def _number(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)  # shortest text that reads back to the same double
    return str(value)


def export_ssp(system: System, out: str | Path, spec_copy: bool = True) -> Path:
    """Write ``system`` as an SSP 2.0 archive at ``out``; returns its path.

    Raises SpecError for a unit that cannot go into an SSP: only FMUs,
    Python units (built into FMUs) and ``connectors`` units (as the system
    connectors they stand for, see :mod:`cosim.export.system_connectors`)
    can; not a player, nor a plug-in's kind.
    """
    out = Path(out)
    spec = system.spec
    problems = [Problem(spec.path, f"$.units.{u.name}", f"a {u.kind} unit cannot be exported to an SSP",
                        "only FMU and Python units go into an SSP: make it one of those (e.g. an FMU), or export "
                        "the system without it")
                for u in spec.units if u.kind not in ("fmu", "python", "connectors")]
    problems += export_problems(system)
    problems += fed_value_problems(system, _unit_values(system))
    if problems:
        raise SpecError(problems)
    with tempfile.TemporaryDirectory(prefix="cosim_ssp_export_") as scratch:
        root = Path(scratch)
        (root / "resources").mkdir()
        fmus = _write_fmus(system, root / "resources")
        ssd = _ssd(system, fmus, root / "resources")
        problems = schema_problems(ssd, f"{out}:SystemStructure.ssd", "ssd")
        if problems:  # our own writer broke the schema: a bug, not the user's mistake
            raise RuntimeError("the exported SSD breaks the SSP schema: " + "; ".join(map(str, problems)))
        (root / "SystemStructure.ssd").write_bytes(
            etree.tostring(ssd.getroottree(), xml_declaration=True, encoding="UTF-8", pretty_print=True))
        out.parent.mkdir(parents=True, exist_ok=True)
        partial = out.with_name(out.name + ".part")
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as zf:
            for path in sorted(root.rglob("*")):
                if path.is_file():
                    zf.write(path, path.relative_to(root).as_posix())
        shutil.move(partial, out)
    if spec_copy:
        _write_companion_spec(system, out)
    return out


def companion_spec_path(out: Path) -> Path:
    """``system.spec.json`` beside ``system.ssp``."""
    return out.with_name(out.stem + ".spec.json")


def _write_companion_spec(system: System, out: Path) -> None:
    raw = system.spec.raw
    companion: dict[str, Any] = {"name": system.spec.name, "system": out.name}
    if system.spec.description:
        companion["description"] = system.spec.description
    experiment = {k: v for k, v in (raw.get("experiment") or {}).items() if k in ("algorithm", "stop_when")}
    if experiment:
        companion["experiment"] = experiment
    ports = {u.name: {"ports": dict(u.ports)} for u in system.spec.units if u.ports}
    if ports:  # the SSP names ports as the units do; the spec's own names map onto them again
        companion["units"] = ports
    for key in ("record", "objectives", "design"):
        if raw.get(key):
            companion[key] = raw[key]
    companion_spec_path(out).write_text(json.dumps(companion, indent=2) + "\n", encoding="utf-8")


def _write_fmus(system: System, resources: Path) -> dict[str, tuple[str, str]]:
    """Each unit's FMU in resources/: unit name -> (source attribute, FMI version)."""
    from cosim.export.fmu import export_python_unit
    from cosim.units.fmu.description import FmuUnitType

    result: dict[str, tuple[str, str]] = {}
    copied: dict[str, str] = {}
    for name, unit in system.units.items():
        if unit.spec.kind == "connectors":
            continue  # system connectors, not a component
        if unit.spec.kind == "fmu":
            unit_type: FmuUnitType = unit.unit_type  # type: ignore[assignment]
            if unit_type.digest not in copied:
                file_name = _unique(resources, Path(unit_type.path).stem)
                shutil.copyfile(unit_type.path, resources / file_name)
                copied[unit_type.digest] = file_name
            result[name] = (f"resources/{copied[unit_type.digest]}", unit.description.fmi_version or "2.0")
        else:  # a Python unit, built into an FMI 2.0 FMU
            file_name = _unique(resources, unit.spec.source.rpartition(":")[2])
            export_python_unit(unit.spec.source, resources / file_name, system.spec.folder)
            result[name] = (f"resources/{file_name}", "2.0")
    return result


def _unique(folder: Path, stem: str) -> str:
    candidate, n = f"{stem}.fmu", 1
    while (folder / candidate).exists():
        n += 1
        candidate = f"{stem}_{n}.fmu"
    return candidate


def _port_names(variable: Any, fmi_version: str) -> list[str]:
    """The connector names of a variable: FMI 2.0 arrays as their scalars."""
    return variable.element_names() if variable.is_array and fmi_version == "2.0" else [variable.name]


def _ssd(system: System, fmus: dict[str, tuple[str, str]], resources: Path) -> Any:
    spec = system.spec
    nsmap = {**{k: NS[k] for k in ("ssd", "ssc", "ssv")}, "oms": OMS_NS, "osp": OSP_NS, "cosim": COSIM_NS}
    root = etree.Element(f"{{{NS['ssd']}}}SystemStructureDescription", nsmap=nsmap)
    root.set("version", "2.0")
    root.set("name", spec.name)
    root.set("generationTool", "cosim")
    if spec.description:
        root.set("description", spec.description)
    top = _e(root, "ssd", "System", name=root_name(system) or spec.name)  # connectors units name the root
    elements = _e(top, "ssd", "Elements")
    values = _unit_values(system)
    for target in fed_parameters(system):  # set by a connection from the system connector feeding it
        fed_unit, _, port = target.rpartition(".")
        values[fed_unit] = [entry for entry in values.get(fed_unit, []) if entry[0] != port]
    solvers = _cvode_solvers(system)
    for name, unit in system.units.items():
        if name not in fmus:
            continue  # a connectors unit: written below, as system connectors
        source, fmi_version = fmus[name]
        component = _e(elements, "ssd", "Component", name=name, type="application/x-fmu-sharedlibrary",
                       source=source, implementation=_implementation(unit))
        connectors = _e(component, "ssd", "Connectors")
        for variable in unit.description.variables:
            if variable.causality not in ("input", "output", "parameter", "calculatedParameter",
                                          "structuralParameter"):
                continue
            if variable.is_array and fmi_version != "2.0":
                continue  # FMI 3.0 arrays: reached through their elements' names in connections
            for port in _port_names(variable, fmi_version):
                connector = _e(connectors, "ssd", "Connector", name=port, kind=variable.causality
                               if variable.causality != "structuralParameter" else "parameter")
                _e(connector, "ssc", _SSC_TYPE[variable.type],
                   **({"unit": variable.unit} if variable.unit and variable.type == "Real" else {}))
        if values.get(name):
            ssv = _ssv(name, values[name])
            (resources / f"{name}.ssv").write_bytes(
                etree.tostring(ssv.getroottree(), xml_declaration=True, encoding="UTF-8", pretty_print=True))
            bindings = _e(component, "ssd", "ParameterBindings")
            _e(bindings, "ssd", "ParameterBinding", source=f"resources/{name}.ssv")
        options = {k: unit.spec.options[k] for k in COSIM_UNIT_OPTIONS if unit.spec.options.get(k) is not None}
        if name in solvers.assigned or options:
            component_annotations = _e(component, "ssd", "Annotations")
        if name in solvers.assigned:  # OMSimulator 3's form: the component names the solver the system defines
            _e(_e(_e(component_annotations, "ssc", "Annotation", type="org.openmodelica"), "oms", "Annotations"),
               "oms", "SimulationInformation", name=solvers.assigned[name])
        if options:  # cosim's own options of the unit, read back by cosim.ssp.annotations.cosim_unit_options
            _e(_e(component_annotations, "ssc", "Annotation", type="org.cosim"), "cosim", "Unit", **options)
    connections = _e(top, "ssd", "Connections")
    for c in system.connections:
        if is_connectors_target(system, c):
            continue  # written with the system connector it feeds
        for start, end in zip(_element_names(c.source), _element_names(c.target), strict=True):
            connection = _e(connections, "ssd", "Connection", startElement=c.source.unit, startConnector=start,
                            endElement=c.target.unit, endConnector=end, suppressUnitConversion="true")
            if c.transforms:
                _e(connection, "ssc", "LinearTransformation", factor=c.factor, offset=c.offset)
    write_system_connectors(system, top, elements, connections, _e, _element_names)
    if not len(connections):  # the schema wants one Connection at least: a system without any has no Connections
        top.remove(connections)
    exp = spec.experiment
    annotations = _e(top, "ssd", "Annotations")
    oms_annotations = _e(_e(annotations, "ssc", "Annotation", type="org.openmodelica"), "oms", "Annotations")
    # the step as OMSimulator 2 (FixedStepMaster) and 3 (an oms_ma solver) write it; OMSimulator 3's cvode
    # solvers carry the model-exchange units' tolerance and max_step
    _e(_e(oms_annotations, "oms", "SimulationInformation"), "oms", "FixedStepMaster", description="oms-ma",
       stepSize=exp.step)
    _e(oms_annotations, "oms", "SimulationInformation", name="cosim_master", method="oms_ma", fixedStepSize=exp.step)
    for solver_name, settings in solvers.defined.items():
        _e(oms_annotations, "oms", "SimulationInformation", name=solver_name, method="cvode", **settings)
    _cosim_experiment(_e(annotations, "ssc", "Annotation", type="org.cosim"), spec)
    default = _e(root, "ssd", "DefaultExperiment", startTime=exp.start, stopTime=exp.stop)
    osp = _e(_e(_e(default, "ssd", "Annotations"), "ssc", "Annotation", type="com.opensimulationplatform"),
             "osp", "Algorithm")
    _e(osp, "osp", "FixedStepAlgorithm", baseStepSize=exp.step)
    return root


@dataclass
class _Solvers:
    """OMSimulator 3 cvode solvers for the model-exchange units: one per distinct tolerance and max_step."""

    defined: dict[str, dict[str, float]] = field(default_factory=dict)  # solver name -> its attributes
    assigned: dict[str, str] = field(default_factory=dict)  # unit name -> solver name


def _cvode_solvers(system: System) -> _Solvers:
    solvers = _Solvers()
    by_settings: dict[tuple, str] = {}
    for name, unit in system.units.items():
        if _implementation(unit) != "ModelExchange":
            continue
        options = unit.spec.options
        settings = {attribute: float(options[key]) for key, attribute in (("tolerance", "relativeTolerance"),
                                                                           ("max_step", "maximumStepSize"))
                    if options.get(key) is not None}
        key = tuple(sorted(settings.items()))
        if key not in by_settings:
            by_settings[key] = f"cosim_cvode{len(by_settings) + 1}"
            solvers.defined[by_settings[key]] = settings
        solvers.assigned[name] = by_settings[key]
    return solvers


def _implementation(unit: Any) -> str:
    """The SSP ``implementation`` of a unit: how it runs (a Python unit becomes a co-simulation FMU)."""
    interface = getattr(unit.unit_type, "interface", "co-simulation") if unit.spec.kind == "fmu" else "co-simulation"
    return "ModelExchange" if interface == "model-exchange" else "CoSimulation"


def _cosim_experiment(annotation: Any, spec: Any) -> None:
    """cosim's own experiment settings an SSP has no place for: the master algorithm and its options (adaptive
    steps, the loop solver, coupled model exchange, early stop, warm start), as ``cosim:Experiment`` with one child per
    option group; :func:`cosim.ssp.experiment.read_experiment` reads them back."""
    raw = spec.raw.get("experiment") or {}
    experiment = _e(annotation, "cosim", "Experiment", algorithm=spec.experiment.algorithm,
                    **{k: raw[k] for k in COSIM_EXPERIMENT_FLAGS if raw.get(k) is not None})
    for group in COSIM_EXPERIMENT_GROUPS:
        if isinstance(raw.get(group), dict) and raw[group]:
            _e(experiment, "cosim", group, **raw[group])


def _element_names(signal: Any) -> list[str]:
    """Connector names of a connection end, one per scalar element (``x[1]`` .. ``x[n]`` for arrays).

    FMI 2.0 FMUs (and Python units exported as such) have these scalars as
    variables; for an FMI 3.0 array they name its elements.
    """
    name = signal.variable.name
    if not signal.variable.is_array:
        return [name]
    return [f"{name}[{ref.offset + 1}]" for ref in signal.refs]


def _unit_values(system: System) -> dict[str, list[tuple[str, str, Any]]]:
    """Per unit: (connector name, type, value) of every parameter and start value the spec sets."""
    result: dict[str, list[tuple[str, str, Any]]] = {}
    for assignment in system.assignments:
        unit = system.units[assignment.unit]
        by_name = unit.description.by_name
        for ref, value in zip(assignment.refs, assignment.values):
            variable = by_name[ref.variable]
            name = f"{variable.name}[{ref.offset + 1}]" if variable.is_array else variable.name
            entries = result.setdefault(assignment.unit, [])
            entries[:] = [e for e in entries if e[0] != name]  # a later assignment wins
            entries.append((name, variable.type, value))
    return result


def _ssv(name: str, entries: list[tuple[str, str, Any]]) -> Any:
    root = etree.Element(f"{{{NS['ssv']}}}ParameterSet", nsmap={"ssv": NS["ssv"]})
    root.set("version", "2.0")
    root.set("name", name)
    parameters = _e(root, "ssv", "Parameters")
    for port, kind, value in entries:
        parameter = _e(parameters, "ssv", "Parameter", name=port)
        _e(parameter, "ssv", _SSC_TYPE[kind], value=value)
    problems = schema_problems(root, f"resources/{name}.ssv", "ssv")
    if problems:
        raise RuntimeError("the exported SSV breaks the SSP schema: " + "; ".join(map(str, problems)))
    return root
