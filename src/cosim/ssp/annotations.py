"""Tool annotations of an SSD that map onto cosim's settings: OMSimulator's solvers, OSP's step hints.

OMSimulator 3 defines solvers on a system and assigns them to components by name::

    <ssc:Annotation type="org.openmodelica"><oms:Annotations>
      <oms:SimulationInformation name="s1" method="oms_ma" fixedStepSize="0.01"/>     (on a system: a definition)
      <oms:SimulationInformation name="s2" method="cvode" relativeTolerance="1e-4" maximumStepSize="0.001"/>
    </oms:Annotations></ssc:Annotation>
    <oms:SimulationInformation name="s2"/>                                             (on a component: its solver)

OMSimulator 2 wrote ``oms:FixedStepMaster stepSize`` (the step, read by the reader's experiment) and
``oms:VariableStepSolver description="cvode" relativeTolerance maximumStepSize`` on the system whose
model-exchange components it integrates.  What maps onto cosim:

- ``oms_ma`` ``fixedStepSize``: the communication step (the smallest, if several);
- ``cvode`` ``relativeTolerance`` (or ``tolerance``) and ``maximumStepSize``: the unit's ``tolerance`` and
  ``max_step``; a component assigned ``cvode`` or ``euler`` runs as model exchange.

The rest is reported once per SSP by :func:`solver_notes` (what cosim does instead).  Namespaces of
the tools' own elements vary between versions, so elements are matched by local name.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from cosim.errors import AnnotationNumberError
from cosim.ssp.xml import tag

READ_TYPES = ("org.openmodelica", "com.opensimulationplatform", "org.cosim")
# a unit's cosim options an SSP has no place for, on its component's org.cosim annotation (cosim.export.ssp)
COSIM_UNIT_OPTIONS = ("record_events", "coupled_model_exchange")
_ME_METHODS = ("cvode", "euler")
_VARIABLE_MASTERS = ("oms_mav", "oms_mav2")
_UNREAD_KEYS = ("initialStepSize", "minimumStepSize", "absoluteTolerance")
_NUMBERS = ("fixedStepSize", "relativeTolerance", "tolerance", "maximumStepSize", "stepSize", "baseStepSize", "value")


def number(element: Any, attribute: str) -> float | None:
    """The attribute as a positive finite number, None when absent; raises AnnotationNumberError otherwise."""
    text = element.get(attribute)
    if text is None:
        return None
    try:
        value = float(text)
    except ValueError:
        raise AnnotationNumberError(element, attribute) from None
    if not (0 < value < float("inf")):
        raise AnnotationNumberError(element, attribute)
    return value


def _check_numbers(element: Any) -> None:
    for attribute in _NUMBERS:
        number(element, attribute)


def _local(element: Any) -> str:
    return element.tag.split("}")[-1] if isinstance(element.tag, str) else ""


def own_annotations(element: Any, annotation_type: str) -> list[Any]:
    """The ``ssc:Annotation`` elements of ``type`` directly under ``element``'s ``ssd:Annotations``."""
    container = element.find(tag("ssd", "Annotations"))
    if container is None:
        return []
    return [a for a in container.findall(tag("ssc", "Annotation")) if a.get("type") == annotation_type]


def _simulation_information(element: Any) -> list[Any]:
    """``oms:SimulationInformation`` elements of an element's OMSimulator annotation (wrapped in
    ``oms:Annotations`` or, in the oldest files, directly under ``ssc:Annotation``)."""
    found = []
    for annotation in own_annotations(element, "org.openmodelica"):
        for child in annotation.iter():
            if _local(child) == "SimulationInformation":
                found.append(child)
    return found


@dataclass
class Solvers:
    """The solver settings an SSD's annotations give, and what they give that cosim does not use."""

    definitions: dict[str, dict[str, str]] = field(default_factory=dict)  # OMS3 name -> attributes
    steps: list[float] = field(default_factory=list)  # oms_ma fixedStepSize values
    system_cvode: dict[tuple[str, ...], dict[str, str]] = field(default_factory=dict)  # OMS2, by system path
    unused: set[str] = field(default_factory=set)  # notes: what is not read


