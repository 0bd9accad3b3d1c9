"""``cosim surrogate`` (fit, store, predict) and ``cosim export-surrogate`` (the surrogates as a C FMU).

User mistakes (a missing table or designs file, an unknown objective or parameter column, a row without a number,
``-o`` without ``--predict``) raise AnalysisError or UsageError: exit 2 and one line naming file, field and fix.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from cosim.cli.exit_codes import EXIT_OK

# cosim.analysis.surrogate.fit.METHODS and study.MAX_ROWS, written here because importing cosim.analysis imports
# pandas, which `cosim --help` must not (tests/project/test_single_sources.py checks the two stay equal)
METHODS = ("auto", "gp", "poly")
MAX_ROWS = 500
TRUST_BELOW = 0.8  # a Q² under this is said aloud: the surrogate explains too little to decide on


def add_surrogate_parsers(sub: Any) -> None:
    """Register ``surrogate`` and ``export-surrogate`` on the ``cosim`` subparsers ``sub``."""
    p = sub.add_parser("surrogate", help="fit a surrogate of each objective (Q², parameter ranking) into "
                                         "DIR/surrogate/, or predict new designs with it")
    p.add_argument("table", help="results folder (or its results.parquet / a .csv with --spec)")
    p.add_argument("--objective", action="append", metavar="OBJ",
                   help="objective column to model (repeatable; default: every objective of the spec)")
    p.add_argument("--method", choices=METHODS, default="auto",
                   help="gp: Gaussian process (anisotropic Matern kernel); poly: polynomial with ridge; auto "
                        "(default): the one with the best 5-fold Q²")
    p.add_argument("--max-rows", type=int, default=MAX_ROWS, metavar="N",
                   help=f"fit on at most N random ok rows (default {MAX_ROWS}; a Gaussian process costs N^3)")
    p.add_argument("--seed", type=int, default=0, help="seed of the row subset, folds and sampling (default 0)")
    p.add_argument("--spec", help="spec.json of the study, when no metadata.json lies beside the table")
    p.add_argument("--predict", metavar="DESIGNS.csv",
                   help="predict these designs (one column per design parameter; .csv or .parquet) with the "
                        "surrogates stored in DIR/surrogate/")
    p.add_argument("-o", "--out", metavar="PREDICTED.csv",
                   help="with --predict: the table to write (the designs, each objective and OBJ_std)")
    p.set_defaults(handler=cmd_surrogate)
    add_export_surrogate_parser(sub)


def cmd_surrogate(args: argparse.Namespace) -> int:
    """``cosim surrogate``: fit and store (prints the summary), or ``--predict`` with the stored surrogates."""
    from cosim.errors import UsageError

    if args.out and not args.predict:
        raise UsageError(f"-o {args.out}: only with --predict DESIGNS.csv (the surrogates go to DIR/surrogate/)")
    if args.predict:
        if not args.out:
            raise UsageError("--predict needs -o PREDICTED.csv: the table to write")
        return _predict(args)
    if args.max_rows < 6:
        raise UsageError(f"--max-rows {args.max_rows}: give at least 6 (5-fold cross-validation)")
    from cosim.analysis.surrogate import fit_table, surrogate_folder, write
    from cosim.analysis.table import load_results

    table = load_results(args.table, args.spec)
    if table.note:
        print(f"cosim: note: {table.note}", file=sys.stderr)
    surrogates = fit_table(table, args.objective, args.method, args.max_rows, args.seed)
    folder = write(surrogates, surrogate_folder(args.table))
    print(_summary_text(surrogates))
    for note in surrogates.notes:
        print(f"note: {note}")
    print(f"written: {folder / 'models.json'}, {folder / 'summary.csv'}")
    return EXIT_OK


def _summary_text(surrogates: Any) -> str:
    from cosim.analysis.surrogate.ranking import parameter_q2

    lines = [f"{'objective':<24} {'surrogate':<14} {'Q2':>8} {'RMSE':>11} {'designs':>7}  ranking: total Sobol index "
             "(Q2 of the parameter)"]
    for name, s in surrogates.objectives.items():
        ranking = ", ".join(f"{i.parameter} {i.total:.2f} ({parameter_q2(s.fitted.q2, i):.2f})" for i in s.ranking)
        lines.append(f"{name:<24} {s.fitted.candidate:<14} {s.fitted.q2:>8.4f} {s.fitted.rmse:>11.4g} {s.rows:>7}  "
                     f"{ranking}")
        if not s.fitted.q2 >= TRUST_BELOW:
            lines.append(f"  warning: {name}: Q2 {s.fitted.q2:.3f} < {TRUST_BELOW}: the surrogate predicts new "
                         "designs poorly; run more designs or model another objective")
    f = surrogates.failures
    lines.append("failed designs: " + (f"{f.failed} of {f.total}; classifier's 5-fold balanced accuracy "
                                       f"{f.balanced_accuracy:.3f}" if f is not None else
                                       "too few (under 5) or none: no classifier"))
    return "\n".join(lines)


def _predict(args: argparse.Namespace) -> int:
    import pandas as pd

    from cosim.analysis.surrogate import read, surrogate_folder
    from cosim.errors import AnalysisError, UsageError

    designs_path, out = Path(args.predict), Path(args.out)
    if out.suffix.lower() not in (".csv", ".parquet"):
        raise UsageError(f"-o {out}: name the table '*.csv' or '*.parquet'")
    if not designs_path.is_file():
        raise AnalysisError(f"--predict {designs_path}: no such file (give a .csv or .parquet of designs)")
    surrogates = read(surrogate_folder(args.table))
    try:
        designs = pd.read_parquet(designs_path) if designs_path.suffix.lower() == ".parquet" \
            else pd.read_csv(designs_path)
    except Exception as exc:  # pandas and pyarrow raise many kinds for a bad file
        raise AnalysisError(f"--predict {designs_path}: cannot read the table: {exc}") from None
    predicted = surrogates.predict(designs, f"--predict {designs_path}")
    wanted = args.objective or list(surrogates.objectives)
    unknown = [o for o in wanted if o not in surrogates.objectives]
    if unknown:
        raise AnalysisError(f"--objective {unknown[0]}: no surrogate of it in {surrogate_folder(args.table)} "
                            f"(there: {', '.join(surrogates.objectives)}); fit it with `cosim surrogate "
                            f"{args.table} --objective {unknown[0]}`")
    dropped = [c for o in surrogates.objectives if o not in wanted for c in (o, f"{o}_std")]
    predicted = predicted.drop(columns=dropped)
    out.parent.mkdir(parents=True, exist_ok=True)
    predicted.to_parquet(out, index=False) if out.suffix.lower() == ".parquet" else predicted.to_csv(out, index=False)
    print(f"written: {out}: {len(predicted)} designs, {', '.join(wanted)} with their standard deviation (_std)"
          + (" and p_fail" if "p_fail" in predicted.columns else ""))
    return EXIT_OK


def add_export_surrogate_parser(sub: Any) -> None:
    """Register ``export-surrogate`` on the ``cosim`` subparsers ``sub``."""
    p = sub.add_parser("export-surrogate", help="the surrogates of DIR/surrogate/ as an FMI co-simulation FMU in "
                                                "C (parameters: the design; outputs: predictions, uncertainty)")
    p.add_argument("table", help="the results folder whose surrogate/ holds models.json (cosim surrogate DIR)")
    p.add_argument("-o", "--out", required=True, metavar="OBJECTIVE.fmu", help="the FMU to write")
    p.add_argument("--objective", action="append", metavar="OBJ",
                   help="only this objective's surrogate (repeatable; default: all)")
    p.add_argument("--fmi", choices=("2", "3"), default="2", help="FMI version (default 2)")
    p.set_defaults(handler=cmd_export_surrogate)


def cmd_export_surrogate(args: argparse.Namespace) -> int:
    """``cosim export-surrogate DIR -o objective.fmu``."""
    from cosim.analysis.surrogate import read, surrogate_folder
    from cosim.errors import UsageError
    from cosim.export.surrogate_fmu import export_surrogate_fmu, output_names, parameter_name

    out = Path(args.out)
    if out.suffix.lower() != ".fmu":
        raise UsageError(f"-o {out}: name the FMU '*.fmu'")
    surrogates = read(surrogate_folder(args.table))  # checks the file is ours before anything is built
    export_surrogate_fmu(surrogates.to_json(), out, args.objective, int(args.fmi))
    chosen = args.objective or list(surrogates.objectives)
    print(f"{out}: FMI {args.fmi}.0 co-simulation FMU (C, no Python at run time); parameters "
          f"{', '.join(parameter_name(p) for p in surrogates.parameters)}; outputs "
          f"{', '.join(n for o in chosen for n in output_names(o))}")
    return EXIT_OK
