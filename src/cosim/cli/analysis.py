"""``cosim plot``, ``cosim pareto``, ``cosim explore``, ``cosim report``: turning a results table into understanding.

Every command takes a results table (a sweep folder, ``results.parquet`` or a
``.csv``), with or without the sweep's ``metadata.json`` beside it.  User
mistakes (missing file, unknown column, bad ``--where``) raise AnalysisError,
a UserError: exit code 2 and one line of text, never a traceback.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from cosim.cli.exit_codes import EXIT_OK

FIGURE_SUFFIXES = (".png", ".svg", ".pdf")


class _Objective(argparse.Action):
    """``--min A --max B`` keeps the order and sense of each objective in one list."""

    def __call__(self, parser, namespace, values, option_string=None):
        items = list(getattr(namespace, self.dest) or [])
        items.append((values, option_string.lstrip("-")))
        setattr(namespace, self.dest, items)


def add_analysis_parsers(sub: Any) -> None:
    """Register plot, pareto, explore and report on the ``cosim`` subparsers ``sub``."""
    p = sub.add_parser("plot", help="2-D/3-D scatter of a results table, coloured by a column")
    p.add_argument("table", help="results.parquet, a .csv, or a sweep folder")
    p.add_argument("--x", required=True, help="column on the x axis")
    p.add_argument("--y", required=True, help="column on the y axis")
    p.add_argument("--z", help="column on the z axis (3-D plot)")
    p.add_argument("--color", help="column giving the colour (with a colour bar)")
    _filters(p)
    _spec_option(p)
    p.add_argument("-o", "--out", required=True, help="figure file: .png, .svg or .pdf")
    p.add_argument("--title", help="figure title")
    p.set_defaults(handler=cmd_plot)

    p = sub.add_parser("pareto", help="the non-dominated designs of chosen objectives")
    p.add_argument("table", help="results.parquet, a .csv, or a sweep folder")
    p.add_argument("--min", dest="objectives", action=_Objective, metavar="OBJ", help="minimize OBJ (repeatable)")
    p.add_argument("--max", dest="objectives", action=_Objective, metavar="OBJ", help="maximize OBJ (repeatable)")
    _filters(p)
    _spec_option(p)
    p.add_argument("--csv", help="write the front (all columns) to this CSV file")
    p.add_argument("--plot", help="draw the front over the cloud of the first two objectives into this figure")
    p.add_argument("--color", help="colour the cloud of --plot by this column")
    p.set_defaults(handler=cmd_pareto)

    p = sub.add_parser("report", help="one self-contained HTML page about a sweep")
    p.add_argument("table", help="results.parquet, a .csv, or a sweep folder")
    p.add_argument("-o", "--out", help="the .html file to write (default: report.html in the results folder, or "
                                        "beside the table file)")
    p.add_argument("--min", dest="objectives", action=_Objective, metavar="OBJ",
                   help="minimize OBJ in the Pareto front (repeatable; replaces the senses of the spec)")
    p.add_argument("--max", dest="objectives", action=_Objective, metavar="OBJ",
                   help="maximize OBJ in the Pareto front (repeatable; replaces the senses of the spec)")
    _spec_option(p)
    p.set_defaults(handler=cmd_report)

    p = sub.add_parser("explore", help="the decision room: the study in the browser (filters, Pareto front, "
                                       "ranking, re-runs); --tk for the desktop window")
    p.add_argument("table", help="results.parquet, a .csv, or a results folder (sweep, optimize, sensitivity)")
    _spec_option(p)
    p.add_argument("--host", default="127.0.0.1",
                   help="address to serve on (default 127.0.0.1: this machine only); the printed link carries a "
                        "token on every address")
    p.add_argument("--no-token", action="store_true",
                   help="serve without a token: anyone who reaches the address (on loopback: every user of this "
                        "machine) can read the study and re-run its designs")
    p.add_argument("--port", type=int, default=0, help="port to serve on (default 0: a free one)")
    p.add_argument("--tk", action="store_true", help="open the Tk point-cloud window instead (needs a display)")
    p.set_defaults(handler=cmd_explore)


def _spec_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--spec", help="spec.json of the sweep, for units, senses and re-runs when no metadata.json "
                                  "lies beside the table (overrides the metadata's spec)")


def _filters(p: argparse.ArgumentParser) -> None:
    p.add_argument("--where", help="keep rows where this expression is true, e.g. \"e_el[1] < 20 and "
                                   "traj.q_via[2] > -50\" (columns named as in the table)")
    p.add_argument("--only-ok", action="store_true", help="leave out rows whose status is not 'ok'")


def _figure_path(text: str, option: str) -> Path:
    from cosim.analysis.table import AnalysisError

    path = Path(text)
    if path.suffix.lower() not in FIGURE_SUFFIXES:
        raise AnalysisError(f"{option} {text}: use a .png, .svg or .pdf file name")
    path.parent.mkdir(parents=True, exist_ok=True)
    return path


def _say_note(table: Any) -> None:
    """What the reader should know about the rows read (an unfinished study's parts), on stderr."""
    if table.note:
        print(f"cosim: note: {table.note}", file=sys.stderr)


def cmd_plot(args: argparse.Namespace) -> int:
    """``cosim plot``: rows failing ``--where`` are greyed; ``--only-ok`` leaves failed rows out."""
    from cosim.analysis.plots import new_figure, save, scatter_cloud
    from cosim.analysis.table import load_results

    out = _figure_path(args.out, "-o")
    table = load_results(args.table, args.spec)
    _say_note(table)
    for column in (args.x, args.y, args.z, args.color):
        if column:
            table.check_column(column)
    rows = table.ok_mask() if args.only_ok else None
    active = table.where(args.where)
    pruned = _pruned_mask(table)
    active = active & ~pruned  # a pruned row's values are bounds, not results: drawn greyed, never coloured
    fig = new_figure(7.5, 6.0 if args.z else 5.0)
    _, counts = scatter_cloud(fig, table, args.x, args.y, args.z, args.color, active=active, rows=rows,
                              title=args.title)
    save(fig, out)
    extra = f", {counts.missing} without a value" if counts.missing else ""
    if pruned.any() and not args.only_ok:
        extra += f" ({int(pruned.sum())} pruned rows among the greyed: their values are bounds)"
    print(f"{out}: {counts.coloured} points coloured, {counts.greyed} greyed{extra}")
    return EXIT_OK


def _pruned_mask(table: Any) -> Any:
    """True for the rows a pruned study stopped (status 'pruned': their objective columns are bounds)."""
    import numpy as np

    if "status" not in table.df.columns:
        return np.zeros(len(table.df), dtype=bool)
    return (table.df["status"].astype(str) == "pruned").to_numpy()


def cmd_pareto(args: argparse.Namespace) -> int:
    """``cosim pareto``: the non-dominated ok rows; ties are all kept, rows with a missing value never count."""
    import pandas as pd

    from cosim.analysis.pareto import front_of, resolve_objectives
    from cosim.analysis.table import AnalysisError, load_results

    table = load_results(args.table, args.spec)
    _say_note(table)
    objectives = resolve_objectives(table, args.objectives)
    if args.color:
        table.check_column(args.color)
    plot = _figure_path(args.plot, "--plot") if args.plot else None
    if plot is not None and len(objectives) < 2:
        raise AnalysisError("--plot needs at least two objectives (--min A --min B)")
    front, considered = front_of(table, objectives, args.where)
    names = [name for name, _ in objectives]
    shown = [c for c in ["point_id", *table.parameter_columns()] if c in table.df.columns and c not in names]
    rows = table.df.loc[front, shown + names]
    rows = rows.sort_values(names[0], ascending=objectives[0][1] == "min", kind="stable")
    senses = ", ".join(f"{s} {n}" for n, s in objectives)
    print(f"Pareto front ({senses}): {int(front.sum())} of {int(considered.sum())} rows")
    pruned = _pruned_mask(table)
    if pruned.any():  # proven off the front by a pruned study: not considered, and no loss (docs/pruning.md)
        print(f"{int(pruned.sum())} pruned rows: proven dominated while running (their values are bounds)")
    with pd.option_context("display.max_rows", 200, "display.width", 160, "display.max_columns", 20):
        print(rows.to_string(index=False))
    if args.csv:
        Path(args.csv).parent.mkdir(parents=True, exist_ok=True)
        table.df.loc[front].to_csv(args.csv, index=False)
        print(f"written: {args.csv}")
    if plot is not None:
        from cosim.analysis.plots import draw_front, new_figure, save, scatter_cloud

        fig = new_figure()
        ax, _ = scatter_cloud(fig, table, names[0], names[1], color=args.color, active=considered)
        draw_front(ax, table, names[0], names[1], front)
        save(fig, plot)
        print(f"written: {plot}")
    return EXIT_OK


def cmd_report(args: argparse.Namespace) -> int:
    """``cosim report``: write the HTML page."""
    from cosim.analysis.report import write_report
    from cosim.analysis.table import load_results

    given = Path(args.table)
    out = Path(args.out) if args.out else (given if given.is_dir() else given.parent) / "report.html"
    table = load_results(args.table, args.spec)
    _say_note(table)
    if args.objectives:
        table.choose_objectives(args.objectives)
    write_report(table, out)
    print(f"written: {out}")
    return EXIT_OK


def cmd_explore(args: argparse.Namespace) -> int:
    """``cosim explore``: serve the decision room until Ctrl-C (``--tk``: open the window; needs a display)."""
    from cosim.analysis.table import AnalysisError, load_results

    table = load_results(args.table, args.spec)
    _say_note(table)
    if not args.tk:
        from cosim.analysis.room.data import Study
        from cosim.analysis.room.live import LiveStudy
        from cosim.analysis.room.server import serve

        if not 0 <= args.port <= 65535:
            raise AnalysisError(f"--port {args.port}: use a port between 1 and 65535, or 0 for a free one")
        # a folder is watched: the rows a running (or resumed) study writes appear in the page as they arrive
        study = LiveStudy(args.table, spec_path=args.spec) if Path(args.table).is_dir() else \
            Study(table, spec_path=args.spec)
        serve(study, host=args.host, port=args.port, no_token=args.no_token)
        return EXIT_OK
    try:
        from cosim.analysis.explorer import run_explorer
    except ImportError as exc:  # tkinter missing from this Python
        raise AnalysisError(f"the explorer needs tkinter: {exc}") from None
    run_explorer(table)
    return EXIT_OK
