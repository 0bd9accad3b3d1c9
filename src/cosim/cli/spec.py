"""``cosim validate``, ``cosim run`` and ``cosim inspect``: one spec (or one FMU) at a time."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from cosim.cli.exit_codes import EXIT_OK, run_exit_code
from cosim.cli.options import add_experiment_options, experiment_overrides
from cosim.errors import UsageError


def add_variant_option(p: argparse.ArgumentParser) -> None:
    """``--variant NAME``: which of an SSP's SSDs (variants) to read."""
    p.add_argument("--variant", metavar="NAME",
                   help="an SSP's variant: one of its SSDs, by its name (cosim inspect lists them); default "
                        "SystemStructure.ssd")


#: the studies `cosim validate --for` checks a spec's design for
STUDIES = ("sweep", "optimize", "sensitivity")


def add_parsers(sub: Any) -> None:
    """Register validate, run and inspect on the ``cosim`` subparsers ``sub``."""
    p = sub.add_parser("validate", help="check a spec and report every problem at once")
    p.add_argument("spec", help="path to spec.json, or an SSP (.ssp, .ssd, or a folder with SystemStructure.ssd)")
    p.add_argument("--for", dest="study", choices=STUDIES,
                   help="check the design for this study: sweep (a grid's ranges need a step), optimize or "
                        "sensitivity (ranges {min, max} are continuous; the optimize section, its objectives and "
                        "constraints are checked). Default: optimize when the spec has an 'optimize' section, "
                        "else sweep")
    add_experiment_options(p)
    add_variant_option(p)
    p.set_defaults(handler=cmd_validate)

    p = sub.add_parser("run", help="run one point of a spec and print its objectives")
    p.add_argument("spec", help="path to spec.json, or an SSP (.ssp, .ssd, or a folder with SystemStructure.ssd)")
    add_experiment_options(p)
    add_variant_option(p)
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="UNIT.PARAM=VALUE",
                   help="set a parameter (VALUE as JSON: 2.5, true, [1,2,3]); repeatable")
    p.add_argument("--input", metavar="TABLE", help="an FMU run alone: play this .csv/.parquet table (a 'time' "
                   "column, one column per input) into the FMU's inputs")
    p.add_argument("--out", help="write the recorded signals to this .parquet or .csv file")
    p.add_argument("--point", metavar="ID", help="re-run this design point of a sweep, recording every output")
    p.add_argument("--results", help="the sweep's results.parquet or folder for --point (default: results/<name>/)")
    p.set_defaults(handler=cmd_run)

    p = sub.add_parser("inspect", help="list the ports of an FMU, a Python unit, a recorded table, or a spec's "
                                       "(or an SSP's) units")
    p.add_argument("target", help="spec.json, an SSP (.ssp, .ssd, or a folder with SystemStructure.ssd), model.fmu, "
                                  "builtin:NAME_fmi3, file.py:Class, package.module:Class, or a recorded "
                                  ".parquet/.csv table")
    add_experiment_options(p)
    add_variant_option(p)
    p.set_defaults(handler=cmd_inspect)


def cmd_validate(args: argparse.Namespace) -> int:
    """``cosim validate spec.json``: 0 when the spec is usable, 2 with every problem otherwise."""
    from cosim.system.validate import check_design, check_spec

    system = check_spec(args.spec, experiment_overrides(args), args.variant)
    study = args.study or ("optimize" if "optimize" in system.spec.raw else "sweep")
    if study == "sweep":
        check_design(system)  # what `cosim sweep` would refuse, validate refuses too
    elif study == "optimize":
        from cosim.studies.optimize import check_optimization

        check_optimization(system)  # what `cosim optimize` refuses before its first evaluation
    else:
        from cosim.studies.sensitivity import sensitivity_space

        sensitivity_space(system.spec)
    spec = system.spec
    print(f"{args.spec}: ok: {len(spec.units)} unit(s), {len(spec.connections)} connection(s), "
          f"{len(spec.objectives)} objective(s); {spec.experiment.algorithm}, step {spec.experiment.step:g} s, "
          f"order: {' -> '.join(system.order)}; design checked for cosim {study}")
    return EXIT_OK


