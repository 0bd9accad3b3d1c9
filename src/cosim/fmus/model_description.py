"""One variable description (``fmus/<name>/model.json``) -> everything generated.

From a model's ``model.json`` this module generates

* the FMI 3.0 ``modelDescription.xml`` (array variables with ``<Dimension>``),
* the FMI 2.0 ``modelDescription.xml`` (one scalar per element, ``tau[1]`` ..
  ``tau[7]``, 1-based),
* ``model_generated.h`` / ``model_generated.c``: the C struct holding every
  variable, value-reference constants, the variable table the shared framework
  (``fmus/common``) uses to get and set values, and ``setStartValues``.

Value references (the same for every FMU we build):

* FMI 3.0: ``time`` has VR 0; the k-th variable of ``model.json`` (1-based) has
  VR k, an array has one VR for all its elements.
* FMI 2.0: every scalar element gets its own VR, numbered consecutively in
  ``model.json`` order: ``time`` is 0, then ``tau[1]`` .. ``tau[7]`` are 1..7,
  and so on.  A VR is also the scalar's 0-based index in ``<ModelVariables>``.

``model.json`` keys: ``name``, ``description``, ``version``,
``defaultExperiment`` ({startTime, stopTime, stepSize}), ``units`` (name ->
{base-unit exponents..., "factor", "offset"}), ``variables``: a list of
{``name``, ``causality`` (parameter | input | output | local), ``type`` (Real |
Integer | Boolean), ``unit``, ``start`` (scalar, or a list for arrays),
``min``, ``max``, ``description``, ``dimension`` (int, arrays only),
``dependencies`` (outputs: names of inputs read directly; ``[]`` = none),
``elementwise`` (bool: element i of an output array depends only on element i
of array dependencies; refines the FMI 2.0 dependencies only), ``derivative``
(Model Exchange: this Real scalar is the time derivative of the named Real
scalar, which thereby is a continuous state), ``variability`` (``discrete``
for a Real that changes only at events; ``tunable`` for a parameter that may be
set between steps, after initialization: FMI ``variability="tunable"``), ``initial`` (``exact`` for an
output or local whose ``start`` the environment may set before initialization: a state's start value, as the
Reference FMUs declare them; else outputs and locals are ``calculated``)}.

Model Exchange keys (see ``fmus/common/model_exchange.h``): ``interfaces``
(``["CoSimulation"]`` by default; ``"ModelExchange"`` needs the model's
``model_event_update`` and ``model_step_event``, ``"CoSimulation"`` its
``model_do_step``), ``eventIndicators`` (names of Real scalars whose sign
changes are state events), ``needsCompletedIntegratorStep`` (bool).
``directionalDerivatives`` (bool): the model supplies ``model_partial`` (framework.h), so the FMUs offer
``fmi2GetDirectionalDerivative`` / ``fmi3GetDirectionalDerivative`` (``providesDirectionalDerivative(s)``).  A build
may offer fewer interfaces than the model supports (the ``interfaces``
argument of the generators).
"""

from __future__ import annotations

import hashlib
import json
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

from cosim.errors import (
    ModelJsonError,  # one error family with the engine (exit code 2 in a command)
)

CAUSALITIES = ("parameter", "input", "output", "local")
C_TYPES = {"Real": "double", "Integer": "int32_t", "Boolean": "bool"}
FMI3_TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}
TYPE_CODES = {"Real": "VT_REAL", "Integer": "VT_INTEGER", "Boolean": "VT_BOOLEAN"}
INTERFACES = ("CoSimulation", "ModelExchange")
CAUSALITY_CODES = {"parameter": "CAUS_PARAMETER", "input": "CAUS_INPUT", "output": "CAUS_OUTPUT", "local": "CAUS_LOCAL"}


