"""The examples at the end of every subcommand's --help: present, accepted by the parser as written, and naming
objectives, parameters and files that examples/drive_energy/spec.json really has."""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys

import pytest

from cosim.cli.examples import EXAMPLES, SPEC
from cosim.cli.main import _parser
from cosim.spec.loader import load_spec
from tests.helpers.paths import REPO


def _subcommands() -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in _parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def _written_by_examples() -> set[str]:
    """The files the examples' ``-o`` options write (export's SSP, export-fmu's FMU)."""
    written = set()
    for examples in EXAMPLES.values():
        for example, _why in examples:
            argv = shlex.split(example)
            if "-o" in argv:
                written.add(argv[argv.index("-o") + 1])
    return written


def test_every_subcommand_has_examples():
    assert set(_subcommands()) == set(EXAMPLES)


@pytest.mark.parametrize("command", sorted(EXAMPLES))
def test_help_ends_with_examples_the_parser_accepts(command):
    shown = subprocess.run([sys.executable, "-m", "cosim", command, "--help"], capture_output=True, text=True,
                           cwd=REPO, timeout=60)
    assert shown.returncode == 0
    help_text = shown.stdout
    assert "\nexamples:\n" in help_text
    parser = _parser()
    spec = load_spec(REPO / SPEC)
    names = {o.name for o in spec.objectives} | {p.target for p in spec.design.parameters}
    for example, _why in EXAMPLES[command]:
        assert f"  {example}\n" in help_text  # shown as written, not re-wrapped
        argv = shlex.split(example)
        assert argv[:2] == ["cosim", command]
        args = parser.parse_args(argv[1:])  # exits (SystemExit 2) on an option the command does not have
        assert args.handler is not None
        for option in ("x", "y", "color", "objective"):
            value = getattr(args, option, None)
            if isinstance(value, str):
                assert value in names, (example, value)
        for name, _sense in getattr(args, "objectives", None) or []:
            assert name in names, (example, name)
        if command == "new":  # its spec is the file it writes; what it reads is there, or another example writes it
            assert args.spec.startswith("results/") and not (REPO / args.spec).exists(), example
            assert (REPO / args.source).exists() or args.source in _written_by_examples(), (example, args.source)
            continue
        for path in (getattr(args, "spec", None), getattr(args, "target", None)):
            if path and not path.startswith("builtin:"):
                assert (REPO / path).exists(), (example, path)
