"""Print pyproject.toml's dependencies (and the test extra) pinned to their declared floors: ``x>=1.2`` -> ``x==1.2``.

.ci/run installs these into a fresh venv and runs the suite there, so a floor that is too low fails CI.
"""

import re
import sys
import tomllib
from pathlib import Path

project = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())["project"]
for requirement in project["dependencies"] + project["optional-dependencies"]["test"]:
    pinned, count = re.subn(r">=", "==", requirement)
    if count != 1:
        sys.exit(f"dependency {requirement!r} has no single '>=' floor; .ci/minimum_requirements.py cannot pin it")
    print(pinned)
