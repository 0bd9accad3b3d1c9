"""cosim's engine: FMI co-simulation of FMUs and Python units, swept over design spaces.

The public API in a few names:

- :func:`run` runs one point of a spec; :func:`sweep` every point of its
  design space on Dask (a pandas DataFrame, one row per point).
- :func:`load_spec` reads and checks a spec.json; :func:`build_system` checks
  that its units and connections fit together; :func:`run_point` runs one
  point of a built system; :class:`Execution` is the run itself.
- :class:`PythonUnit` and :class:`Variable` are what a Python unit is made of;
  :class:`UnitKind` and :func:`register_unit_kind` add a kind of unit.
- :class:`CosimError` is the base of every error cosim raises on purpose
  (:class:`UserError` with :class:`Problem` objects, :class:`UnitError`).

``import orchestrator`` is cheap: the names are imported on first use, so it
loads neither the engine, nor Dask, nor registers exit hooks.
"""

from __future__ import annotations

import importlib
import sys
import types
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

if TYPE_CHECKING:  # for type checkers and IDEs; at run time the names come from __getattr__
    import pandas as pd

    from .errors import CosimError, Problem, UnitError, UserError
    from .execution import Execution, RunResult
    from .point import run_point
    from .problems import SpecError
    from .spec import Spec, load_spec
    from .system import System, build_system
    from .unit import Variable
    from .unit_kinds import UnitKind, register_unit_kind
    from .units.python import PythonUnit

__version__ = "0.1.0"

# public name -> the module that defines it (imported when the name is first used)
_LAZY = {
    "CosimError": ".errors", "Problem": ".errors", "UnitError": ".errors", "UserError": ".errors",
    "Execution": ".execution", "RunResult": ".execution", "run_point": ".point", "SpecError": ".problems",
    "Spec": ".spec", "load_spec": ".spec", "System": ".system", "build_system": ".system", "Variable": ".unit",
    "UnitKind": ".unit_kinds", "register_unit_kind": ".unit_kinds", "PythonUnit": ".units.python",
}
__all__ = sorted([*_LAZY, "run", "sweep"])


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})


def run(spec_path: str | Path, values: Mapping[str, Any] | None = None, record: bool = True) -> RunResult:
    """Run one point of the spec at ``spec_path``; ``values`` maps 'unit.param' to a value.

    Raises SpecError when the spec or a value does not fit; a failing run is
    reported in the result's status and message instead.
    """
    from .point import run_point
    from .spec import load_spec
    from .system import build_system

    return run_point(build_system(load_spec(spec_path)), values, record=record)


def sweep(spec_path: str | Path, workers: int | None = None, out: str | Path | None = None,
          scheduler: str | None = None, timeout: float | None = None, resume: bool = False,
          **options: Any) -> pd.DataFrame:
    """Evaluate every point of the spec's design space on Dask; returns the results table (always a DataFrame).

    ``workers`` local worker processes (default: one per core, as ``cosim
    sweep``), or a running ``scheduler`` (address).  ``out`` keeps the results
    folder; ``timeout`` is the seconds a point may run; ``resume`` runs only
    the points missing in ``out``.  Further options: ``batch_size``, ``csv``,
    ``progress`` (a stream), ``quiet``.  See :class:`orchestrator.sweep.Sweep`.

    Raises SpecError for a bad spec or design space, SweepError when ``out``
    or the scheduler cannot be used.
    """
    from .sweep import Sweep

    return Sweep(spec_path, workers=workers, out=out, scheduler=scheduler, timeout=timeout, resume=resume,
                 **options).run()


class _Package(types.ModuleType):
    """Keeps the function :func:`sweep` when the submodule ``orchestrator.sweep`` is imported.

    Python sets a package's attribute to a submodule when that submodule is
    first imported; here the function of the same name must stay (the
    submodule is still reachable as ``sys.modules['orchestrator.sweep']``).
    """

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "sweep" and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
