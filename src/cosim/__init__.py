"""cosim: FMI co-simulation of FMUs and Python units, swept, optimised and analysed over design spaces.

What a notebook or script needs, in a few names (each imported on first use):

- :func:`load_spec` reads and checks a spec.json; :func:`run` runs one point of it.
- :func:`sweep`, :func:`optimize` and :func:`sensitivity` are the three studies of ``cosim sweep | optimize |
  sensitivity``: they write a results folder and return its table.
- :func:`read_results` reads a results folder or table as a pandas DataFrame (its metadata in ``df.attrs``);
  :func:`pareto` gives its non-dominated rows.
- :class:`PythonUnit` and :class:`Variable` are what a Python unit is made of; :class:`UnitKind` and
  :func:`register_unit_kind` add a kind of unit.
- :class:`CosimError` is the base of every error cosim raises on purpose (:class:`UserError` and its
  :class:`SpecError` carry :class:`Problem` objects; :class:`UnitError` is a unit's failure).

``import cosim`` is cheap: it imports neither the engine, nor Dask, nor pandas, and registers no exit hooks.
The layers of the package, and where a new unit kind, algorithm or study plugs in, are described in
docs/architecture.md.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

if TYPE_CHECKING:  # for type checkers and IDEs; at run time the names come from __getattr__
    import pandas as pd

    from cosim.errors import CosimError, Problem, SpecError, UnitError, UserError
    from cosim.execution.point import run_point
    from cosim.execution.run import Execution, RunResult
    from cosim.spec.loader import Spec, load_spec
    from cosim.system.builder import System, build_system
    from cosim.units.kind import UnitKind
    from cosim.units.protocol import Variable
    from cosim.units.python.unit import PythonUnit
    from cosim.units.registry import register_unit_kind

__version__ = "0.1.0"

# public name -> the module that defines it (imported when the name is first used)
_LAZY = {
    "CosimError": "cosim.errors", "Problem": "cosim.errors", "SpecError": "cosim.errors",
    "UnitError": "cosim.errors", "UserError": "cosim.errors",
    "Execution": "cosim.execution.run", "RunResult": "cosim.execution.run", "run_point": "cosim.execution.point",
    "Spec": "cosim.spec.loader", "load_spec": "cosim.spec.loader",
    "System": "cosim.system.builder", "build_system": "cosim.system.builder",
    "Variable": "cosim.units.protocol", "PythonUnit": "cosim.units.python.unit",
    "UnitKind": "cosim.units.kind", "register_unit_kind": "cosim.units.registry",
}
# the public names, written out for readers and linters (tests/project/test_public_api.py checks they match _LAZY)
__all__ = ["CosimError", "Execution", "Problem", "PythonUnit", "RunResult", "Spec", "SpecError", "System",
    "UnitError", "UnitKind", "UserError", "Variable", "__version__", "build_system", "load_spec", "optimize",
    "pareto", "read_results", "register_unit_kind", "run", "run_point", "sensitivity", "sweep"]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
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
    from cosim.execution.point import run_point
    from cosim.spec.loader import load_spec
    from cosim.system.builder import build_system

    return run_point(build_system(load_spec(spec_path)), values, record=record)


def sweep(spec_path: str | Path, workers: int | None = None, out: str | Path | None = None,
          scheduler: str | None = None, timeout: float | None = None, resume: bool = False,
          **options: Any) -> pd.DataFrame:
    """Evaluate every point of the spec's design space on Dask; returns the results table (always a DataFrame).

    ``workers`` local workers (default: one per core, as ``cosim sweep``), or a running ``scheduler``
    (address).  ``out`` keeps the results folder; ``timeout`` is the seconds a point may run; ``resume`` runs
    only the points missing in ``out``.  Further options: ``batch_size``, ``csv``, ``progress`` (a stream),
    ``quiet``, or the option records ``where``, ``how`` and ``show`` (:mod:`cosim.studies.options`).  See
    :class:`cosim.studies.sweep.Sweep`.

    Raises SpecError for a bad spec or design space, SweepError when ``out``
    or the scheduler cannot be used.
    """
    from cosim.studies.sweep import Sweep

    return Sweep(spec_path, workers=workers, out=out, scheduler=scheduler, timeout=timeout, resume=resume,
                 **options).run()


def optimize(spec_path: str | Path, out: str | Path, **options: Any) -> pd.DataFrame:
    """Search the spec's design space for the Pareto front of its objectives; returns one row per evaluation.

    Options as ``cosim optimize``: ``objectives`` ({name: 'min'|'max'}), ``budget``, ``sampler``, ``batch``,
    ``seed``, ``resume``, ``workers``, ``scheduler``, ``cluster``, ``timeout``, ``progress``, ``quiet``, and
    ``storage`` (an Optuna storage URL such as ``sqlite:///study.db`` that also receives the trials, for
    optuna-dashboard and Optuna's plots) with ``study_name``, or the option records ``where``, ``how``,
    ``stop`` and ``show`` (:mod:`cosim.studies.options`; see :class:`cosim.studies.optimize.Optimization`).
    Raises SpecError for a bad spec, OptimizeError when ``out`` or the cluster cannot be used.
    """
    from cosim.studies.optimize import optimize as run_optimization

    return run_optimization(spec_path, out, **options)


def sensitivity(spec_path: str | Path, out: str | Path, method: str = "sobol", n: int | None = None,
                **options: Any) -> pd.DataFrame:
    """Sobol (or Morris) indices of the spec's objectives over its parameter box; returns the indices.

    Runs the sample as a sweep into ``out`` (its rows in ``out/results.parquet``) and writes
    ``out/sensitivity.csv``; ``options`` as ``cosim sensitivity`` (``seed``, ``objectives``, ``workers``,
    ``scheduler``, ``timeout``, ``resume``, ``quiet``).  Raises SpecError for a bad spec, SensitivityError for
    bad settings.
    """
    from cosim.studies.sensitivity import SensitivityStudy

    _, indices = SensitivityStudy(spec_path, out, method=method, n=n, **options).run()
    return indices


def read_results(path: str | Path, spec: str | Path | None = None) -> pd.DataFrame:
    """The results table of a study folder, ``results.parquet`` or ``.csv`` as a DataFrame.

    ``df.attrs`` holds ``metadata`` (the folder's metadata.json, or None), ``spec`` (the study's spec, or None)
    and ``units`` ({column: unit}).  ``spec`` names a spec.json for a table stored without one.
    Raises AnalysisError (a UserError) when the table is missing or unreadable.
    """
    from cosim.analysis.table import load_results

    table = load_results(path, spec)
    df = table.df
    df.attrs.update(metadata=table.metadata, spec=table.spec,
                    units={c: table.unit(c) for c in table.columns if table.unit(c)})
    return df


def pareto(path: str | Path, minimize: Sequence[str] = (), maximize: Sequence[str] = (),
           where: str | None = None) -> pd.DataFrame:
    """The non-dominated ok rows of a results table (as ``cosim pareto``): ties kept, rows with NaN left out.

    Objectives default to those of the study's spec with a ``sense``.  ``where`` filters rows first (the
    ``--where`` expression).  Raises AnalysisError for an unknown column or when no objective is known.
    """
    from cosim.analysis.pareto import front_of, resolve_objectives
    from cosim.analysis.table import load_results

    table = load_results(path)
    chosen = [(name, "min") for name in minimize] + [(name, "max") for name in maximize]
    objectives = resolve_objectives(table, chosen or None)
    front, _ = front_of(table, objectives, where)
    return table.df.loc[front]
