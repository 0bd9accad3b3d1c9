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
    p.add_argument("--fmi", choices=("2", "3"), metavar="2|3",
                   help="2: put the FMI 2.0 build of each built-in FMU (builtin:NAME_fmi3 -> builtin:NAME_fmi2) in "
                        "the archive, for tools that load only FMI 2.0 such as libcosim (default: as the spec names "
                        "them; an archive with FMI 3.0 FMUs is written with a warning)")
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
    if args.fmi == "2":
        system = _with_fmi2_builtins(system)
    export_ssp(system, out)
    _warn_fmi3(system, args.fmi)
    python_units = [n for n, u in system.units.items() if u.spec.kind == "python"]
    print(f"{out}: SSP 2.0, {len(system.units)} component(s), {len(system.connections)} connection(s)"
          + (f"; Python units built into FMI 2.0 FMUs: {', '.join(python_units)} (they need this Python "
             "version with cosim and the units' packages installed where they run)" if python_units else ""))
    print(f"{companion_spec_path(out)}: the spec's objectives, design space and records on top of the SSP")
    return EXIT_OK


def _with_fmi2_builtins(system: Any) -> Any:
    """The system again with every ``builtin:NAME_fmi3`` unit replaced by ``builtin:NAME_fmi2`` (the same C model
    built for FMI 2.0). Raises SpecError when the FMI 2.0 build does not fit the spec (e.g. an array port)."""
    import dataclasses

    from cosim.system.builder import build_system
    from cosim.units.fmu.kind import BUILTIN_PREFIX

    def fmi2(unit: Any) -> Any:
        if unit.kind == "fmu" and unit.source.startswith(BUILTIN_PREFIX) and unit.source.endswith("_fmi3"):
            return dataclasses.replace(unit, source=unit.source[:-len("_fmi3")] + "_fmi2")
        return unit

    spec = system.spec
    units = tuple(fmi2(u) for u in spec.units)
    return system if units == spec.units else build_system(dataclasses.replace(spec, units=units))


def _warn_fmi3(system: Any, fmi: str | None) -> None:
    """Say on stderr which units went into the archive as FMI 3.0 FMUs: libcosim (and other FMI 2.0-only
    tools) refuse the whole archive, and nothing else would tell the user before they try."""
    import sys

    from cosim.units.fmu.kind import BUILTIN_PREFIX

    fmi3 = [name for name, unit in system.units.items() if unit.spec.kind == "fmu"
            and (getattr(unit.description, "fmi_version", "") or "").startswith("3")]
    if not fmi3:
        return
    builtins = [n for n in fmi3 if system.spec.unit(n).source.startswith(BUILTIN_PREFIX)]
    fix = ("; `cosim export --fmi 2` writes the FMI 2.0 build of the built-in ones (" + ", ".join(builtins) + ")"
           if builtins and fmi != "2" else "; replace them by FMI 2.0 FMUs for such tools")
    print(f"warning: FMI 3.0 FMUs in the archive ({', '.join(fmi3)}): libcosim and other tools that load only "
          f"FMI 2.0 cannot open it{fix}", file=sys.stderr)


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