def read_system_solvers(system: Any, path: tuple[str, ...], solvers: Solvers) -> None:
    """Collect the solver definitions on one ``ssd:System`` (OMSimulator 3 and 2 forms) into ``solvers``.

    Raises AnnotationNumberError for a setting cosim reads that is no positive number.
    """
    for info in _simulation_information(system):
        _check_numbers(info)
        for child in info:
            if isinstance(child.tag, str):
                _check_numbers(child)
        name, method = info.get("name"), info.get("method")
        if name and method:  # OMSimulator 3: a definition
            solvers.definitions[name] = dict(info.attrib)
            if method == "oms_ma" and info.get("fixedStepSize"):
                solvers.steps.append(float(info.get("fixedStepSize")))
            elif method in _VARIABLE_MASTERS:
                solvers.unused.add(f"solver '{name}' is OMSimulator's variable-step master {method}: cosim steps "
                                   "with one fixed communication step (the SSP's or --step)")
            elif method == "euler":
                solvers.unused.add(f"solver '{name}' is explicit Euler: CVode integrates its model-exchange "
                                   "components instead")
            elif method not in ("oms_ma", "cvode"):
                solvers.unused.add(f"solver '{name}' uses method '{method}', which cosim does not know: ignored")
            _note_unread_keys(info, name, solvers)
        for child in info:
            local = _local(child)
            if local == "VariableStepSolver":  # OMSimulator 2, on the system of its model-exchange components
                if child.get("description") == "cvode":
                    solvers.system_cvode[path] = dict(child.attrib)
                    _note_unread_keys(child, f"{'.'.join(path) or 'root'} cvode", solvers)
                else:
                    solvers.unused.add(f"OMSimulator solver '{child.get('description')}' of system "
                                       f"'{'.'.join(path) or 'root'}': CVode integrates its model-exchange "
                                       "components instead")
            elif local == "VariableStepMaster":
                solvers.unused.add(f"OMSimulator's variable-step master of system '{'.'.join(path) or 'root'}': "
                                   "cosim steps with one fixed communication step (the SSP's or --step)")
            elif local == "FixedStepSolver":
                solvers.unused.add(f"OMSimulator's FixedStepSolver of system '{'.'.join(path) or 'root'}' is "
                                   "not read: CVode integrates model-exchange components")


def _note_unread_keys(info: Any, name: str, solvers: Solvers) -> None:
    unread = [k for k in _UNREAD_KEYS if info.get(k) is not None]
    if unread:
        solvers.unused.add(f"solver '{name}': {', '.join(unread)} not read (cosim's CVode takes a relative "
                           "tolerance and a maximum step)")


def component_solver(component: Any) -> str | None:
    """The name of the OMSimulator 3 solver assigned to a component, if any."""
    for info in _simulation_information(component):
        if info.get("name") and not info.get("method"):
            return info.get("name")
    return None


def step_size_hint(component: Any) -> float | None:
    """OSP's ``osp:StepSizeHint value`` on a component, if any; raises AnnotationNumberError."""
    for annotation in own_annotations(component, "com.opensimulationplatform"):
        for child in annotation.iter():
            if _local(child) == "StepSizeHint" and child.get("value"):
                return number(child, "value")
    return None


def json_scalar(text: str) -> Any:
    """An attribute's text as the JSON value it was written from: Boolean, integer, number or string."""
    if text in ("true", "false"):
        return text == "true"
    if re.fullmatch(r"[+-]?\d+", text):
        return int(text)
    try:
        return float(text)
    except ValueError:
        return text


def cosim_unit_options(component: Any) -> dict[str, Any]:
    """A unit's own cosim options (:data:`COSIM_UNIT_OPTIONS`) from its component's ``org.cosim`` annotation,
    ``<cosim:Unit record_events="true"/>`` as :mod:`cosim.export.ssp` writes it; their form is the spec's,
    checked with it."""
    options: dict[str, Any] = {}
    for annotation in own_annotations(component, "org.cosim"):
        for child in annotation:
            if _local(child) == "Unit":
                options.update({k: json_scalar(v) for k, v in child.attrib.items() if k in COSIM_UNIT_OPTIONS})
    return options


def cvode_settings(attributes: dict[str, str]) -> dict[str, float]:
    """cosim's ``tolerance`` and ``max_step`` from an OMSimulator cvode solver's attributes."""
    settings = {}
    tolerance = attributes.get("relativeTolerance") or attributes.get("tolerance")
    if tolerance:
        settings["tolerance"] = float(tolerance)
    if attributes.get("maximumStepSize"):
        settings["max_step"] = float(attributes["maximumStepSize"])
    return settings


def unread_annotation_types(root: Any) -> list[str]:
    """The ``ssc:Annotation`` types in an SSD that cosim does not read, each once, in document order."""
    seen: list[str] = []
    for annotation in root.iter(tag("ssc", "Annotation")):
        kind = annotation.get("type")
        if kind and kind not in READ_TYPES and kind not in seen:
            seen.append(kind)
    return seen
