"""``cosim new spec.json --from model.fmu|system.ssp``: a starter spec that validates and runs at once."""

from __future__ import annotations

import argparse
import json
import logging
import os
from dataclasses import replace
from pathlib import Path
from typing import Any

from cosim.cli.exit_codes import EXIT_OK


def add_new_parser(sub: Any) -> None:
    """Register ``new`` on the ``cosim`` subparsers ``sub``."""
    from cosim.cli.spec import add_variant_option

    p = sub.add_parser("new", help="write a starter spec for an FMU or an SSP: every port recorded, its experiment, "
                                   "one example objective and design parameter")
    p.add_argument("spec", help="the spec.json to write")
    p.add_argument("--from", dest="source", required=True, metavar="MODEL",
                   help="the model: an FMU (model.fmu, or a folder of an extracted FMU) or an SSP (.ssp, .ssd, or a "
                        "folder with SystemStructure.ssd)")
    p.add_argument("--force", action="store_true", help="overwrite the spec if it exists")
    add_variant_option(p)
    p.set_defaults(handler=cmd_new)


def cmd_new(args: argparse.Namespace) -> int:
    """Write the starter spec, after checking it as ``cosim validate`` and ``cosim sweep`` would.

    Raises UsageError (exit 2) for a spec that exists (without ``--force``), a name not ending in .json, or a
    source that is neither an FMU nor an SSP; SpecError (exit 2) for a model that cannot be read; InternalError
    (exit 70) when the starter spec made does not validate (a bug: nothing is written)."""
    from cosim.errors import InternalError, SpecError, UsageError
    from cosim.spec.fmu_alone import is_fmu
    from cosim.ssp import is_ssp
    from cosim.system.starter import explanation, starter_spec
    from cosim.system.validate import check_design, check_spec

    spec_path, source = Path(args.spec), Path(args.source)
    if spec_path.suffix.lower() != ".json":
        raise UsageError(f"{spec_path}: name the spec '*.json' (e.g. cosim new spec.json --from {source})")
    if spec_path.exists() and not args.force:
        raise UsageError(f"{spec_path} exists: cosim new does not overwrite it; give another name, or --force")
    if not source.exists():
        raise UsageError(f"--from {source}: no such file or folder")
    ssp = is_ssp(source)
    if not ssp and not is_fmu(source):
        raise UsageError(f"--from {source}: give an FMU (.fmu) or an SSP (.ssp, .ssd, or a folder with "
                         "SystemStructure.ssd)")
    if args.variant and not ssp:
        raise UsageError(f"--variant {args.variant}: an FMU has no variants (an SSP's SSDs are its variants)")
    starter = starter_spec(check_spec(source, None, args.variant), source, spec_path, ssp, args.variant)
    spec_path.parent.mkdir(parents=True, exist_ok=True)
    # checked under a name of its own in the same folder (relative paths resolve alike), then put in place:
    # a spec that would not validate is never left behind, and an existing one is replaced whole or not at all
    trial = spec_path.with_name(f".{spec_path.stem}.cosim-new-{os.getpid()}.json")
    try:
        trial.write_text(json.dumps(starter.content, indent=2) + "\n", encoding="utf-8")
        logging.disable(logging.WARNING)  # the model's notes were shown once, when it was read above
        try:
            check_design(check_spec(trial))
        except SpecError as exc:  # a starter spec that does not validate is cosim's mistake: said so, nothing written
            raise InternalError(f"the starter spec cosim new made for {source} does not validate (not written):\n"
                                + "\n".join(str(replace(p, file=str(spec_path) if p.file == str(trial) else p.file))
                                             for p in exc.problems)) from None
        finally:
            logging.disable(logging.NOTSET)
        os.replace(trial, spec_path)
    finally:
        trial.unlink(missing_ok=True)
    print(explanation(starter, spec_path))
    return EXIT_OK
