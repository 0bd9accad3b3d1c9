"""Problems of an SSP's flattened spec reported where the user can find them: at the SSD's elements.

An SSP run alone becomes a spec the user never wrote; a problem found in it (``$.units.SuT.motor...``) is moved
to the SSD element it comes from: the component, the system (for its ``connectors`` unit), else the root
system, with the message kept.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Iterable

from cosim.errors import Problem, SpecError

_UNIT_PATH = re.compile(r"^\$\.units\.(.+)$")


def at_ssd_elements(problems: Iterable[Problem], path: str | Path, variant: str | None = None) -> list[Problem]:
    """``problems`` with every JSON path (``$...``) of the spec flattened from the SSP at ``path`` replaced by
    the file and element path of the SSD element it comes from; other problems unchanged.  Reads the SSP again
    (only when some problem has a JSON path); when that read fails, its own problems are returned."""
    problems = list(problems)
    if not any(p.path.startswith("$") for p in problems):
        return problems
    from cosim.ssp.reader import read_ssp

    try:
        elements = read_ssp(path, variant).elements
    except SpecError as exc:
        return list(exc.problems)
    located = []
    for problem in problems:
        if not problem.path.startswith("$"):
            located.append(problem)
            continue
        label, where = elements[""]
        unit = _UNIT_PATH.match(problem.path)
        if unit:  # the longest unit name the path starts with ('SuT.motor' in '$.units.SuT.motor.parameters.k')
            rest = unit.group(1)
            for name in sorted((n for n in elements if n), key=len, reverse=True):
                if rest == name or rest.startswith(name + "."):
                    label, where = elements[name]
                    break
        located.append(Problem(label, where, problem.message, problem.fix))
    return located
