"""Time per step of the surrogate FMU of `cosim export-surrogate` (issue 37: <= 10 us per step).

Surrogates of e_total and peak_tau_ratio[2] (Gaussian processes) are fitted on 200 random designs of the committed
pick-and-place table and exported as an FMI 2.0 FMU; FMPy's FMU2Slave then steps it from Python:

- ``fixed``: the design is set once, each step is doStep + getReal of the 4 outputs (the outputs are evaluated
  once: they depend on the parameters only);
- ``new design every step``: each step sets both tunable parameters first, so every step evaluates both
  Gaussian processes (200 designs each: kernel vector, forward substitution for the variance).

Every figure includes FMPy's ctypes calls from Python (~1-2 us each), so the FMU's own cost is lower.

    PYTHONPATH=src python benchmarks/surrogate_fmu_step.py [STEPS]      (default 20000)
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
TABLE = REPO / "examples" / "pick_and_place" / "study"


def main(steps: int) -> None:
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    from cosim.analysis.surrogate import fit_table
    from cosim.analysis.table import load_results
    from cosim.export.surrogate_fmu import export_surrogate_fmu

    table = load_results(TABLE)
    table.df = table.df.sample(200, random_state=0)
    surrogates = fit_table(table, ["e_total", "peak_tau_ratio[2]"], method="gp")
    with tempfile.TemporaryDirectory() as tmp:
        fmu = export_surrogate_fmu(surrogates.to_json(), Path(tmp) / "objective.fmu")
        md = read_model_description(str(fmu))
        vr = {v.name: v.valueReference for v in md.modelVariables}
        slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu), tmp + "/x"),
                          modelIdentifier=md.coSimulation.modelIdentifier, instanceName="s")
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        outputs = [vr[n] for n in ("e_total", "e_total_std", "peak_tau_ratio_2", "peak_tau_ratio_2_std")]
        parameters = [vr["traj_waypoints_9"], vr["traj_waypoints_11"]]
        model = surrogates.objectives["e_total"].fitted.model
        designs = model.scaling.low + model.scaling.span * np.random.default_rng(1).random((steps, 2))
        print(f"machine: 2-core x86_64; load average before {os.getloadavg()}; "
              f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC; {steps} steps each")
        slave.setReal(parameters, list(designs[0]))
        start = time.perf_counter()
        for i in range(steps):
            slave.doStep(i * 1e-3, 1e-3)
            slave.getReal(outputs)
        fixed = (time.perf_counter() - start) / steps
        start = time.perf_counter()
        for i in range(steps):
            slave.setReal(parameters, list(designs[i]))
            slave.doStep((steps + i) * 1e-3, 1e-3)
            slave.getReal(outputs)
        moving = (time.perf_counter() - start) / steps
        evaluations = slave.getReal([vr["evaluations"]])[0]
        slave.terminate()
        slave.freeInstance()
    print(f"fixed design:          {fixed * 1e6:.2f} us per step (doStep + getReal of 4 outputs)")
    print(f"new design every step: {moving * 1e6:.2f} us per step (setReal of 2 + doStep + getReal of 4; "
          f"{int(evaluations)} evaluations of both surrogates)")
    print(f"load average after {os.getloadavg()}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20000)
