"""A thin alias of :mod:`cosim` under its old name, for FMUs exported by earlier versions of cosim.

``cosim export-fmu`` used to write FMUs whose Python code imports ``orchestrator.unit`` (and user units written
then import ``orchestrator.units.python``).  This package maps every old module name onto the module of the
``cosim`` package that now holds it, so those FMUs and units keep working.  New code imports ``cosim``; this
alias will be removed on :data:`REMOVAL` (release 0.3), and importing it says so once (a FutureWarning, which
Python shows by default).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings
from typing import Any

import cosim

REMOVAL = "2027-06-01"
warnings.warn(f"'orchestrator' is the old name of 'cosim', kept for FMUs exported by cosim before 2026-11-23; it "
              f"will be removed on {REMOVAL} (release 0.3): import cosim instead, and export such FMUs again with "
              "'cosim export-fmu'", FutureWarning, stacklevel=2)

# old module name (below orchestrator.) -> the cosim module that holds it now
MOVED = {
    "errors": "cosim.errors",
    "problems": "cosim.errors",
    "archive": "cosim.util.archive",
    "file_digest": "cosim.util.digest",
    "limits": "cosim.util.limits",
    "quantities": "cosim.util.quantities",
    "spec_json": "cosim.util.strict_json",
    "unit": "cosim.units.protocol",
    "unit_kinds": "cosim.units.registry",
    "units.fmu": "cosim.units.fmu.description",
    "units.fmi2": "cosim.units.fmu.fmi2",
    "units.fmi3": "cosim.units.fmu.fmi3",
    "units.fmi_instance": "cosim.units.fmu.instance",
    "units.fmpy_internals": "cosim.units.fmu.fmpy_internals",
    "units.model_exchange": "cosim.units.fmu.model_exchange",
    "units.python": "cosim.units.python.unit",
    "units.python_batch": "cosim.units.python.batch",
    "data_files": "cosim.units.python.data_files",
    "import_guard": "cosim.units.python.import_guard",
    "units.player": "cosim.units.player",
    "units": "cosim.units",
    "algorithms": "cosim.master.algorithms",
    "observers": "cosim.master.observers",
    "stepping": "cosim.system.stepping",
    "ssp.archive": "cosim.ssp.archive",
    "ssp.reader": "cosim.ssp.reader",
    "ssp.xml": "cosim.ssp.xml",
    "ssp.writer": "cosim.export.ssp",
    "ssp": "cosim.ssp",
    "spec": "cosim.spec.loader",
    "design": "cosim.spec.design",
    "expressions": "cosim.spec.expressions",
    "system": "cosim.system.builder",
    "system_parts": "cosim.system.parts",
    "connection_checks": "cosim.system.connection_checks",
    "connection_units": "cosim.system.connection_units",
    "value_checks": "cosim.system.value_checks",
    "signals": "cosim.system.signals",
    "study_checks": "cosim.system.study_checks",
    "validate": "cosim.system.validate",
    "execution": "cosim.execution.run",
    "point": "cosim.execution.point",
    "lockstep": "cosim.execution.lockstep",
    "fmu_export": "cosim.export.fmu",
    "results": "cosim.results.store",
    "results_folder": "cosim.results.folder",
    "folder_lock": "cosim.results.lock",
    "table_columns": "cosim.results.columns",
    "unit_checksums": "cosim.results.checksums",
    "cluster": "cosim.parallel.cluster.cluster_file",
    "early_cluster": "cosim.parallel.cluster.early",
    "evaluator": "cosim.parallel.cluster.client",
    "isolation": "cosim.parallel.isolation.runner",
    "scheduler_check": "cosim.parallel.cluster.scheduler_check",
    "dashboard": "cosim.parallel.dashboard.web_server",
    "dashboard_on_demand": "cosim.parallel.dashboard.on_demand",
    "dashboard_points": "cosim.parallel.dashboard.points",
    "interrupts": "cosim.parallel.cluster.interrupts",
    "viewers": "cosim.analysis.viewers",
    "analysis.explorer": "cosim.analysis.explorer",
    "analysis.pareto": "cosim.analysis.pareto",
    "analysis.plots": "cosim.analysis.plots",
    "analysis.report": "cosim.analysis.report",
    "analysis.rerun": "cosim.analysis.rerun",
    "analysis.sensitivity": "cosim.analysis.sensitivity",
    "analysis.table": "cosim.analysis.table",
    "analysis.traces": "cosim.analysis.traces",
    "analysis": "cosim.analysis",
    "sweep": "cosim.studies.sweep",
    "optimize": "cosim.studies.optimize",
    "sensitivity_study": "cosim.studies.sensitivity",
    "driver": "cosim.studies.driver",
    "inspection": "cosim.cli.inspection",
    "cli": "cosim.cli.main",
    "cli_options": "cosim.cli.options",
    "analysis_cli": "cosim.cli.analysis",
    "export_cli": "cosim.cli.export",
    "optimize_cli": "cosim.cli.optimize",
    "sensitivity_cli": "cosim.cli.sensitivity",
    "spec_cli": "cosim.cli.spec",
    "sweep_cli": "cosim.cli.sweep",
}


class _AliasFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds ``orchestrator.X`` as the module it became and registers it under both names."""

    def find_spec(self, fullname: str, path: Any = None, target: Any = None) -> Any:
        old = fullname.partition(".")[2]
        if fullname.startswith("orchestrator.") and old in MOVED:
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec: Any) -> Any:
        return importlib.import_module(MOVED[spec.name.partition(".")[2]])

    def exec_module(self, module: Any) -> None:
        pass  # the cosim module is already executed


if not any(isinstance(finder, _AliasFinder) for finder in sys.meta_path):
    sys.meta_path.insert(0, _AliasFinder())


def __getattr__(name: str) -> Any:
    return getattr(cosim, name)
