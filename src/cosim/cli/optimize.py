"""``cosim optimize``: multi-objective optimisation of a spec's design space (see :mod:`cosim.studies.optimize`).

Exit codes: 0 every evaluation ok, 1 some evaluations not ok (failed,
timeout, crashed: the optimisation went on), 2 a bad spec, results folder or
command line.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from cosim.cli.exit_codes import EXIT_OK, EXIT_RUN_FAILED
from cosim.errors import UsageError


class _Objective(argparse.Action):
    """``--min A --max B``: (name, 'min' | 'max') pairs in the order given."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, list(getattr(namespace, self.dest) or []) + [(values, option_string[2:])])


def add_optimize_parser(sub: Any) -> None:
    """Register the ``optimize`` subcommand on an argparse sub-parser collection."""
    from cosim.cli.sweep import add_cluster_options
    from cosim.studies.sampler_names import SAMPLERS

    p = sub.add_parser("optimize", help="search a spec's design space for the Pareto front (Optuna, on Dask)")
    p.add_argument("spec", help="path to spec.json")
    p.add_argument("--out", metavar="DIR", help="results folder (default: results/<spec name>_optimize)")
    p.add_argument("--min", dest="objectives", action=_Objective, metavar="OBJ",
                   help="minimize OBJ (repeatable; replaces optimize.objectives and the spec's senses)")
    p.add_argument("--max", dest="objectives", action=_Objective, metavar="OBJ", help="maximize OBJ (repeatable)")
    p.add_argument("--budget", type=int, metavar="N", help="evaluations in all (default: optimize.budget, or 200)")
    p.add_argument("--sampler", choices=SAMPLERS, help="Optuna sampler (default: optimize.sampler, or tpe)")
    p.add_argument("--batch", type=int, metavar="K",
                   help="designs asked and evaluated in parallel per round (default 8; nsga2: 20, its population)")
    p.add_argument("--explore", action="store_true",
                   help="serve the decision room of the results folder while the optimisation runs (new evaluations "
                        "appear as they are written; linked from the Dask dashboard's Cosim page); on loopback")
    p.add_argument("--prune", action="store_true",
                   help="stop a design once a finished one strictly dominates every value it can still reach; its "
                        "trial is told to Optuna as PRUNED (docs/pruning.md). Off by default")
    p.add_argument("--seed", type=int, metavar="S", help="sampler seed (default: optimize.seed, or a random one)")
    p.add_argument("--resume", action="store_true", help="continue the optimisation stored in --out to the budget")
    p.add_argument("--workers", type=int, metavar="N", help="local workers, each running points in a child process (default: one per core)")
    add_cluster_options(p)
    p.add_argument("--timeout", type=float, metavar="S", help="seconds an evaluation may run before it is stopped")
    p.add_argument("--storage", metavar="URL",
                   help="also keep the trials in this Optuna storage, e.g. sqlite:///study.db, for optuna-dashboard "
                        "and Optuna's plots (the results folder stays the study; --resume replays into it)")
    p.add_argument("--study-name", metavar="NAME",
                   help="the study's name in --storage (default: the results folder's absolute path)")
    p.set_defaults(handler=cmd_optimize)


def cmd_optimize(args: argparse.Namespace) -> int:
    """Run an optimisation; returns the exit code. SpecError, OptimizeError and UsageError reach cli.main."""
    from cosim.cli.sweep import print_not_ok, runs_recorded, say_the_dashboard_is_gone
    from cosim.cli.wording import CLI_WORDS
    from cosim.results.folder import default_folder
    from cosim.studies.optimize import Optimization

    for option in ("budget", "batch", "workers"):
        value = getattr(args, option)
        if value is not None and value < 1:
            raise UsageError(f"--{option} must be at least 1")
    out = Path(args.out) if args.out else Path(f"{default_folder(args.spec)}_optimize")
    objectives = {name: f"{sense}imize" for name, sense in args.objectives} if args.objectives else None
    run = Optimization(args.spec, out, objectives=objectives, budget=args.budget, sampler=args.sampler, batch=args.batch,
                       seed=args.seed, resume=args.resume, workers=args.workers, scheduler=args.scheduler,
                       cluster=args.cluster, timeout=args.timeout, quiet=getattr(args, "quiet", False),
                       storage=args.storage, study_name=args.study_name, explore=args.explore,
                       prune=getattr(args, "prune", False), words=CLI_WORDS)
    runs_before = runs_recorded(run.store)
    counts = run.run()
    total = sum(counts.values())
    summary = ", ".join(f"{n} {s}" for s, n in sorted(counts.items()) if n)
    print(f"{total} evaluations: {summary or 'none'}; table: {run.store.table_path}")
    print(f"front: cosim pareto {run.store.table_path}; report: cosim report {out} -o report.html")
    say_the_dashboard_is_gone(args, run.store, runs_before, out, run.cluster)
    not_ok = total - counts.get("ok", 0)
    if not_ok:
        print_not_ok(run.store.table_path, 5)
    return EXIT_OK if not_ok == 0 else EXIT_RUN_FAILED
