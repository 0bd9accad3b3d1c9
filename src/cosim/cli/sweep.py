"""``cosim sweep``: evaluate a spec's design space on Dask (see :mod:`cosim.studies.sweep`).

Exit codes: 0 every point ok, 1 some points not ok (failed, timeout,
crashed), 2 a bad spec, results folder or command line (a UserError raised
to :func:`cosim.cli.main.main`).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cosim.cli.exit_codes import EXIT_OK, EXIT_RUN_FAILED
from cosim.errors import UsageError

if TYPE_CHECKING:  # the estimate imports numpy, which `cosim --help` does not
    from cosim.studies.estimate import TimeEstimate

# sample runs of a dry run: stratified over the space (a Latin hypercube of the grid's axes), one warm-up first
DRY_RUN_SAMPLES = 12


def add_sweep_parser(sub: Any) -> None:
    """Register the ``sweep`` subcommand on an argparse sub-parser collection."""
    p = sub.add_parser("sweep", help="evaluate every design point of a spec on Dask; write a results table")
    p.add_argument("spec", help="path to spec.json, or an SSP (.ssp, .ssd, or a folder with SystemStructure.ssd)")
    p.add_argument("--out", metavar="DIR", help="results folder (default: results/<spec name> in the current folder)")
    p.add_argument("--workers", type=int, metavar="N", help="local workers, each running points in a child process (default: one per core)")
    add_cluster_options(p)
    p.add_argument("--timeout", type=float, metavar="S", help="seconds a point may run before it is stopped")
    p.add_argument("--resume", action="store_true", help="run only the points missing in --out")
    p.add_argument("--recompute", action="store_true",
                   help="with --resume: when a unit's file or a data file it reads changed since the stored rows, discard them and run "
                        "every point again (without it such a resume is refused)")
    p.add_argument("--csv", action="store_true", help="also write DIR/results.csv")
    p.add_argument("--batch-size", type=int, metavar="N", help="points per Dask task (default: automatic)")
    p.add_argument("--explore", action="store_true",
                   help="serve the decision room of the results folder while the sweep runs (new points appear as "
                        "they are written; linked from the Dask dashboard's Cosim page); on loopback")
    p.add_argument("--prune", action="store_true",
                   help="stop a design as soon as a finished one strictly dominates every value it can still reach "
                        "(objectives with a sense, or optimize.objectives; the constraints of optimize.constraints): "
                        "the front stays the same; pruned rows have status 'pruned' and hold bounds "
                        "(docs/pruning.md). Off by default")
    from cosim.cli.options import add_experiment_options
    add_experiment_options(p)
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="UNIT.PARAM=VALUE",
                   help="fix a parameter for every point (VALUE as JSON: 2.5, true, [1,2,3]; a design parameter "
                        "of that one value, in place of its range if the design has one); repeatable, as for run")
    p.add_argument("--dry-run", action="store_true",
                   help="print the number of points, the first few and a time estimate from sample runs of "
                        "points spread over the whole space (the first, the last and between)")
    p.set_defaults(handler=cmd_sweep)


def add_cluster_options(p: argparse.ArgumentParser) -> None:
    """--scheduler and --cluster, shared by ``sweep`` and ``optimize`` (see :mod:`cosim.parallel.cluster`)."""
    where = p.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="use a running Dask scheduler, e.g. tcp://host:8786 (default: $DASK_SCHEDULER_ADDRESS, "
                            "else a local cluster)")
    where.add_argument("--cluster", metavar="FILE",
                       help="start the Dask cluster a YAML/JSON file names (type, kwargs, scale or adapt), "
                            "e.g. Slurm or Kubernetes")


def cmd_sweep(args: argparse.Namespace) -> int:
    """Run (or dry-run) a sweep; returns the exit code. SpecError, SweepError and UsageError reach cli.main."""
    if args.batch_size is not None and args.batch_size < 1:
        raise UsageError("--batch-size must be at least 1")
    from cosim.parallel.cluster.choice import named_local

    if not args.dry_run and named_local(args.scheduler, args.cluster):
        # most likely a local cluster, whose workers run in this process: their point children start now and
        # import while this process imports the rest and checks the spec (stopped if the sweep runs elsewhere)
        from cosim.parallel.isolation.runner import start_spare_children

        start_spare_children(args.workers or os.cpu_count() or 1)
    from cosim.cli.options import experiment_overrides
    from cosim.cli.wording import CLI_WORDS
    from cosim.results.folder import default_folder
    from cosim.studies.sweep import Sweep

    out = Path(args.out) if args.out else default_folder(args.spec)
    if args.dry_run:
        return _dry_run(args)
    sweep = Sweep(args.spec, workers=args.workers, out=out, scheduler=args.scheduler, cluster=args.cluster,
                  timeout=args.timeout, fixed=fixed_values(args),
                  resume=args.resume, batch_size=args.batch_size, csv=args.csv, experiment=experiment_overrides(args),
                  recompute=args.recompute, quiet=getattr(args, "quiet", False), explore=args.explore,
                  start_early=True, prune=getattr(args, "prune", False), words=CLI_WORDS)  # the local cluster starts while the results folder and payload are prepared
    runs_before = runs_recorded(sweep.store)
    counts = sweep.run_to_disk()  # a huge sweep's table never sits in memory
    total = sum(counts.values())
    summary = ", ".join(f"{n} {s}" for s, n in sorted(counts.items()) if n)
    print(f"{total} points: {summary or 'none'}; table: {sweep.store.table_path}")
    say_the_dashboard_is_gone(args, sweep.store, runs_before, out, sweep.cluster)
    pruned = counts.get("pruned", 0)  # proven off the front (docs/pruning.md): a result, not a failure
    if pruned:
        print(f"{pruned} pruned: proven off the front; their objective columns hold bounds, not results "
              "(cosim run --point ID runs one to its end)")
    not_ok = total - counts.get("ok", 0) - pruned
    if not_ok:
        print_not_ok(sweep.store.table_path, 5)
        if not_ok > 5:
            print(f"  ... and {not_ok - 5} more (see the 'message' column)", file=sys.stderr)
    return EXIT_OK if not_ok == 0 else EXIT_RUN_FAILED


def fixed_values(args: argparse.Namespace) -> dict[str, Any] | None:
    """The ``--set UNIT.PARAM=VALUE`` options as {target: value} (None without any); UsageError for a bad one."""
    from cosim.cli.spec import parse_assignment

    return dict(parse_assignment(text) for text in args.sets) or None


def runs_recorded(store: Any) -> int:
    """How many runs the results folder's metadata.json records (0 for a new folder)."""
    return len((store.metadata() or {}).get("runs", []))


