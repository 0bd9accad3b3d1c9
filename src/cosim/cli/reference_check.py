"""Run FMUs built elsewhere (e.g. the Modelica Reference FMUs) through cosim and compare with fmpy.

    python -m cosim.cli.reference_check FMU_OR_FOLDER ... [--markdown]

For each FMU: ``cosim inspect`` must succeed (or, for an FMU cosim does not run, ``cosim validate`` must refuse
it with exit code 2); ``cosim run`` of a one-unit spec over the FMU's default experiment, recording every output,
is compared sample by sample with fmpy's ``simulate_fmu`` at the same step.  Prints one line (or Markdown table
row) per FMU: whether it ran, where it ended, the largest difference from fmpy, or cosim's refusal message.

Each FMU runs in a child process given ``--timeout`` seconds (default 120): an FMU whose default experiment
is far longer than its internal solver can cover (the Reference FMU *Roberts*: stop time 1e7 with a fixed internal
Euler step of 1e-3 s, about 1e10 steps) is reported as ``timed out`` with the experiment it was given, instead of
the whole check hanging; ``--stop``/``--step`` run it over a shorter one.

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


def _check_in_child(connection, path: Path, work: Path, stop: float | None, step: float | None) -> None:
    """The child's side of :func:`check_bounded`: ``check``'s row (or its error as a row) sent back."""
    try:
        row = check(path, work, stop, step)
    except Exception as exc:  # reported as that FMU's row: the other FMUs are still checked
        row = {"fmu": path.stem, "fmi": "?", "result": "error", "detail": f"{type(exc).__name__}: {exc}"}
    connection.send(row)
    connection.close()


def check_bounded(path: Path, work: Path, stop: float | None, step: float | None, timeout: float) -> dict:
    """``check`` in a child process that is stopped after ``timeout`` seconds: a row whose result is
    ``timed out`` then, naming the experiment it ran (an FMU never hangs the whole check)."""
    import multiprocessing

    context = multiprocessing.get_context("spawn")  # no forked copy of this process's threads or FMUs
    receiver, sender = context.Pipe(duplex=False)
    child = context.Process(target=_check_in_child, args=(sender, path, work, stop, step), daemon=True)
    child.start()
    sender.close()
    try:
        if receiver.poll(timeout):
            return receiver.recv()
        given = ", ".join(f"--{k} {v:g}" for k, v in (("stop", stop), ("step", step)) if v is not None)
        return {"fmu": path.stem, "fmi": _fmi_version(path), "result": "timed out",
                "detail": f"no result within {timeout:g} s over "
                          f"{'its default experiment' if not given else given}; give a shorter --stop (or a "
                          f"longer --timeout)"}
    finally:
        if child.is_alive():
            child.kill()
        child.join()


def _fmi_version(path: Path) -> str:
    from fmpy import read_model_description

    try:
        return read_model_description(str(path), validate=False).fmiVersion
    except Exception:  # the row still says which FMU timed out
        return "?"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m cosim.cli.reference_check", description=__doc__)
    parser.add_argument("paths", nargs="+", type=Path, help=".fmu files or folders holding them")
    parser.add_argument("--markdown", action="store_true", help="print a Markdown table")
    parser.add_argument("--stop", type=float, help="stop time instead of the default experiment's")
    parser.add_argument("--step", type=float, help="communication step instead of the default experiment's")
    parser.add_argument("--timeout", type=float, default=120.0,
                        help="seconds one FMU may take before it is stopped and reported 'timed out' (default 120)")
    args = parser.parse_args(argv)
    if args.timeout <= 0:
        parser.error(f"--timeout {args.timeout:g}: give a positive number of seconds")
    fmus = [p for path in args.paths for p in (sorted(path.rglob("*.fmu")) if path.is_dir() else [path])]
    with tempfile.TemporaryDirectory() as tmp:
        rows = [check_bounded(path, Path(tmp), args.stop, args.step, args.timeout) for path in fmus]
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
