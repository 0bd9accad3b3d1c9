"""Cross-check with another engine: libcosim (libcosimpy from PyPI) runs the SSP cosim exports.

libcosim's fixed-step algorithm steps every unit from the values exchanged at
the end of the previous step, as cosim's Jacobi master does.  The system is a
ring of three FMI 2.0 ``linear_ode`` FMUs (built from fmus/) with a
LinearTransformation on one connection; libcosim reads the parameters from
the exported .ssv files and the step from the OSP annotation.  (libcosim
does not propagate outputs through units with direct feed-through while
initializing and cosim does, so a feed-through unit in a loop differs in the
first steps; these units have none.)
"""

from __future__ import annotations

import json
import os
import zipfile

import numpy as np
import pytest

from cosim.execution.run import Execution
from cosim.export.ssp import export_ssp
from cosim.system.validate import check_spec

RING = {
    "name": "ring",
    "units": {
        "a": {"fmu": "builtin:linear_ode_fmi2", "parameters": {"a": -1.0, "b": 1.0, "x0": 1.0}},
        "b": {"fmu": "builtin:linear_ode_fmi2", "parameters": {"a": -0.5, "b": -2.0, "x0": 0.0}},
        "c": {"fmu": "builtin:linear_ode_fmi2", "parameters": {"a": 0.3, "b": 0.7, "x0": -0.5}},
    },
    "connections": [
        {"from": "a.y", "to": "b.u", "factor": 2.5, "offset": 0.1},
        {"from": "b.y", "to": "c.u"},
        {"from": "c.y", "to": "a.u"},
    ],
    "experiment": {"stop": 1.0, "step": 0.01, "algorithm": "jacobi"},
    "record": ["a.y", "b.y", "c.y"],
}


def _libcosimpy():
    try:
        import libcosimpy  # noqa: F401
    except ImportError:
        if os.environ.get("CI") == "true":
            raise
        pytest.skip("libcosimpy is not installed (pip install libcosimpy==0.0.6)")


def run_libcosim(folder, step: float, n_steps: int, names=("a", "b", "c"), variable: str = "y"):
    """Step libcosim n_steps times through the unpacked SSP in ``folder``; ``variable`` of each unit after each step."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.ERROR)
    execution = CosimExecution.from_ssp_file(str(folder), step_size=round(step * 1e9))
    index = {s.name.decode(): s.index for s in execution.slave_infos()}
    reference = {n: next(v.reference for v in execution.slave_variables(index[n]) if v.name.decode() == variable)
                 for n in names}
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    rows = []
    for _ in range(n_steps):
        execution.step()
        rows.append([observer.last_real_values(index[n], [reference[n]])[0] for n in names])
    return np.array(rows)


def test_libcosim_runs_the_exported_ssp_to_the_same_values(tmp_path):
    _libcosimpy()
    (tmp_path / "ring.json").write_text(json.dumps(RING))
    archive = export_ssp(check_spec(tmp_path / "ring.json"), tmp_path / "ring.ssp")
    with zipfile.ZipFile(archive) as zf:
        zf.extractall(tmp_path / "unpacked")
    ours = Execution(check_spec(archive), record=True).run()
    assert ours.ok, ours.message
    theirs = run_libcosim(tmp_path / "unpacked", 0.01, 100)
    mine = ours.traces[["a.y", "b.y", "c.y"]].to_numpy()[1:]
    assert theirs.shape == mine.shape == (100, 3)
    assert np.max(np.abs(theirs - mine)) <= 1e-12
    assert not np.allclose(mine[-1], mine[0])  # the ring really moved


def test_export_of_fmi3_builtins_warns_and_fmi_2_writes_what_libcosim_loads(tmp_path, capsys):
    from cosim.cli.main import main

    _libcosimpy()
    ring3 = json.loads(json.dumps(RING).replace("_fmi2", "_fmi3"))  # the built-ins as the docs name them
    (tmp_path / "ring.json").write_text(json.dumps(ring3))
    assert main(["export", str(tmp_path / "ring.json"), "-o", str(tmp_path / "three.ssp")]) == 0
    err = capsys.readouterr().err
    assert "warning: FMI 3.0 FMUs in the archive (a, b, c)" in err and "cosim export --fmi 2" in err
    with zipfile.ZipFile(tmp_path / "three.ssp") as zf:
        zf.extractall(tmp_path / "three")
    with pytest.raises(AssertionError, match="Unable to create execution"):  # what the warning is about
        run_libcosim(tmp_path / "three", 0.01, 1)
    assert main(["export", str(tmp_path / "ring.json"), "-o", str(tmp_path / "two.ssp"), "--fmi", "2"]) == 0
    assert "warning" not in capsys.readouterr().err
    with zipfile.ZipFile(tmp_path / "two.ssp") as zf:
        zf.extractall(tmp_path / "two")
    ours = Execution(check_spec(tmp_path / "ring.json"), record=True).run()  # the FMI 3.0 system, run by cosim
    theirs = run_libcosim(tmp_path / "two", 0.01, 100)
    assert np.max(np.abs(theirs - ours.traces[["a.y", "b.y", "c.y"]].to_numpy()[1:])) <= 1e-12
