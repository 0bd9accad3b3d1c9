"""The ``cosim`` command line: one function per subcommand.

Exit codes follow the kind of outcome: 0 everything ran, 1 a run failed,
2 a bad spec, file or usage (the user's to fix), 70 an internal error (ours);
:func:`orchestrator.errors.exit_code` decides them for every subcommand.
A user's mistake never shows a traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
import traceback
from pathlib import Path
from typing import Any, Sequence

from .errors import EXIT_INTERNAL, EXIT_OK, EXIT_RUN_FAILED, EXIT_USAGE, UsageError, UserError, exit_code

__all__ = ["EXIT_INTERNAL", "EXIT_OK", "EXIT_RUN_FAILED", "EXIT_USAGE", "UsageError", "main"]


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``cosim`` console script; returns the exit code.

    Every subcommand returns its own code for what it ran (0, or 1 when a run
    failed); whatever it raises is reported here and mapped by
    :func:`orchestrator.errors.exit_code`: a UserError lists its problems
    (exit 2), anything unexpected prints a traceback (exit 70).
    """
    parser = _parser()
    args = parser.parse_args(argv)
    if not getattr(args, "handler", None):
        parser.print_help()
        return EXIT_USAGE
    try:
        return args.handler(args)
    except BaseException as exc:  # noqa: BLE001 - every outcome gets its exit code here, and only here
        if isinstance(exc, SystemExit):
            raise
        report_error(exc)
        return exit_code(exc)


def report_error(exc: BaseException) -> None:
    """Print what a user needs to know about ``exc`` on stderr (no traceback for a user's mistake)."""
    if isinstance(exc, UserError):
        _print_problems(exc.problems)
    elif isinstance(exc, KeyboardInterrupt):
        print("cosim: interrupted", file=sys.stderr)
    else:
        print("cosim: internal error (please report it with the text below)", file=sys.stderr)
        traceback.print_exception(exc)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="cosim", description="FMI co-simulation orchestrator.")
    sub = parser.add_subparsers(title="commands")

    p = sub.add_parser("validate", help="check a spec and report every problem at once")
    p.add_argument("spec", help="path to spec.json, or an SSP (.ssp, .ssd, or a folder with SystemStructure.ssd)")
    add_experiment_options(p)
    p.set_defaults(handler=cmd_validate)

    p = sub.add_parser("run", help="run one point of a spec and print its objectives")
    p.add_argument("spec", help="path to spec.json, or an SSP (.ssp, .ssd, or a folder with SystemStructure.ssd)")
    add_experiment_options(p)
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="UNIT.PARAM=VALUE",
                   help="set a parameter (VALUE as JSON: 2.5, true, [1,2,3]); repeatable")
    p.add_argument("--out", help="write the recorded signals to this .parquet or .csv file")
    p.add_argument("--point", metavar="ID", help="re-run this design point of a sweep, recording every output")
    p.add_argument("--results", help="the sweep's results.parquet or folder for --point (default: results/<name>/)")
    p.set_defaults(handler=cmd_run)

    p = sub.add_parser("inspect", help="list an FMU's variables, or a spec's units, connections and order")
    p.add_argument("target", help="an .fmu file, a spec.json or an SSP")
    add_experiment_options(p)
    p.set_defaults(handler=cmd_inspect)
    from .export_cli import add_export_parsers
    add_export_parsers(sub)
    from .sweep_cli import add_sweep_parser
    add_sweep_parser(sub)
    from .optimize_cli import add_optimize_parser
    add_optimize_parser(sub)
    from .sensitivity_cli import add_sensitivity_parser
    add_sensitivity_parser(sub)
    from .analysis_cli import add_analysis_parsers
    add_analysis_parsers(sub)
    return parser


def add_experiment_options(p: argparse.ArgumentParser) -> None:
    """--start/--stop/--step/--algorithm: override the experiment (what an SSP often lacks)."""
    group = p.add_argument_group("experiment (overrides the spec's; needed for an SSP without them)")
    group.add_argument("--start", type=float, metavar="S", help="start time (s)")
    group.add_argument("--stop", type=float, metavar="S", help="stop time (s)")
    group.add_argument("--step", type=float, metavar="S", help="communication step size (s)")
    group.add_argument("--algorithm", choices=("gauss-seidel", "jacobi"), help="master algorithm")