def parse_assignment(text: str) -> tuple[str, Any]:
    """'unit.param=VALUE' -> ('unit.param', value); VALUE is read as JSON, else as a string.

    Raises UsageError when there is no '='.
    """
    target, sep, value = text.partition("=")
    if not sep or "." not in target:
        raise UsageError(f"--set '{text}': write UNIT.PARAM=VALUE, e.g. --set motor.k_m=0.15")
    try:
        return target.strip(), json.loads(value)
    except json.JSONDecodeError:
        return target.strip(), value


def _fmu_with_input(args: argparse.Namespace) -> Any:
    """``cosim run model.fmu --input signals.csv``: the FMU alone with the table played into its inputs."""
    from cosim.spec.fmu_alone import fmu_raw_spec, is_fmu
    from cosim.spec.loader import spec_from_dict
    from cosim.system.builder import build_system

    path = Path(args.spec)
    if not is_fmu(path):
        raise UsageError(f"--input {args.input}: plays a table into an FMU run alone (cosim run model.fmu "
                         "--input signals.csv); a spec connects a player unit instead")
    return build_system(spec_from_dict(fmu_raw_spec(path, experiment_overrides(args), Path(args.input)), path))


def cmd_run(args: argparse.Namespace) -> int:
    """``cosim run spec.json``: run one point, print objectives, optionally write traces.

    The spec is loaded and its system built once, also with ``--point``.
    """
    from cosim.execution.point import run_point
    from cosim.system.validate import check_spec

    out = Path(args.out) if args.out else None
    if out is not None and out.suffix.lower() not in (".parquet", ".csv"):
        raise UsageError(f"--out {out}: use a .parquet or .csv file name")
    sets = dict(parse_assignment(text) for text in args.sets)
    system = _fmu_with_input(args) if args.input else check_spec(args.spec, experiment_overrides(args), args.variant)
    values: dict[str, Any] = {}
    if args.point:  # values from the sweep's table; traces by default to <results>/points/<ID>.parquet
        from cosim.analysis.rerun import prepare_point_run
        system, values, out = prepare_point_run(system, args.point, args.results, out)
    elif out is not None and not system.spec.record:  # record-and-replay in one line: every output by default
        system = system.recording_all_outputs()
        print(f"recording every output of {', '.join(system.units)} (the spec has no 'record' list)")
    values.update(sets)  # --set wins over the point's value of the same parameter
    result = run_point(system, values, record=out is not None)
    units = {o.name: o.unit or "" for o in system.spec.objectives}
    if result.objectives:
        width = max(len(k) for k in result.objectives)
        print(f"{'objective':<{width}}  {'value':>14}  unit")
        for name, value in result.objectives.items():
            print(f"{name:<{width}}  {value:>14.6g}  {units.get(name.split('[')[0], '')}")
    warm = system.spec.experiment.warm_start
    since = f" from the warm start at t={warm:g} s (made first, with the spec's values)" if warm is not None else ""
    print(f"status: {result.status}; {result.steps} steps{since} to t={result.end_time:g} s in {result.elapsed:.3f} s")
    if result.step_stats:
        from cosim.master.adaptive import describe_statistics
        print(describe_statistics(result.step_stats))
    if result.message:
        print(f"message: {result.message}", file=sys.stderr)
    if out is not None and result.traces is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        if out.suffix.lower() == ".csv":
            result.traces.to_csv(out, index=False)
        else:
            result.traces.to_parquet(out, index=False)
        signals = [str(c) for c in result.traces.columns if c != "time"]
        print(f"traces: {out} ({len(result.traces)} rows, {len(signals)} signals: {_abbreviated(signals)})")
    return run_exit_code(result)


def _abbreviated(names: list[str], most: int = 8) -> str:
    return ", ".join(names[:most]) + (f", ... ({len(names) - most} more)" if len(names) > most else "")


def cmd_inspect(args: argparse.Namespace) -> int:
    """``cosim inspect TARGET``: the ports of an FMU, Python unit or recorded table, or of a spec's units."""
    from cosim.cli.inspection import inspect_target

    return inspect_target(args.target, experiment_overrides(args), args.variant)
