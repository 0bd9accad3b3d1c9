"""``cosim export`` (a spec as an SSP 2.0 archive) and ``cosim export-fmu`` (a Python unit as an FMU)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def add_export_parsers(sub: Any) -> None:
    """Register the export subcommands on the CLI's subparsers."""
    from cosim.cli.options import add_experiment_options

    p = sub.add_parser("export", help="write a spec's system as an SSP 2.0 archive (Python units become FMUs)")
    p.add_argument("spec", help="path to spec.json (or an SSP)")
    p.add_argument("-o", "--out", required=True, metavar="SYSTEM.ssp", help="the archive to write")
    add_experiment_options(p)
    p.set_defaults(handler=cmd_export)

    p = sub.add_parser("export-fmu", help="build an FMI 2.0 co-simulation FMU from a Python unit (pythonfmu)")
    p.add_argument("unit", help="'file.py:Class' or 'package.module:Class'")
    p.add_argument("-o", "--out", required=True, metavar="UNIT.fmu", help="the FMU to write")
    p.set_defaults(handler=cmd_export_fmu)


def cmd_export(args: argparse.Namespace) -> int:
    """``cosim export spec.json -o system.ssp``; also writes system.spec.json beside it."""
    from cosim.cli.exit_codes import EXIT_OK
    from cosim.cli.options import experiment_overrides
    from cosim.errors import UsageError
    from cosim.export.ssp import companion_spec_path, export_ssp
    from cosim.system.validate import check_spec

    out = Path(args.out)
    if out.suffix.lower() != ".ssp":
        raise UsageError(f"-o {out}: name the archive '*.ssp'")
    system = check_spec(args.spec, experiment_overrides(args))
    export_ssp(system, out)
    python_units = [n for n, u in system.units.items() if u.spec.kind == "python"]
    print(f"{out}: SSP 2.0, {len(system.units)} component(s), {len(system.connections)} connection(s)"
          + (f"; Python units built into FMI 2.0 FMUs: {', '.join(python_units)} (they need this Python "
             "version with cosim and the units' packages installed where they run)" if python_units else ""))
    print(f"{companion_spec_path(out)}: the spec's objectives, design space and records on top of the SSP")
    return EXIT_OK


def cmd_export_fmu(args: argparse.Namespace) -> int:
    """``cosim export-fmu file.py:Class -o unit.fmu``."""
    import sys

    from cosim.cli.exit_codes import EXIT_OK
    from cosim.errors import UsageError
    from cosim.export.fmu import export_python_unit

    out = Path(args.out)
    if out.suffix.lower() != ".fmu":
        raise UsageError(f"-o {out}: name the FMU '*.fmu'")
    export_python_unit(args.unit, out, Path.cwd())
    print(f"{out}: FMI 2.0 co-simulation FMU of {args.unit} (pythonfmu); it runs where Python "
          f"{sys.version_info.major}.{sys.version_info.minor} with numpy, cosim and the unit's packages is installed")
    return EXIT_OK
