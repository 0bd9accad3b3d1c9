"""``cosim export-surrogate``: the surrogates of ``DIR/surrogate/models.json`` as an FMI co-simulation FMU in C.

The FMU's parameters are the design parameters (tunable, start at the centre of the fitted box, min/max the box),
its outputs each objective's prediction ``OBJ`` and standard deviation ``OBJ_std`` (names made identifiers:
``peak_tau_ratio[2]`` -> ``peak_tau_ratio_2``); no Python at run time.  The model is generated into a folder of
its own (``model.json``; ``model.c`` with the numbers as exact hexadecimal C literals) and built with the
framework of ``cosim/fmus/common`` and the evaluator ``cosim/fmus/surrogate/surrogate.c``, like our other FMUs.

The outputs depend on the parameters only: they are evaluated when a parameter changed since the last
evaluation (local ``evaluations`` counts them), so a step costs a comparison per parameter.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Any, Mapping

from cosim.errors import AnalysisError
from cosim.fmus.build import FMUS_DIR, build_model_folder
from cosim.spec.expressions import identifier

EVALUATOR = FMUS_DIR / "surrogate" / "surrogate.c"
MODEL_NAME = "surrogate"
MAX_PARAMETERS = 64  # surrogate.c's fixed buffer


def output_names(objective: str) -> tuple[str, str]:
    """The FMU's output names of one objective: (prediction, standard deviation)."""
    name = identifier(objective)
    return name, f"{name}_std"


def parameter_name(parameter: str) -> str:
    """The FMU's parameter name of one design parameter."""
    return identifier(parameter)


def export_surrogate_fmu(models: Mapping[str, Any], out: str | Path, objectives: list[str] | None = None,
                         fmi_version: int = 2) -> Path:
    """Build the FMU of the surrogates in ``models`` (the dict of ``models.json``) at ``out``.

    ``objectives`` chooses some (default: all).  Raises AnalysisError for an unknown objective, names that
    collide once made identifiers, or more than 64 parameters; FmuBuildError when gcc fails.
    """
    parameters = list(models["parameters"])
    chosen = objectives or list(models["objectives"])
    unknown = [o for o in chosen if o not in models["objectives"]]
    if unknown:
        raise AnalysisError(f"--objective {unknown[0]}: no surrogate of it (there: "
                            f"{', '.join(models['objectives'])}); fit it with `cosim surrogate DIR --objective ...`")
    if len(parameters) > MAX_PARAMETERS:
        raise AnalysisError(f"{len(parameters)} design parameters: the surrogate FMU takes at most {MAX_PARAMETERS}")
    names = [parameter_name(p) for p in parameters] + [n for o in chosen for n in output_names(o)]
    clash = sorted({n for n in names if names.count(n) > 1 or n in ("evaluations", "time")
                    or n.startswith("evaluated_at_")})
    if clash:
        raise AnalysisError(f"the FMU's variable name '{clash[0]}' would stand for two columns (or a name the "
                            "FMU uses itself); rename the column in the study")
    with tempfile.TemporaryDirectory(prefix="cosim-surrogate-") as tmp:
        folder = Path(tmp) / MODEL_NAME
        folder.mkdir()
        (folder / "model.json").write_text(json.dumps(model_json(models, chosen), indent=1))
        (folder / "model.c").write_text(model_c(models, chosen))
        return build_model_folder(folder, fmi_version, Path(out), ("CoSimulation",), extra_sources=(EVALUATOR,))


def model_json(models: Mapping[str, Any], objectives: list[str]) -> dict[str, Any]:
    """The ``model.json`` of the FMU (see cosim/fmus/README.md for the form)."""
    variables = []
    first = models["objectives"][objectives[0]]["model"]["scaling"]
    for j, p in enumerate(models["parameters"]):
        low, span = float(first["low"][j]), float(first["span"][j])
        variables.append({"name": parameter_name(p), "causality": "parameter", "variability": "tunable",
                          "type": "Real", "start": low + span / 2, "min": low, "max": low + span,
                          "description": f"design parameter {p} (the surrogates were fitted over "
                                         f"[{low:.6g}, {low + span:.6g}])"})
    for o in objectives:
        entry = models["objectives"][o]
        mean, std = output_names(o)
        variables.append({"name": mean, "causality": "output", "type": "Real", "dependencies": [],
                          "description": f"predicted {o} ({entry['candidate']}, 5-fold Q2 {entry['q2']:.4f})"})
        variables.append({"name": std, "causality": "output", "type": "Real", "dependencies": [],
                          "description": f"standard deviation of the prediction of {o}"})
    variables.append({"name": "evaluations", "causality": "local", "type": "Real", "start": 0.0,
                      "description": "how often the surrogates were evaluated (once per change of a parameter)"})
    for p in models["parameters"]:
        variables.append({"name": f"evaluated_at_{parameter_name(p)}", "causality": "local", "type": "Real",
                          "start": 0.0, "description": f"{p} at the last evaluation"})
    return {"name": MODEL_NAME, "version": "1.0",
            "description": f"surrogates of {', '.join(objectives)} fitted by cosim surrogate on "
                           f"{models.get('source') or 'a study'}",
            "defaultExperiment": {"startTime": 0, "stopTime": 1, "stepSize": 0.01},
            "units": {"s": {"s": 1}}, "variables": variables}