@dataclass(frozen=True)
class ModelVariable:
    """One variable of ``model.json`` (an array when ``dimension`` is set)."""

    name: str
    causality: str
    type: str
    vr3: int
    vr2: int
    unit: str | None = None
    start: Any = None
    min: float | None = None
    max: float | None = None
    description: str = ""
    dimension: int | None = None
    dependencies: tuple[str, ...] | None = None
    elementwise: bool = False
    derivative: str | None = None  # Model Exchange: the state this variable is the derivative of
    discrete: bool = False  # a Real that changes only at events
    tunable: bool = False  # a parameter that may be set after initialization (between steps, in event mode)
    initial: str | None = None  # "exact": an output or local whose start value may be set before initialization

    @property
    def size(self) -> int:
        return self.dimension or 1

    @property
    def variability(self) -> str:
        if self.causality == "parameter":
            return "tunable" if self.tunable else "fixed"
        return "continuous" if self.type == "Real" and not self.discrete else "discrete"

    def starts(self) -> list[Any]:
        """Start value of every element (``start`` may be one value for all)."""
        start = self.start if self.start is not None else _zero(self.type)
        if isinstance(start, list):
            if len(start) != self.size:
                raise ModelJsonError(f"'{self.name}': start has {len(start)} values, dimension is {self.size}")
            return start
        return [start] * self.size

    def element_names(self) -> list[str]:
        if self.dimension is None:
            return [self.name]
        return [f"{self.name}[{i}]" for i in range(1, self.size + 1)]


@dataclass(frozen=True)
class Model:
    """A parsed ``model.json``."""

    name: str
    description: str
    version: str
    default_experiment: dict[str, float]
    units: dict[str, dict[str, float]]
    variables: tuple[ModelVariable, ...]
    digest: str = ""
    extra: dict = field(default_factory=dict)
    interfaces: tuple[str, ...] = ("CoSimulation",)
    event_indicators: tuple[str, ...] = ()
    needs_completed_integrator_step: bool = False
    directional_derivatives: bool = False  # model.c supplies model_partial: the FMUs offer directional derivatives

    def states(self) -> list[tuple[ModelVariable, ModelVariable]]:
        """(continuous state, its derivative) pairs, in the order of the derivatives."""
        by_name = self.by_name()
        return [(by_name[v.derivative], v) for v in self.variables if v.derivative]

    def offers(self, interfaces: tuple[str, ...] | None) -> tuple[str, ...]:
        """The interfaces a build offers: ``interfaces`` (checked) or all the model supports."""
        if interfaces is None:
            return self.interfaces
        unknown = [i for i in interfaces if i not in self.interfaces]
        if not interfaces or unknown:
            raise ModelJsonError(f"model '{self.name}' supports {', '.join(self.interfaces)}; "
                                 f"cannot build {', '.join(interfaces) or 'no interface'}")
        return tuple(i for i in INTERFACES if i in interfaces)

    @property
    def token(self) -> str:
        """The instantiation token / GUID: derived from the sources' digest."""
        return "{" + str(uuid.UUID(self.digest[:32])) + "}"

    def by_name(self) -> dict[str, ModelVariable]:
        return {v.name: v for v in self.variables}

    @property
    def n_scalars(self) -> int:
        return 1 + sum(v.size for v in self.variables)  # + time


def _zero(type_: str) -> Any:
    return {"Real": 0.0, "Integer": 0, "Boolean": False}[type_]


