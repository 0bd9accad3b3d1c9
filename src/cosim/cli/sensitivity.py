"""``cosim sensitivity``: Sobol or Morris indices of a spec's objectives (see :mod:`cosim.studies.sensitivity`).

Exit codes: 0 every run ok, 1 some runs not ok (their objectives' indices
are NaN), 2 a bad spec, results folder or command line.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from cosim.cli.exit_codes import EXIT_OK, EXIT_RUN_FAILED
from cosim.errors import UsageError


def add_sensitivity_parser(sub: Any) -> None:
    """Register the ``sensitivity`` subcommand on an argparse sub-parser collection."""
    from cosim.studies.sensitivity import DEFAULT_N, DEFAULT_SEED, METHODS

    p = sub.add_parser("sensitivity", help="Sobol or Morris indices of the objectives over the design space (SALib)")
    p.add_argument("spec", help="path to spec.json")
    p.add_argument("--method", choices=METHODS, default="sobol",
                   help="sobol: first-order and total indices, n*(D+2) runs; morris: mu* and sigma, n*(D+1) runs")
    p.add_argument("-n", type=int, metavar="N",
                   help=f"base sample size (default sobol {DEFAULT_N['sobol']}, morris {DEFAULT_N['morris']})")
    p.add_argument("--seed", type=int, default=None, metavar="S", help=f"sample seed (default {DEFAULT_SEED})")
    p.add_argument("--objective", action="append", metavar="NAME",
                   help="objective to analyse (repeatable; default: those with a sense, else all)")
    p.add_argument("--out", metavar="DIR", help="results folder (default: results/<spec name>_<method>)")
    p.add_argument("--workers", type=int, metavar="N", help="local workers, each running points in a child process (default: one per core)")
    from cosim.cli.sweep import add_cluster_options
    add_cluster_options(p)
    p.add_argument("--timeout", type=float, metavar="S", help="seconds a run may take before it is stopped")
    p.add_argument("--resume", action="store_true", help="run only the sample points missing in --out")
    p.set_defaults(handler=cmd_sensitivity)


def cmd_sensitivity(args: argparse.Namespace) -> int:
    """Sample, run, analyse; prints the indices. SpecError and UserErrors reach cli.main."""
    from cosim.cli.wording import CLI_WORDS
    from cosim.results.folder import default_folder
    from cosim.studies.sensitivity import FIGURE_NAME, TABLE_NAME, SensitivityStudy, unreliable_indices

    if args.n is not None and args.n < 2:
        raise UsageError("-n must be at least 2")
    out = Path(args.out) if args.out else Path(f"{default_folder(args.spec)}_{args.method}")
    study = SensitivityStudy(args.spec, out, method=args.method, n=args.n, seed=args.seed,
                             objectives=args.objective, workers=args.workers, scheduler=args.scheduler,
                             cluster=args.cluster,
                             timeout=args.timeout, resume=args.resume, quiet=getattr(args, "quiet", False),
                             words=CLI_WORDS)
    from cosim.cli.sweep import runs_recorded, say_the_dashboard_is_gone

    runs_before = runs_recorded(study.sweep.store)
    counts, indices = study.run()
    total = sum(counts.values())
    wide = indices.pivot_table(index=["objective", "parameter"], columns="index", values=["value", "conf"],
                               sort=False)
    wide.columns = [f"{index}" if kind == "value" else f"{index}_conf" for kind, index in wide.columns]
    print(wide.to_string(float_format=lambda v: f"{v:.4f}"))
    print(f"{total} designs: " + ", ".join(f"{n} {s}" for s, n in sorted(counts.items()) if n)
          + f"; indices: {out / TABLE_NAME}, figure: {out / FIGURE_NAME}")
    say_the_dashboard_is_gone(args, study.sweep.store, runs_before, out, study.sweep.cluster)
    warning = unreliable_indices(indices, args.method, study.n, CLI_WORDS)
    if warning:
        print(f"cosim: warning: {warning}", file=sys.stderr)
    not_ok = total - counts.get("ok", 0)
    if not_ok:
        print(f"{not_ok} runs not ok: the indices of the objectives they leave without a value are NaN",
              file=sys.stderr)
    return EXIT_OK if not_ok == 0 else EXIT_RUN_FAILED