def _doubles(values: Any) -> str:
    """Exact C literals (hexadecimal floating point: no rounding in print or parse)."""
    flat = _flatten(values)
    return "{" + ", ".join(float(v).hex() for v in flat) + "}" if flat else "{0.0}"


def _ints(values: Any) -> str:
    flat = _flatten(values)
    return "{" + ", ".join(str(int(v)) for v in flat) + "}" if flat else "{0}"


def _flatten(values: Any) -> list[Any]:
    if isinstance(values, (list, tuple)):
        return [x for v in values for x in _flatten(v)]
    return [values]


SHAPES = {"matern32": "SHAPE_MATERN32", "matern52": "SHAPE_MATERN52", "rbf": "SHAPE_RBF"}


def model_c(models: Mapping[str, Any], objectives: list[str]) -> str:
    """The generated ``model.c``: the numbers of each surrogate and the four model functions."""
    parameters = [parameter_name(p) for p in models["parameters"]]
    d = len(parameters)
    lines = ["/* Generated by cosim export-surrogate: the surrogates of models.json as constants. */",
             '#include "framework.h"', '#include "surrogate.h"', ""]
    structs, work = [], 1
    for k, o in enumerate(objectives):
        m = models["objectives"][o]["model"]
        scaling = m["scaling"]
        lines += [f"static const double LOW_{k}[] = {_doubles(scaling['low'])};",
                  f"static const double SPAN_{k}[] = {_doubles(scaling['span'])};"]
        common = (f".n_params = {d}, .low = LOW_{k}, .span = SPAN_{k}, .y_mean = {float(scaling['y_mean']).hex()}, "
                  f".y_scale = {float(scaling['y_scale']).hex()}")
        if m["kind"] == "gp":
            n = len(m["alpha"])
            work = max(work, 2 * n)
            lines += [f"static const double LENGTH_{k}[] = {_doubles(m['length_scales'])};",
                      f"static const double XTRAIN_{k}[] = {_doubles(m['x_train'])};",
                      f"static const double ALPHA_{k}[] = {_doubles(m['alpha'])};",
                      f"static const double CHOLESKY_{k}[] = {_doubles(m['cholesky'])};"]
            structs.append(f"    {{.kind = SURROGATE_GP, {common}, .shape = {SHAPES[m['shape']]}, "
                           f".constant = {float(m['constant']).hex()}, .noise = {float(m['noise']).hex()}, "
                           f".length_scales = LENGTH_{k}, .n_train = {n}, .x_train = XTRAIN_{k}, .alpha = ALPHA_{k}, "
                           f".cholesky = CHOLESKY_{k}}}")
        elif m["kind"] == "poly":
            lines += [f"static const int POWERS_{k}[] = {_ints(m['powers'])};",
                      f"static const double COEFFICIENTS_{k}[] = {_doubles(m['coefficients'])};"]
            structs.append(f"    {{.kind = SURROGATE_POLY, {common}, .n_terms = {len(m['coefficients'])}, "
                           f".powers = POWERS_{k}, .coefficients = COEFFICIENTS_{k}, "
                           f".intercept = {float(m['intercept']).hex()}, .error = {float(m['error']).hex()}}}")
        else:
            raise AnalysisError(f"{o}: a surrogate of kind {m['kind']!r} cannot be exported (gp, poly can)")
    lines += [f"#define N_OBJECTIVES {len(objectives)}", f"#define WORK {work}",
              "static const Surrogate SURROGATES[N_OBJECTIVES] = {", ",\n".join(structs), "};", ""]
    x = ", ".join(f"d->{p}" for p in parameters)
    same = " && ".join(f"x[{j}] == d->evaluated_at_{p}" for j, p in enumerate(parameters))
    outputs = "\n".join(f"    surrogate_predict(&SURROGATES[{k}], x, work, &d->{output_names(o)[0]}, "
                        f"&d->{output_names(o)[1]});" for k, o in enumerate(objectives))
    remember = "\n".join(f"    d->evaluated_at_{p} = x[{j}];" for j, p in enumerate(parameters))
    checks = "\n".join(f'    if (check_finite(comp, "{p}", SCALAR, d->{p}) > Warning) return Error;'
                       for p in parameters)
    lines += ["Status model_validate(ModelInstance *comp) {", "    ModelData *d = &comp->d;", checks, "    return OK;",
              "}", "", "void model_initialize(ModelInstance *comp) { (void)comp; }", "",
              "/* The outputs depend on the parameters only: evaluated again only when one of them changed. */",
              "Status model_calculate(ModelInstance *comp) {", "    ModelData *d = &comp->d;",
              f"    const double x[{d}] = {{{x}}};", "    double work[WORK];",
              f"    if (d->evaluations > 0 && {same}) return OK;", checks, outputs, remember,
              "    d->evaluations += 1;", "    return OK;", "}", "",
              "Status model_do_step(ModelInstance *comp, double t, double h) {",
              "    (void)t;", "    (void)h;", "    return model_calculate(comp);", "}", ""]
    return "\n".join(lines)
