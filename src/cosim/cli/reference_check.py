"""Run FMUs built elsewhere (e.g. the Modelica Reference FMUs) through cosim and compare with fmpy.

    python -m cosim.cli.reference_check FMU_OR_FOLDER ... [--markdown]

For each FMU: ``cosim inspect`` must succeed (or, for an FMU cosim does not run, ``cosim validate`` must refuse
it with exit code 2); ``cosim run`` of a one-unit spec over the FMU's default experiment, recording every output,
is compared sample by sample with fmpy's ``simulate_fmu`` at the same step.  Prints one line (or Markdown table
row) per FMU: whether it ran, where it ended, the largest difference from fmpy, or cosim's refusal message.

Nothing here is committed FMUs: build them from their public sources first (docs/fmi-support.md says how).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
from pathlib import Path

import numpy as np


def check(path: Path, work: Path, stop_override: float | None = None, step_override: float | None = None) -> dict:
    """The outcome for one FMU: {fmu, fmi, result, detail}; the overrides replace the default experiment's."""
    from fmpy import read_model_description, simulate_fmu

    from cosim.cli.main import main
    from cosim.execution.point import run_point
    from cosim.spec.loader import load_spec
    from cosim.system.builder import build_system

    md = read_model_description(str(path), validate=False)
    row = {"fmu": path.stem, "fmi": md.fmiVersion}
    experiment = md.defaultExperiment
    start = float(experiment.startTime or 0.0) if experiment else 0.0
    stop = float(experiment.stopTime or 1.0) if experiment and experiment.stopTime else 1.0
    step = float(experiment.stepSize) if experiment and experiment.stepSize else (stop - start) / 500
    stop, step = stop_override or stop, step_override or step
    spec = {"units": {"m": {"fmu": str(path)}}, "experiment": {"start": start, "stop": stop, "step": step},
            "record": ["m.*"]}
    spec_path = work / f"{path.stem}_{md.fmiVersion}.json"
    spec_path.write_text(json.dumps(spec))
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        inspect_code = main(["inspect", str(path)])
    if inspect_code != 0:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
            validate_code = main(["validate", str(spec_path)])
        message = " ".join(line.strip() for line in out.getvalue().splitlines() if "FMU" in line or "fix:" in line)
        row.update(result="refused" if validate_code == 2 else f"inspect exit {inspect_code}", detail=message)
        return row
    result = run_point(build_system(load_spec(spec_path)), None, record=True)
    if not result.ok:
        row.update(result="failed", detail=result.message)
        return row
    ours = result.traces
    numeric = [v.name for v in md.modelVariables if v.causality == "output"
               and v.type not in ("String", "Binary", "Clock")]
    reference = simulate_fmu(str(path), start_time=start, stop_time=stop, output_interval=step, output=numeric)
    worst, compared = 0.0, 0
    if len(reference) != len(ours):
        row.update(result="differs", detail=f"{len(ours)} samples, fmpy {len(reference)}")
        return row
    worst = float(np.max(np.abs(ours["time"].to_numpy() - reference["time"]))) if len(ours) else 0.0
    for name in numeric:
        expected = np.asarray(reference[name], dtype=float).reshape(len(reference), -1)
        columns = [c for c in ours.columns if c == f"m.{name}" or c.startswith(f"m.{name}[")]
        got = ours[columns].to_numpy(dtype=float)
        worst = max(worst, float(np.max(np.abs(got - expected))) if got.size else 0.0)
        compared += 1
    ended = f", {result.message}" if result.message else ""
    row.update(result="exact" if worst == 0.0 else f"max |diff| {worst:.3g}",
               detail=f"{compared} outputs, {len(ours)} samples to t={result.end_time:g}{ended}")
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m cosim.cli.reference_check", description=__doc__)
    parser.add_argument("paths", nargs="+", type=Path, help=".fmu files or folders holding them")
    parser.add_argument("--markdown", action="store_true", help="print a Markdown table")
    parser.add_argument("--stop", type=float, help="stop time instead of the default experiment's")
    parser.add_argument("--step", type=float, help="communication step instead of the default experiment's")
    args = parser.parse_args(argv)
    fmus = [p for path in args.paths for p in (sorted(path.rglob("*.fmu")) if path.is_dir() else [path])]
    with tempfile.TemporaryDirectory() as tmp:
        rows = [check(path, Path(tmp), args.stop, args.step) for path in fmus]
    if args.markdown:
        print("| FMU | FMI | cosim vs fmpy | detail |\n|---|---|---|---|")
        for r in rows:
            print(f"| {r['fmu']} | {r['fmi']} | {r['result']} | {r['detail'].replace('|', '/')} |")
    else:
        for r in rows:
            print(f"{r['fmu']:14s} FMI {r['fmi']}  {r['result']:12s} {r['detail']}")
    return 0 if all(r["result"] in ("exact", "refused") for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
