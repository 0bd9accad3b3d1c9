"""The experiment an SSP gives: ``ssd:DefaultExperiment`` start and stop, the step size from OMSimulator's
``FixedStepMaster`` or ``oms_ma`` solvers or OSP's ``FixedStepAlgorithm``, cosim's own master algorithm and
experiment options (its ``org.cosim`` annotation); and one note per kind of tool annotation cosim does not use."""

from __future__ import annotations

from typing import Any

from cosim.errors import AnnotationNumberError
from cosim.master.registry import ALGORITHMS
from cosim.ssp.annotations import json_scalar, number, unread_annotation_types
from cosim.ssp.reading import Reading, log_once
from cosim.ssp.xml import tag

# cosim's experiment settings an SSP has no place for, in its org.cosim annotation (cosim.export.ssp writes them):
# flags as attributes of cosim:Experiment, option groups as its children
COSIM_EXPERIMENT_FLAGS = ("coupled_model_exchange", "early_stop", "warm_start")
COSIM_EXPERIMENT_GROUPS = ("adaptive", "loop_solver")

# What OMSimulator runs an SSP with when it gives no ssd:DefaultExperiment and no step size: its command-line
# flags' defaults --startTime 0, --stopTime 1, --stepSize 1e-3 (src/OMSimulatorLib/Flags.h), which Model.cpp
# also takes for a DefaultExperiment without startTime/stopTime and System.cpp for a system's step size
OMSIMULATOR_DEFAULTS = {"start": 0.0, "stop": 1.0, "step": 1e-3}


def with_tool_defaults(experiment: dict, given: str) -> dict:
    """``experiment`` with the stop time and step size it lacks taken from :data:`OMSIMULATOR_DEFAULTS`, as
    OMSimulator runs such an SSP, and one note (logged once per SSP ``given``) naming the values and the
    options that change them; ``experiment`` itself (a new dict) when it lacks neither."""
    missing = [k for k in ("stop", "step") if k not in experiment]
    if not missing:
        return dict(experiment)
    filled = {**experiment, **{k: OMSIMULATOR_DEFAULTS[k] for k in missing}}
    what = {"stop": "stop time (ssd:DefaultExperiment stopTime)",
            "step": "step size (OMSimulator FixedStepMaster or oms_ma fixedStepSize, OSP FixedStepAlgorithm)"}
    values = ", ".join(f"{k} {OMSIMULATOR_DEFAULTS[k]:g} s" for k in missing)
    log_once(given, f"the SSP gives no {' and no '.join(what[k] for k in missing)}: run with OMSimulator's "
                    f"defaults, {values}; {' / '.join('--' + k for k in missing)} (or a spec's \"experiment\") "
                    "change them")
    return filled


def read_experiment(reading: Reading, root: Any) -> dict:
    """The spec's ``experiment`` from the SSD ``root``: what it gives of start, stop, step and algorithm.

    No note for a missing stop time or step size: the spec or the command line may give them, and
    :func:`with_tool_defaults` fills in OMSimulator's when neither does.
    """
    experiment: dict[str, Any] = {}
    default = root.find(tag("ssd", "DefaultExperiment"))
    if default is not None:
        if default.get("startTime") is not None:
            experiment["start"] = float(default.get("startTime"))
        if default.get("stopTime") is not None:
            experiment["stop"] = float(default.get("stopTime"))
    step = None
    for element in root.iter():
        if not isinstance(element.tag, str):
            continue
        local = element.tag.split("}")[-1]
        try:
            if local == "FixedStepMaster" and element.get("stepSize"):
                step = number(element, "stepSize")  # OMSimulator
            elif local == "FixedStepAlgorithm" and (element.get("baseStepSize") or element.get("stepSize")):
                step = number(element, "baseStepSize" if element.get("baseStepSize") else "stepSize")  # OSP
        except AnnotationNumberError as exc:
            reading.bad_number(exc)
            break
        if step is not None:
            break
    steps = reading.solvers.steps
    if step is None and steps:  # OMSimulator 3: oms_ma solvers' fixedStepSize
        step = min(steps)
        if len(set(steps)) > 1:
            reading.note(f"OMSimulator solvers give several steps ({', '.join(f'{s:g}' for s in steps)}"
                         f"): cosim steps every unit with the smallest, {step:g} s")
    if step is not None:
        experiment["step"] = step
    for annotation in root.iter(tag("ssc", "Annotation")):
        if annotation.get("type") == "org.cosim":  # written by cosim export: its master algorithm and options
            for child in annotation:
                if isinstance(child.tag, str) and child.get("algorithm") in ALGORITHMS:
                    experiment.update(_cosim_experiment(child))
    return experiment


def _cosim_experiment(element: Any) -> dict:
    """The experiment settings of a ``cosim:Experiment`` (as :mod:`cosim.export.ssp` writes them): the algorithm,
    the flags among its attributes, one option group per child.  Their form is the spec's, checked with it."""
    experiment: dict[str, Any] = {"algorithm": element.get("algorithm")}
    for flag in COSIM_EXPERIMENT_FLAGS:
        if element.get(flag) is not None:
            experiment[flag] = json_scalar(element.get(flag))
    for child in element:
        local = child.tag.split("}")[-1] if isinstance(child.tag, str) else ""
        if local in COSIM_EXPERIMENT_GROUPS:
            experiment[local] = {key: json_scalar(value) for key, value in child.attrib.items()}
    return experiment


def note_unread(reading: Reading, root: Any) -> None:
    """One note per kind of annotation content cosim does not use."""
    for text in sorted(reading.solvers.unused):
        reading.note(text)
    if reading.hints:
        reading.note(f"OSP step size hints ignored ({', '.join(reading.hints)}): cosim steps every unit with one "
                     "communication step")
    for kind in unread_annotation_types(root):
        reading.note(f"annotations of type '{kind}' are not read")
