"""Print pyproject.toml's dependencies (and the test extra) pinned to their declared floors: ``x>=1.2`` -> ``x==1.2``.

.ci/minimum_versions installs these into a fresh venv and runs the suite there, so a floor that is too low fails.
Upper caps beside the floor are dropped (``fmpy>=0.3.32,<0.4`` -> ``fmpy==0.3.32``); a requirement pinned
exactly (``torch==2.13.0``) is printed as it is; the test extra's ``cosim[EXTRA]`` stands for that extra's
requirements.  Any other form (no bound, only a cap, ``~=``, two floors) is refused with exit 1: it has no
single version to test.

    python .ci/minimum_requirements.py [PYPROJECT]      (default: the repository's pyproject.toml)
"""

import sys
import tomllib
from pathlib import Path

from packaging.requirements import Requirement

path = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[1] / "pyproject.toml"
project = tomllib.loads(path.read_text())["project"]
extras = project.get("optional-dependencies", {})


def requirements(listed: list[str]) -> list[Requirement]:
    """``listed`` parsed, with cosim[EXTRA] replaced by that extra's requirements (recursively)."""
    out = []
    for text in listed:
        requirement = Requirement(text)
        if requirement.name == project["name"]:
            for extra in sorted(requirement.extras):
                out += requirements(extras[extra])
        else:
            out.append(requirement)
    return out


for requirement in requirements(project["dependencies"] + extras.get("test", [])):
    specifiers = list(requirement.specifier)
    floors = [s for s in specifiers if s.operator == ">="]
    caps = [s for s in specifiers if s.operator in ("<", "<=", "!=")]
    exact = len(specifiers) == 1 and specifiers[0].operator == "=="
    if not exact and (len(floors) != 1 or len(floors) + len(caps) != len(specifiers)) \
            or requirement.marker is not None:
        sys.exit(f"dependency '{requirement}' has neither a single '>=' floor nor an exact '==' pin; "
                 ".ci/minimum_requirements.py cannot pin it")
    extra = f"[{','.join(sorted(requirement.extras))}]" if requirement.extras else ""
    print(f"{requirement.name}{extra}=={(specifiers[0] if exact else floors[0]).version}")