def experiment_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The experiment fields given on the command line."""
    return {k: getattr(args, k) for k in ("start", "stop", "step", "algorithm") if getattr(args, k, None) is not None}


def _print_problems(problems: Sequence[Any]) -> None:
    if len(problems) == 1 and not problems[0].file and not problems[0].path:  # a command-line mistake
        print(f"cosim: error: {problems[0]}", file=sys.stderr)
        return
    count = len(problems)
    print(f"{count} problem{'s' if count != 1 else ''} found:", file=sys.stderr)
    for problem in problems:
        print(f"- {problem}", file=sys.stderr)


def cmd_validate(args: argparse.Namespace) -> int:
    """``cosim validate spec.json``: 0 when the spec is usable, 2 with every problem otherwise."""
    from .validate import check_spec

    system = check_spec(args.spec, experiment_overrides(args))
    spec = system.spec
    print(f"{args.spec}: ok: {len(spec.units)} unit(s), {len(spec.connections)} connection(s), "
          f"{len(spec.objectives)} objective(s); {spec.experiment.algorithm}, step {spec.experiment.step:g} s, "
          f"order: {' -> '.join(system.order)}")
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


def cmd_run(args: argparse.Namespace) -> int:
    """``cosim run spec.json``: run one point, print objectives, optionally write traces.

    The spec is loaded and its system built once, also with ``--point``.
    """
    from .point import run_point
    from .validate import check_spec

    out = Path(args.out) if args.out else None
    if out is not None and out.suffix.lower() not in (".parquet", ".csv"):
        raise UsageError(f"--out {out}: use a .parquet or .csv file name")
    sets = dict(parse_assignment(text) for text in args.sets)
    system = check_spec(args.spec, experiment_overrides(args))
    values: dict[str, Any] = {}
    if args.point:  # values from the sweep's table; traces by default to <results>/points/<ID>.parquet
        from .analysis.rerun import prepare_point_run
        system, values, out = prepare_point_run(system, args.point, args.results, out)
    values.update(sets)  # --set wins over the point's value of the same parameter
    result = run_point(system, values, record=out is not None)
    units = {o.name: o.unit or "" for o in system.spec.objectives}
    if result.objectives:
        width = max(len(k) for k in result.objectives)
        print(f"{'objective':<{width}}  {'value':>14}  unit")
        for name, value in result.objectives.items():
            print(f"{name:<{width}}  {value:>14.6g}  {units.get(name.split('[')[0], '')}")
    print(f"status: {result.status}; {result.steps} steps to t={result.end_time:g} s in {result.elapsed:.3f} s")
    if result.message:
        print(f"message: {result.message}", file=sys.stderr)
    if out is not None and result.traces is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        if out.suffix.lower() == ".csv":
            result.traces.to_csv(out, index=False)
        else:
            result.traces.to_parquet(out, index=False)
        print(f"traces: {out} ({len(result.traces)} rows, {len(result.traces.columns) - 1} signals)")
    return result.exit_code


def cmd_inspect(args: argparse.Namespace) -> int:
    """``cosim inspect file.fmu|spec.json``: variables of an FMU, or the structure of a spec."""
    target = Path(args.target)
    if target.suffix.lower() == ".fmu" or args.target.startswith("builtin:"):
        return _inspect_fmu(args.target)
    from .validate import check_spec

    system = check_spec(target, experiment_overrides(args))
    print(f"spec {target}: {system.spec.name}")
    print("units:")
    for name, unit in system.units.items():
        d = unit.description
        kind = f"FMI {d.fmi_version}" if d.kind == "fmu" else d.kind
        if d.kind == "fmu" and unit.unit_type.interface == "model-exchange":
            kind += " model-exchange"  # co-simulation, the usual case, goes without saying
        ports = _listed_variables(d)  # FMI 2.0 scalars x[1]..x[n] count once, as their array x
        inputs = sum(v.causality == "input" for v in ports)
        outputs = sum(v.causality == "output" for v in ports)
        print(f"  {name}: {kind} {unit.spec.source} ({inputs} inputs, {outputs} outputs)")
    print("connections:")
    for c in system.connections:
        scaled = f" (x {c.factor:.17g} + {c.offset:.17g})" if c.transforms else ""
        print(f"  {c.source.text} -> {c.target.text}{scaled}")
    exp = system.spec.experiment
    print(f"experiment: {exp.start:g} .. {exp.stop:g} s, step {exp.step:g} s, {exp.algorithm}")
    print(f"stepping order: {' -> '.join(system.order)}")
    return EXIT_OK


def _inspect_fmu(reference: str) -> int:
    from .unit_kinds import resolve_fmu_path
    from .units.fmu import FmuUnitType, offered_interfaces

    try:
        unit_type = FmuUnitType(resolve_fmu_path(reference), reference)
        d = unit_type.describe()
    except FileNotFoundError as exc:
        raise UsageError(str(exc)) from None
    offered = offered_interfaces(unit_type.model_description())
    print(f"{reference}: {d.name}, FMI {d.fmi_version} {' and '.join(offered)}"
          + (f", default step {d.default_step:g} s" if d.default_step else ""))
    if len(offered) > 1:
        print(f"  runs as {unit_type.interface} unless the spec's unit sets \"interface\": \"model-exchange\"")
    if d.description:
        print(f"  {d.description}")
    if getattr(unit_type.model_description().coSimulation, "needsExecutionTool", False):
        print("  needsExecutionTool: the FMU drives its exporting tool, which must be installed and licensed "
              "on every machine that runs it (also every Dask worker)")
    rows = [("name", "causality", "type", "unit", "start", "range", "description")]
    for v in _listed_variables(d):
        if v.causality == "local":
            continue
        shape = f"[{','.join(map(str, v.shape))}]" if v.shape else ""
        rng = "" if v.min is None and v.max is None else f"[{_fmt(v.min) or '-inf'}, {_fmt(v.max) or 'inf'}]"
        rows.append((v.name + shape, v.causality, v.fmi_type or v.type, v.unit or "", _fmt(v.start), rng,
                     v.description[:50]))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    for row in rows:
        print("  " + "  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip())
    return EXIT_OK


def _listed_variables(d: Any) -> list:
    """The variables to show: FMI 2.0 scalars x[1]..x[n] that are also offered as the array x are left out."""
    arrays = {v.name for v in d.variables if v.is_array}
    return [v for v in d.variables
            if not (d.fmi_version == "2.0" and not v.is_array and v.name.split("[")[0] in arrays)]


def _fmt(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bytes):
        return value.hex() or '""'  # FMI 3.0 Binary: the bytes in hex, as the trace columns hold them
    if isinstance(value, tuple):
        return "(" + ", ".join(_fmt(v) for v in value[:4]) + (", ..." if len(value) > 4 else "") + ")"
    return f"{value:g}" if isinstance(value, float) else str(value)


if __name__ == "__main__":  # as orchestrator.cli, so that subcommand modules raise the UsageError caught here
    from orchestrator.cli import main as _main
    sys.exit(_main())