def say_the_dashboard_is_gone(args: argparse.Namespace, store: Any, runs_before: int, out: Path,
                              cluster: Any) -> None:
    """After a study on a cluster cosim started (and closed), say on stderr that the dashboard link printed at its
    start is gone with it, and how to look at the results instead (also for ``optimize`` and ``sensitivity``).

    The dashboard lives as long as its cluster: the link of a study of a few seconds (the README's first
    sweep) was dead before it could be clicked, with nothing saying why.  Nothing is said under ``-q``, on a
    running scheduler (``cluster``, the study's ClusterChoice, names one: its dashboard stays), or when no
    cluster was started (every point was already in the folder: no run was recorded).
    """
    if getattr(args, "quiet", False) or not cluster.started_here:
        return
    if runs_recorded(store) <= runs_before:
        return
    print(f"cosim: the dashboard closed with the cluster this study started; the results: cosim explore {out} "
          f"(or cosim report {out})", file=sys.stderr)


def print_not_ok(table: Path, n: int) -> None:
    """Print the first ``n`` rows of ``table`` whose status is not ok, one line each, on stderr (also for
    ``cosim optimize``)."""
    from cosim.cli.options import message_line

    for row in first_not_ok(table, n):
        print(f"  {row['point_id']} {row['status']}: {message_line(row['message'])}", file=sys.stderr)