def load_model(path: Path, digest: str = "") -> Model:
    """Parse and check ``model.json``; raises :class:`ModelJsonError`."""
    try:
        raw = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ModelJsonError(f"{path}: {exc}") from exc
    variables: list[ModelVariable] = []
    vr2 = 1
    names: set[str] = set()
    for k, item in enumerate(raw.get("variables", []), start=1):
        name = item.get("name")
        if not name or not name.isidentifier() or name in names or name == "time":
            raise ModelJsonError(f"{path}: variable {k}: bad or duplicate name {name!r}")
        names.add(name)
        causality = item.get("causality")
        type_ = item.get("type", "Real")
        if causality not in CAUSALITIES or type_ not in C_TYPES:
            raise ModelJsonError(f"{path}: '{name}': causality {causality!r} / type {type_!r} not supported")
        dim = item.get("dimension")
        deps = item.get("dependencies")
        var = ModelVariable(
            name=name, causality=causality, type=type_, vr3=k, vr2=vr2, unit=item.get("unit"),
            start=item.get("start"), min=item.get("min"), max=item.get("max"),
            description=item.get("description", ""), dimension=int(dim) if dim else None,
            dependencies=tuple(deps) if deps is not None else None, elementwise=bool(item.get("elementwise", False)),
            derivative=item.get("derivative"), discrete=item.get("variability") == "discrete",
            tunable=item.get("variability") == "tunable", initial=item.get("initial"),
        )
        if var.initial not in (None, "exact") or (var.initial and (causality not in ("output", "local")
                                                                    or var.start is None)):
            raise ModelJsonError(f"{path}: '{name}': 'initial' may only be 'exact', on an output or local with a "
                                 "start value")
        if item.get("variability") not in (None, "discrete", "continuous", "tunable"):
            raise ModelJsonError(f"{path}: '{name}': variability must be 'discrete', 'continuous' or 'tunable'")
        if var.tunable and causality != "parameter":
            raise ModelJsonError(f"{path}: '{name}': only a parameter can be 'tunable'")
        var.starts()  # checks the length
        if var.unit is not None and var.unit not in raw.get("units", {}):
            raise ModelJsonError(f"{path}: '{name}': unit '{var.unit}' is not in 'units'")
        variables.append(var)
        vr2 += var.size
    for v in variables:
        for dep in v.dependencies or ():
            if dep not in names or next(x for x in variables if x.name == dep).causality != "input":
                raise ModelJsonError(f"{path}: '{v.name}' depends on '{dep}', which is not an input")
    interfaces, indicators = _model_exchange_keys(path, raw, variables)
    return Model(
        name=raw["name"], description=raw.get("description", ""), version=str(raw.get("version", "1.0")),
        default_experiment=raw.get("defaultExperiment", {}), units=raw.get("units", {}),
        variables=tuple(variables), digest=digest or hashlib.sha256(Path(path).read_bytes()).hexdigest(),
        interfaces=interfaces, event_indicators=indicators,
        needs_completed_integrator_step=bool(raw.get("needsCompletedIntegratorStep", False)),
        directional_derivatives=bool(raw.get("directionalDerivatives", False)),
    )


