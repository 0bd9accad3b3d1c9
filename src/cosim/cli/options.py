"""Command-line options shared by several ``cosim`` subcommands (imported by the subcommand modules)."""

from __future__ import annotations

import argparse
from typing import Any


def add_experiment_options(p: argparse.ArgumentParser) -> None:
    """--start/--stop/--step/--algorithm: override the experiment (what an SSP often lacks)."""
    group = p.add_argument_group("experiment (overrides the spec's; needed for an SSP without them)")
    group.add_argument("--start", type=float, metavar="S", help="start time (s)")
    group.add_argument("--stop", type=float, metavar="S", help="stop time (s)")
    group.add_argument("--step", type=float, metavar="S", help="communication step size (s)")
    from cosim.master.registry import ALGORITHMS

    group.add_argument("--algorithm", choices=tuple(ALGORITHMS), help="master algorithm")


def experiment_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The experiment fields given on the command line."""
    return {k: getattr(args, k) for k in ("start", "stop", "step", "algorithm") if getattr(args, k, None) is not None}


def message_line(message: object, width: int = 120) -> str:
    """The first line of a row's message, cut to ``width`` characters, for a summary on the terminal.

    A failed row's message may go on with the unit's traceback (cosim.errors.unit_traceback); the summary shows
    what failed, and says where the rest is.
    """
    text = str(message)
    first, _, rest = text.partition("\n")
    shown = first[:width]
    return shown + (" (the traceback is in the 'message' column)" if rest.strip() else "")