def first_not_ok(table: Path, n: int) -> list[dict]:
    """The first ``n`` rows whose status is neither ok nor pruned, reading only three columns (also for ``cosim optimize``)."""
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    rows = pq.read_table(table, columns=["point_id", "status", "message"])
    failed = pc.and_(pc.not_equal(rows.column("status"), "ok"), pc.not_equal(rows.column("status"), "pruned"))
    return rows.filter(failed).slice(0, n).to_pylist()


def _dry_run(args: argparse.Namespace) -> int:
    import tempfile

    from cosim.cli.options import experiment_overrides, message_line
    from cosim.cli.wording import CLI_WORDS
    from cosim.studies.estimate import estimate_time
    from cosim.studies.sweep import Sweep

    with tempfile.TemporaryDirectory(prefix="cosim_dry_") as scratch:
        sweep = Sweep(args.spec, workers=args.workers, out=scratch, timeout=args.timeout, quiet=True,
                      scheduler=args.scheduler, cluster=args.cluster, experiment=experiment_overrides(args),
                      fixed=fixed_values(args), words=CLI_WORDS)
        local = sweep.cluster.local
        total = len(sweep.space)
        if not sweep.space.targets:
            from cosim.studies.sweep import NO_DESIGN_SPACE

            print(f"{sweep.spec.name}: 1 point: {NO_DESIGN_SPACE}")
        else:
            print(f"{sweep.spec.name}: {total} points ({sweep.space.method}; parameters: "
                  f"{', '.join(sweep.space.targets)})")
        for point in sweep.space.head(5):
            print(f"  {point.id}  " + ", ".join(f"{k}={v}" for k, v in point.values.items()))
        if total > 5:
            print(f"  ... and {total - 5} more")
        samples = sweep.sample_runs(DRY_RUN_SAMPLES)
    for row in samples:
        print(f"sample {row.point_id}: {row.status} in {row.run_time:.3f} s"
              + (f" ({message_line(row.message, 100)})" if row.message else ""))
    times = sorted(r.run_time for r in samples if r.ok)
    if times:
        _print_estimate(args, estimate_time(times), times, total, local)
    else:
        print("estimate: none (no sample run succeeded)")
    return EXIT_OK


def _print_estimate(args: argparse.Namespace, estimate: TimeEstimate, times: list[float], total: int,
                    local: bool) -> None:
    """The time of the whole sweep from the sample times: the mean (not the median: on an uneven space a
    few dear points make most of the total) and the bootstrap range of that mean (cosim.studies.estimate)."""
    per_point = estimate.mean
    spread = (f"mean of {len(times)} sample run(s) stratified over the space, {times[0]:.3f}-{times[-1]:.3f} s; "
              f"{estimate.confidence:.0%} range of the mean {estimate.low:.3f}-{estimate.high:.3f} s")
    workers = args.workers or os.cpu_count() or 1
    if not local:  # the sweep runs on a scheduler or a cluster file's cluster (its ClusterChoice)
        print(f"estimate: {per_point:.3f} s per point ({spread}); {total * per_point:.0f} s of work in total "
              f"({total * estimate.low:.0f}-{total * estimate.high:.0f} s; divide by the scheduler's worker count)")
    else:
        mean, low, high = estimate.total(total, workers)
        print(f"estimate: {per_point:.3f} s per point ({spread}), about {_fmt_time(mean)} on {workers} "
              f"worker(s) (range {_fmt_time(low)} to {_fmt_time(high)})")
    if times[-1] > 3 * times[0]:
        print("note: the sample runs differ more than 3x: the points' cost depends on the design, and the "
              "estimate is only as good as the few samples are typical of the space")
    if args.timeout is None:
        from cosim.parallel.point_stream import TIMEOUT_FACTOR, default_timeout

        print(f"timeout: {default_timeout(times * 3):.0f} s per point by default ({TIMEOUT_FACTOR} x the "
              "measured point time, within COSIM_TIMEOUT_FLOOR .. COSIM_TIMEOUT_FIRST); --timeout S sets it")


def _fmt_time(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"
