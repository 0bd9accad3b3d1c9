"""How a user's mistakes are listed on the terminal: every one when they are few, a bounded sample when many.

A spec of 10^5 wrong connections has 10^5 problems; listing them all printed
2 x 10^5 lines, in which a different mistake was lost.  Above :data:`SHOWN`
problems the list is a sample by kind (problems of one file, at the same path
but for its indices, with the same fix are one kind, e.g. ``$.connections[i].from``
naming a variable unit 's' lacks; the fix is said once per kind): the places go round the kinds in
the order found, one at a time, so no kind is hidden behind a numerous one
while there are places, and each kind shows its first problems.
One last line says how many more there are and how to see them all: ``cosim
--all-problems COMMAND ...`` lists every one, as before.  The exit code does
not depend on how many are shown.
"""

from __future__ import annotations

import re
import sys
from typing import Any, Sequence, TextIO

SHOWN = 50  # problems listed at most, unless --all-problems
ALL_PROBLEMS = "--all-problems"


def print_problems(problems: Sequence[Any], every: bool = False, stream: TextIO | None = None) -> None:
    """Print ``problems`` (:class:`cosim.errors.Problem`) on ``stream`` (stderr): all of them when ``every``
    or when there are at most SHOWN, otherwise SHOWN of them grouped by kind, then how many more."""
    out = stream if stream is not None else sys.stderr
    if len(problems) == 1 and not problems[0].file and not problems[0].path:  # a command-line mistake
        print(f"cosim: error: {problems[0]}", file=out)
        return
    count = len(problems)
    if every or count <= SHOWN:
        print(f"{count} problem{'s' if count != 1 else ''} found:", file=out)
        for problem in problems:
            print(f"- {problem}", file=out)
        return
    kinds = _by_kind(problems)
    shown = _share(SHOWN, [len(members) for members in kinds.values()])
    print(f"{count} problems found; {SHOWN} of them, by kind ({len(kinds)} kind{'s' if len(kinds) != 1 else ''}):",
          file=out)
    listed = 0
    for (_, _, fix), members, n in zip(kinds, kinds.values(), shown):
        if not n:
            continue
        for problem in members[:n]:
            where = ": ".join(part for part in (problem.file, problem.path) if part)
            print(f"- {where}: {problem.message}" if where else f"- {problem.message}", file=out)
        listed += n
        if fix:
            print(f"    fix{f' (all {len(members)} of this kind)' if len(members) > 1 else ''}: {fix}", file=out)
    unseen = sum(1 for n in shown if not n)
    kinds_unseen = f", of {unseen} kind{'s' if unseen != 1 else ''} not shown" if unseen else " like these"
    print(f"... and {count - listed} more problems{kinds_unseen} (add {ALL_PROBLEMS} to the command to list "
          "every one)", file=out)


_INDEX = re.compile(r"\[\d+\]")  # $.connections[7], ssd:Connection[7]: the place in a list


def _by_kind(problems: Sequence[Any]) -> dict[tuple[str, str, str], list[Any]]:
    """Problems grouped by (file, path without its indices, fix), kinds and members in the order found."""
    kinds: dict[tuple[str, str, str], list[Any]] = {}
    for problem in problems:
        kinds.setdefault((problem.file, _INDEX.sub("[]", problem.path), problem.fix), []).append(problem)
    return kinds


def _share(places: int, sizes: list[int]) -> list[int]:
    """How many of each group to show among ``places``: one each in order while places last, then the rest
    in turn, never more than a group has."""
    shown = [0] * len(sizes)
    while places > 0:
        before = places
        for i, size in enumerate(sizes):
            if places and shown[i] < size:
                shown[i] += 1
                places -= 1
        if places == before:  # every group fully shown
            break
    return shown
