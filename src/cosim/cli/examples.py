"""Examples at the end of each subcommand's ``--help`` (argparse epilogs), written against
examples/drive_energy/spec.json so that they can be tried from a source checkout as they are.

tests/cli/test_cli_examples.py parses every line with cosim's own parser: an example that names an option the
command no longer has fails there.
"""

from __future__ import annotations

import argparse

SPEC = "examples/drive_energy/spec.json"
TABLE = "results/drive_energy"

EXAMPLES: dict[str, list[tuple[str, str]]] = {
    "validate": [(f"cosim validate {SPEC}", "every problem of the spec at once, with JSON paths and fixes"),
                 (f"cosim validate {SPEC} --for optimize", "also what cosim optimize would refuse")],
    "run": [(f"cosim run {SPEC} --out results/one", "one run; traces in results/one"),
            (f"cosim run {SPEC} --set energy.gear_ratio=120 --stop 1.5", "another parameter value and stop time"),
            (f"cosim run {SPEC} --point ID --results {TABLE}", "re-run a design of a sweep (IDs from its table)")],
    "inspect": [(f"cosim inspect {SPEC}", "units, ports and connections of the spec"),
                ("cosim inspect builtin:motor_gear_energy_fmi3", "the variables of one FMU")],
    "export": [(f"cosim export {SPEC} -o {TABLE}/drive.ssp", "the system as an SSP 2.0 archive"),
               (f"cosim export {SPEC} -o {TABLE}/drive.ssp --fmi 2", "with FMI 2.0 built-ins (for libcosim)")],
    "export-fmu": [("cosim export-fmu examples/drive_energy/drive_profile.py:DriveProfile -o results/drive.fmu",
                    "a Python unit as an FMI 2.0 FMU")],
    "new": [(f"cosim new {TABLE}/drive_ssp.json --from {TABLE}/drive.ssp",
             "a starter spec of an SSP (after cosim export above): its ports recorded, one objective, one parameter"),
            (f"cosim new {TABLE}/drive_fmu.json --from results/drive.fmu --force",
             "the same for an FMU (after cosim export-fmu), replacing a starter written before")],
    "sweep": [(f"cosim sweep {SPEC} --dry-run", "count the points and estimate the time first"),
              (f"cosim sweep {SPEC} --out {TABLE}", "every design point on a local Dask cluster"),
              (f"cosim sweep {SPEC} --out {TABLE} --resume", "go on after Ctrl-C or a kill"),
              (f"cosim sweep {SPEC} --scheduler tcp://host:8786", "on a running Dask scheduler")],
    "optimize": [(f"cosim optimize {SPEC} --budget 40 --seed 1", "the Pareto front of the objectives with a sense"),
                 (f"cosim optimize {SPEC} --min energy --min peak_power --sampler nsga2 --batch 8",
                  "chosen objectives and sampler"),
                 (f"cosim optimize {SPEC} --out {TABLE}_optimize --storage sqlite:///results/optuna.db",
                  "the trials also in an Optuna storage: optuna-dashboard sqlite:///results/optuna.db")],
    "sensitivity": [(f"cosim sensitivity {SPEC} -n 64 --objective energy", "Sobol indices of each parameter"),
                    (f"cosim sensitivity {SPEC} --method morris -n 16", "Morris screening, fewer runs")],
    "plot": [(f"cosim plot {TABLE} --x energy.gear_ratio --y energy --color drive.duration -o {TABLE}/fig.png",
              "a point cloud of the table")],
    "pareto": [(f"cosim pareto {TABLE} --min energy --min peak_power --csv {TABLE}/front.csv",
                "the designs no other beats in both")],
    "report": [(f"cosim report {TABLE} -o {TABLE}/report.html", "one HTML page: table, front, figures")],
    "surrogate": [(f"cosim surrogate {TABLE} --objective energy", "a surrogate of energy: Q², ranking, in "
                   f"{TABLE}/surrogate/"),
                  (f"cosim surrogate {TABLE} --predict {TABLE}/designs.csv -o {TABLE}/predicted.csv",
                   "predictions and uncertainty for new designs")],
    "export-surrogate": [(f"cosim export-surrogate {TABLE} -o {TABLE}/energy.fmu",
                          "the surrogates as an FMI 2.0 FMU in C: a cheap stand-in unit")],
    "explore": [(f"cosim explore {TABLE}", "the decision room in the browser (prints its link)")],
}


def epilog(command: str) -> str | None:
    """The examples of ``command`` as an argparse epilog, or None when it has none."""
    lines = EXAMPLES.get(command)
    if not lines:
        return None
    return "examples:\n" + "\n".join(f"  {example}\n      {why}" for example, why in lines)


def add_examples(subparsers: argparse._SubParsersAction) -> None:
    """Give every registered subcommand its examples (kept as written: RawDescriptionHelpFormatter)."""
    for name, parser in subparsers.choices.items():
        text = epilog(name)
        if text:
            parser.epilog = text
            parser.formatter_class = argparse.RawDescriptionHelpFormatter
