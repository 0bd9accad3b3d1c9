"""The ``fmu`` unit kind: an FMI 2.0 or 3.0 FMU, co-simulation or model exchange, from a path, a member of an
SSP archive or ``builtin:NAME_fmiN`` (an FMU cosim builds from its own C sources on first use)."""

from __future__ import annotations

import re
from pathlib import Path

from cosim.errors import FmuProblems, Problem
from cosim.units.fmu.description import FmuUnitType
from cosim.units.kind import UnitKind, UnitSpec
from cosim.util.archive import member_file

BUILTIN_PREFIX = "builtin:"


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
        return member_file(reference)
    path = Path(reference)
    if not path.is_absolute() and base_dir is not None:
        path = Path(base_dir) / path
    return path


def _built_in_fmu(reference: str) -> Path:
    # deferred: the builder (and numpy under it) is imported only when a built-in FMU is asked for
    from cosim.fmus.build import FmuBuildError, available_models, ensure_built

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


def _create_fmu(spec: UnitSpec, folder: str) -> FmuUnitType:
    # whole-number parameters may be structural parameters that size FMI 3.0 arrays: the description needs them
    structural = {spec.ports.get(k, k): v for k, v in spec.parameters.items()
                  if isinstance(v, int) and not isinstance(v, bool)}
    settings = None
    if "tolerance" in spec.options or "max_step" in spec.options:  # the model-exchange solver (units/model_exchange)
        # deferred: model exchange imports fmpy's model classes (~0.13 s), for units that ask for its solver only
        from cosim.units.fmu.model_exchange import SolverSettings

        settings = SolverSettings(**{k: spec.options[k] for k in ("tolerance", "max_step") if k in spec.options})
    return FmuUnitType(resolve_fmu_path(spec.source, folder), reference=spec.source, structural=structural,
                       interface=spec.options.get("interface"), solver_settings=settings)


KIND = UnitKind("fmu", {
    "fmu": {"type": "string", "description": "Path to an .fmu (relative to the spec's folder) or "
                                             "'builtin:NAME_fmi3' / 'builtin:NAME_fmi2'."},
    "interface": {"enum": ["co-simulation", "model-exchange"],
                  "description": "fmu only: how the FMU runs. Default: co-simulation when the FMU offers it, else "
                                 "model exchange (integrated by cosim with CVode inside each step)."},
    "tolerance": {"type": "number", "exclusiveMinimum": 0, "exclusiveMaximum": 1,
                  "description": "fmu, model exchange only: relative tolerance of the solver (CVode; absolute "
                                 "tolerance = tolerance x nominal). Default 1e-8."},
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
