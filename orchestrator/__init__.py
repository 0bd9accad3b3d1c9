"""cosim's engine: FMI co-simulation of FMUs and Python units, swept over design spaces.

The public API in a few names:

- :func:`load_spec` reads and checks a spec.json; :func:`build_system` checks
  that its units and connections fit together.
- :class:`Execution` runs one design point; :func:`run` does all three steps.
- :class:`PythonUnit` and :class:`Variable` are what a Python unit is made of.
"""

from __future__ import annotations

from typing import Any, Mapping

from .execution import Execution, RunResult
from .problems import Problem, SpecError
from .spec import Spec, load_spec
from .system import System, build_system
from .unit import UnitError, Variable
from .units.python import PythonUnit
from .sweep import sweep

__all__ = ["Execution", "Problem", "PythonUnit", "RunResult", "Spec", "SpecError", "System", "UnitError",
           "Variable", "build_system", "load_spec", "run", "sweep"]
__version__ = "0.1.0"


def run(spec_path: str, values: Mapping[str, Any] | None = None, record: bool = True) -> RunResult:
    """Run one point of the spec at ``spec_path``; ``values`` maps 'unit.param' to a value.

    Raises SpecError when the spec or a value does not fit; a failing run is
    reported in the result's status and message instead.
    """
    from .point import run_point

    return run_point(build_system(load_spec(spec_path)), values, record=record)
