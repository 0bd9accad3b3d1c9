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
    except BrokenPipeError:  # the reader stopped early (`cosim pareto ... | head`): not an error of ours
        _discard_stdout()
        return EXIT_OK
    except BaseException as exc:  # noqa: BLE001 - every outcome gets its exit code here, and only here
        if isinstance(exc, SystemExit):
            raise
        report_error(exc)
        return exit_code(exc)


def _discard_stdout() -> None:
    """Point stdout at /dev/null, so the interpreter's final flush into the closed pipe raises nothing."""
    import os

    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)


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
    from . import __version__

    parser = argparse.ArgumentParser(prog="cosim", description="FMI co-simulation orchestrator.")
    parser.add_argument("--version", action="version", version=f"cosim {__version__}")
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

    p = sub.add_parser("inspect", help="list the ports of an FMU, a Python unit, a recorded table, or a spec's "
                                       "(or an SSP's) units")
    p.add_argument("target", help="spec.json, system.ssp, model.fmu, builtin:NAME_fmi3, file.py:Class, "
                                  "package.module:Class, or a recorded .parquet/.csv table")
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
    from .algorithms import ALGORITHMS

    group.add_argument("--algorithm", choices=tuple(ALGORITHMS), help="master algorithm")


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
    from .validate import check_design, check_spec

    system = check_spec(args.spec, experiment_overrides(args))
    check_design(system)  # what `cosim sweep` would refuse, validate refuses too
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
    print(f"status: {result.status}; {result.steps} steps to t={result.end_time:g} s in {result.elapsed:.3f} s")
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
    return result.exit_code


def _abbreviated(names: list[str], most: int = 8) -> str:
    return ", ".join(names[:most]) + (f", ... ({len(names) - most} more)" if len(names) > most else "")


def cmd_inspect(args: argparse.Namespace) -> int:
    """``cosim inspect TARGET``: the ports of an FMU, Python unit or recorded table, or of a spec's units."""
    from .inspection import inspect_target

    return inspect_target(args.target, experiment_overrides(args))


if __name__ == "__main__":  # as orchestrator.cli, so that subcommand modules raise the UsageError caught here
    from orchestrator.cli import main as _main
    sys.exit(_main())