def _model_exchange_keys(path: Path, raw: dict, variables: list[ModelVariable]) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Check ``interfaces``, ``derivative`` and ``eventIndicators``; return the interfaces and indicators."""
    interfaces = raw.get("interfaces", ["CoSimulation"])
    if not isinstance(interfaces, list) or not interfaces or any(i not in INTERFACES for i in interfaces):
        raise ModelJsonError(f"{path}: 'interfaces' must be a non-empty list of {', '.join(INTERFACES)}")
    by_name = {v.name: v for v in variables}

    def real_scalar(name: Any) -> bool:
        return name in by_name and by_name[name].type == "Real" and by_name[name].dimension is None

    for v in variables:
        if v.derivative is None:
            continue
        if not real_scalar(v.name) or v.causality != "local":
            raise ModelJsonError(f"{path}: derivative '{v.name}' must be a local Real scalar")
        if not real_scalar(v.derivative) or by_name[v.derivative].causality not in ("output", "local"):
            raise ModelJsonError(f"{path}: '{v.name}': the state '{v.derivative}' must be an output or local Real scalar")
    indicators = raw.get("eventIndicators", [])
    if not isinstance(indicators, list) or not all(real_scalar(n) for n in indicators):
        raise ModelJsonError(f"{path}: 'eventIndicators' must list Real scalar variables")
    if "ModelExchange" not in interfaces and (indicators or any(v.derivative for v in variables)):
        raise ModelJsonError(f"{path}: states and event indicators need \"ModelExchange\" in 'interfaces'")
    return tuple(i for i in INTERFACES if i in interfaces), tuple(indicators)


# -- XML ---------------------------------------------------------------------

def _fmt(value: Any, type_: str) -> str:
    if type_ == "Boolean":
        return "true" if value else "false"
    if type_ == "Integer":
        return str(int(value))
    return repr(float(value))


def _attrs(**kwargs: Any) -> str:
    return "".join(f" {k}={quoteattr(str(v))}" for k, v in kwargs.items() if v is not None)


def _unit_definitions(model: Model) -> list[str]:
    if not model.units:
        return []
    lines = ["  <UnitDefinitions>"]
    for name, base in model.units.items():
        lines.append(f"    <Unit name={quoteattr(name)}>")
        lines.append(f"      <BaseUnit{_attrs(**{k: v for k, v in base.items()})}/>")
        lines.append("    </Unit>")
    lines.append("  </UnitDefinitions>")
    return lines


def _default_experiment(model: Model) -> str:
    d = model.default_experiment
    return f"  <DefaultExperiment{_attrs(startTime=d.get('startTime'), stopTime=d.get('stopTime'), stepSize=d.get('stepSize'))}/>"


LOG_CATEGORIES = ['  <LogCategories>', '    <Category name="logStatusError" description="Errors and bad values"/>',
                  '    <Category name="logEvents" description="Lifecycle messages"/>', '  </LogCategories>']


def _has_start(v: ModelVariable) -> bool:
    # Outputs and locals are "calculated" (FMI forbids a start value for them) unless declared "exact".
    return v.causality in ("parameter", "input") or v.initial == "exact"


def _initial(v: ModelVariable) -> str | None:
    return (v.initial or "calculated") if v.causality in ("output", "local") else None


def _needs_step(model: Model) -> str:
    return "true" if model.needs_completed_integrator_step else "false"


def fmi3_model_description(model: Model, interfaces: tuple[str, ...] | None = None) -> str:
    """The FMI 3.0 modelDescription.xml text for ``model`` offering ``interfaces`` (default: all it supports)."""
    offered = model.offers(interfaces)
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           f'<fmiModelDescription fmiVersion="3.0"{_attrs(modelName=model.name, instantiationToken=model.token, description=model.description, version=model.version, generationTool="cosim fmus.build", variableNamingConvention="structured")}>']
    if "ModelExchange" in offered:
        out.append(f'  <ModelExchange{_attrs(modelIdentifier=model.name)} canGetAndSetFMUState="false"'
                   ' canSerializeFMUState="false" canBeInstantiatedOnlyOncePerProcess="false" needsExecutionTool="false"'
                   f' needsCompletedIntegratorStep="{_needs_step(model)}"{_derivatives(model, 3)}/>')
    if "CoSimulation" in offered:
        out.append(f'  <CoSimulation{_attrs(modelIdentifier=model.name)} canHandleVariableCommunicationStepSize="true"'
                   ' canGetAndSetFMUState="true" canSerializeFMUState="true" canBeInstantiatedOnlyOncePerProcess="false"'
                   f' needsExecutionTool="false" providesIntermediateUpdate="false" hasEventMode="false"{_derivatives(model, 3)}/>')
    out += _unit_definitions(model)
    out += LOG_CATEGORIES
    out.append(_default_experiment(model))
    out.append("  <ModelVariables>")
    time_unit = _attrs(unit="s") if "s" in model.units else ""
    out.append(f'    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"{time_unit} description="Simulation time"/>')
    for v in model.variables:
        tag = FMI3_TYPES[v.type]
        start = " ".join(_fmt(s, v.type) for s in v.starts()) if _has_start(v) else None
        attrs = _attrs(name=v.name, valueReference=v.vr3, description=v.description or None, causality=v.causality,
                       variability=v.variability, initial=_initial(v))
        if v.type == "Real":
            attrs += _attrs(unit=v.unit)
        if v.type != "Boolean":
            attrs += _attrs(min=None if v.min is None else _fmt(v.min, v.type), max=None if v.max is None else _fmt(v.max, v.type))
        attrs += _attrs(start=start)
        if v.derivative and "ModelExchange" in offered:
            attrs += _attrs(derivative=model.by_name()[v.derivative].vr3)
        if v.dimension is None:
            out.append(f"    <{tag}{attrs}/>")
        else:
            out.append(f"    <{tag}{attrs}>")
            out.append(f'      <Dimension start="{v.dimension}"/>')
            out.append(f"    </{tag}>")
    out.append("  </ModelVariables>")
    out.append("  <ModelStructure>")
    by_name = model.by_name()
    for v in model.variables:
        if v.causality == "output":
            deps = None if v.dependencies is None else " ".join(str(by_name[d].vr3) for d in v.dependencies)
            out.append(f"    <Output{_attrs(valueReference=v.vr3, dependencies=deps)}/>")
    me = "ModelExchange" in offered
    states = model.states() if me else []
    for _, derivative in states:
        out.append(f"    <ContinuousStateDerivative{_attrs(valueReference=derivative.vr3)}/>")
    for vr in _initial_unknowns(model, states, lambda v: [v.vr3]):
        out.append(f"    <InitialUnknown{_attrs(valueReference=vr)}/>")
    for name in model.event_indicators if me else ():
        out.append(f"    <EventIndicator{_attrs(valueReference=model.by_name()[name].vr3)}/>")
    out.append("  </ModelStructure>")
    out.append("</fmiModelDescription>")
    return "\n".join(out) + "\n"


def _derivatives(model: Model, version: int) -> str:
    """The interface attribute saying the FMU gives directional derivatives (FMI 2.0 and 3.0 spell it apart)."""
    if not model.directional_derivatives:
        return ""
    return ' providesDirectionalDerivative="true"' if version == 2 else ' providesDirectionalDerivatives="true"'


def fmi2_model_description(model: Model, interfaces: tuple[str, ...] | None = None) -> str:
    """The FMI 2.0 modelDescription.xml text for ``model`` (arrays as scalars) offering ``interfaces``."""
    offered = model.offers(interfaces)
    me = "ModelExchange" in offered
    indicators = _attrs(numberOfEventIndicators=len(model.event_indicators)) if me else ""
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           f'<fmiModelDescription fmiVersion="2.0"{_attrs(modelName=model.name, guid=model.token, description=model.description, version=model.version, generationTool="cosim fmus.build", variableNamingConvention="structured")}{indicators}>']
    if me:
        not_needed = "false" if model.needs_completed_integrator_step else "true"
        out.append(f'  <ModelExchange{_attrs(modelIdentifier=model.name)} completedIntegratorStepNotNeeded="{not_needed}"'
                   ' canGetAndSetFMUstate="false" canSerializeFMUstate="false" canBeInstantiatedOnlyOncePerProcess="false"'
                   f' needsExecutionTool="false" canNotUseMemoryManagementFunctions="true"{_derivatives(model, 2)}/>')
    if "CoSimulation" in offered:
        out.append(f'  <CoSimulation{_attrs(modelIdentifier=model.name)} canHandleVariableCommunicationStepSize="true"'
                   ' canGetAndSetFMUstate="true" canSerializeFMUstate="true" canBeInstantiatedOnlyOncePerProcess="false"'
                   f' needsExecutionTool="false" canNotUseMemoryManagementFunctions="true"{_derivatives(model, 2)}/>')
    out += _unit_definitions(model)
    out += LOG_CATEGORIES
    out.append(_default_experiment(model))
    out.append("  <ModelVariables>")
    time_unit = _attrs(unit="s") if "s" in model.units else ""
    out.append(f'    <ScalarVariable name="time" valueReference="0" causality="independent" variability="continuous" description="Simulation time"><Real{time_unit}/></ScalarVariable>')
    for v in model.variables:
        for i, (element, start) in enumerate(zip(v.element_names(), v.starts())):
            desc = v.description or None
            out.append(f"    <!-- index {v.vr2 + i + 1} -->")
            out.append(f"    <ScalarVariable{_attrs(name=element, valueReference=v.vr2 + i, description=desc, causality=v.causality, variability=v.variability, initial=_initial(v))}>")
            inner = ""
            if v.type == "Real":
                inner += _attrs(unit=v.unit)
            if v.type != "Boolean":
                inner += _attrs(min=None if v.min is None else _fmt(v.min, v.type), max=None if v.max is None else _fmt(v.max, v.type))
            if _has_start(v):
                inner += _attrs(start=_fmt(start, v.type))
            if v.derivative and me:
                inner += _attrs(derivative=model.by_name()[v.derivative].vr2 + 1)
            out.append(f"      <{v.type}{inner}/>")
            out.append("    </ScalarVariable>")
    out.append("  </ModelVariables>")
    out.append("  <ModelStructure>")
    by_name = model.by_name()
    outputs = [v for v in model.variables if v.causality == "output"]
    states = model.states() if me else []
    if outputs:
        out.append("    <Outputs>")
        for v in outputs:
            for i in range(v.size):
                if v.dependencies is None:
                    deps = None
                else:
                    indices: list[int] = []
                    for d in v.dependencies:
                        dv = by_name[d]
                        if v.elementwise and dv.size == v.size:
                            indices.append(dv.vr2 + i + 1)
                        else:
                            indices.extend(dv.vr2 + j + 1 for j in range(dv.size))
                    deps = " ".join(str(x) for x in sorted(indices))
                out.append(f"      <Unknown{_attrs(index=v.vr2 + i + 1, dependencies=deps)}/>")
        out.append("    </Outputs>")
    if states:
        out.append("    <Derivatives>")
        for _, derivative in states:
            out.append(f"      <Unknown index=\"{derivative.vr2 + 1}\"/>")
        out.append("    </Derivatives>")
    initial = _initial_unknowns(model, states, lambda v: [v.vr2 + i + 1 for i in range(v.size)])
    if initial:
        out.append("    <InitialUnknowns>")
        for index in initial:
            out.append(f"      <Unknown index=\"{index}\"/>")
        out.append("    </InitialUnknowns>")
    out.append("  </ModelStructure>")
    out.append("</fmiModelDescription>")
    return "\n".join(out) + "\n"


def _initial_unknowns(model: Model, states: list[tuple[ModelVariable, ModelVariable]], refs) -> list[int]:
    """Sorted indices/VRs (``refs(variable)``) of the initial unknowns: outputs, states and derivatives.

    Every output, state and derivative of our models is ``initial="calculated"`` unless declared ``exact``,
    so FMI 2.0 and 3.0 both require all the calculated ones in this list (and none of the exact ones).
    """
    chosen = [v for v in model.variables if v.causality == "output" and v.initial != "exact"]
    chosen += [s for s, _ in states if s.causality != "output" and s.initial != "exact"] + [d for _, d in states]
    return sorted({r for v in chosen for r in refs(v)})


# -- C -----------------------------------------------------------------------

def generated_header(model: Model, interfaces: tuple[str, ...] | None = None) -> str:
    """``model_generated.h``: the ModelData struct, value-reference constants and what the build offers."""
    offered = model.offers(interfaces)
    up = lambda v: v.name.upper()  # noqa: E731
    lines = ["/* Generated by fmus/model_description.py from model.json -- do not edit. */",
             "#ifndef MODEL_GENERATED_H", "#define MODEL_GENERATED_H", "#include <stdbool.h>", "#include <stdint.h>", "",
             f'#define MODEL_IDENTIFIER "{model.name}"', f'#define INSTANTIATION_TOKEN "{model.token}"',
             f"#define N_VARIABLES {len(model.variables) + 1}  /* including time */",
             f"#define N_SCALARS {model.n_scalars}  /* FMI 2.0 value references 0 .. N_SCALARS-1 */",
             f"#define N_STATES {len(model.states())}  /* Model Exchange: continuous states */",
             f"#define N_EVENT_INDICATORS {len(model.event_indicators)}",
             f"#define HAS_CO_SIMULATION {int('CoSimulation' in offered)}  /* interfaces this build offers */",
             f"#define HAS_MODEL_EXCHANGE {int('ModelExchange' in offered)}",
             f"#define PROVIDES_DIRECTIONAL_DERIVATIVE {int(model.directional_derivatives)}  /* model_partial */", ""]
    for v in model.variables:
        lines.append(f"#define VR_{up(v)} {v.vr3}  /* FMI 3.0 */")
        lines.append(f"#define VR2_{up(v)} {v.vr2}  /* FMI 2.0: {v.element_names()[0]}; element i (1-based) is VR2_{up(v)} + i - 1 */")
        if v.dimension is not None:
            lines.append(f"#define N_{up(v)} {v.dimension}")
    lines += ["", "/* Every variable of the model; the model code reads and writes these fields. */", "typedef struct {"]
    for v in model.variables:
        dim = f"[{v.dimension}]" if v.dimension is not None else ""
        lines.append(f"    {C_TYPES[v.type]} {v.name}{dim};  /* {v.causality}{', ' + v.unit if v.unit else ''} */")
    if not model.variables:
        lines.append("    int unused;")
    lines += ["} ModelData;", "", "#endif", ""]
    return "\n".join(lines)


def generated_source(model: Model) -> str:
    """``model_generated.c``: variable table, VR-2 lookup and setStartValues."""
    lines = ["/* Generated by fmus/model_description.py from model.json -- do not edit. */",
             '#include <stddef.h>', '#include "framework.h"', "",
             "const VariableInfo VARIABLES[N_VARIABLES] = {",
             '    {"time", VT_REAL, CAUS_INDEPENDENT, 1, 0, 0, false, false},']
    for v in model.variables:
        lines.append(f'    {{"{v.name}", {TYPE_CODES[v.type]}, {CAUSALITY_CODES[v.causality]}, {v.size}, '
                     f"offsetof(ModelData, {v.name}), {v.vr2}, {'true' if v.tunable else 'false'}, "
                     f"{'true' if v.initial == 'exact' else 'false'}}},")
    lines += ["};", "", "/* FMI 2.0 value reference -> index into VARIABLES (element = vr - VARIABLES[i].vr2). */",
              "const uint16_t VR2_VARIABLE[N_SCALARS] = {"]
    owners = [0] + [k for k, v in enumerate(model.variables, start=1) for _ in range(v.size)]
    lines.append("    " + ", ".join(str(o) for o in owners))
    lines += ["};", "", "void setStartValues(ModelData *d) {"]
    for v in model.variables:
        start = v.starts()
        c = (lambda s: ("true" if s else "false")) if v.type == "Boolean" else (
            (lambda s: str(int(s))) if v.type == "Integer" else (lambda s: repr(float(s))))
        if v.dimension is None:
            lines.append(f"    d->{v.name} = {c(start[0])};")
        else:
            for i, s in enumerate(start):
                lines.append(f"    d->{v.name}[{i}] = {c(s)};")
    lines += ["}", ""]
    return "\n".join(lines + _model_exchange_source(model))


def _model_exchange_source(model: Model) -> list[str]:
    """Offsets of states, derivatives and indicators, and defaults of the model functions it does not supply."""
    def offsets(name: str, variables: list[str]) -> str:
        items = ", ".join(f"offsetof(ModelData, {v})" for v in variables) or "0"
        return f"const size_t {name}[] = {{{items}}};"

    states = model.states()
    lines = ["/* Model Exchange (see model_exchange.h). */", '#include "model_exchange.h"',
             offsets("STATE_OFFSETS", [s.name for s, _ in states]),
             offsets("DERIVATIVE_OFFSETS", [d.name for _, d in states]),
             offsets("EVENT_INDICATOR_OFFSETS", list(model.event_indicators)), ""]
    if "ModelExchange" not in model.interfaces:  # a co-simulation-only model.c has no events
        lines += ["Status model_event_update(ModelInstance *comp, EventInfo *info) {",
                  "    (void)comp; (void)info;", "    return OK;", "}",
                  "bool model_step_event(ModelInstance *comp) {", "    (void)comp;", "    return false;", "}", ""]
    if "CoSimulation" not in model.interfaces:  # a Model-Exchange-only model.c has no doStep
        lines += ["Status model_do_step(ModelInstance *comp, double t, double h) {", "    (void)t; (void)h;",
                  '    logError(comp, "this model supports Model Exchange only");', "    return Error;", "}", ""]
    return lines
