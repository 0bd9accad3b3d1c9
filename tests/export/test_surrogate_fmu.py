"""`cosim export-surrogate`: the surrogates as a C FMU built with gcc, valid for FMPy, whose outputs equal the
Python predictions to 1e-12, evaluated once per change of a parameter, and usable as a unit in a spec."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu

from cosim.analysis.surrogate import fit_table, read, write
from cosim.analysis.table import load_results
from cosim.cli.main import main
from cosim.export.surrogate_fmu import export_surrogate_fmu
from tests.analysis.test_surrogate import PARAMETERS, make_study
from tests.helpers.tools import require_tool


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """A study with a Gaussian-process surrogate (smooth) and a polynomial one (quadratic), stored."""
    require_tool("gcc", "gcc")
    folder, _, _ = make_study(tmp_path_factory.mktemp("fmu") / "study")
    table = load_results(folder)
    gp = fit_table(table, ["smooth"], method="gp")
    poly = fit_table(table, ["quadratic"], method="poly")
    gp.objectives.update(poly.objectives)
    write(gp, folder / "surrogate")
    return folder


def _slave(fmu, tmp_path):
    md = read_model_description(str(fmu))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu), str(tmp_path / "x")),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="s")
    return slave, {v.name: v.valueReference for v in md.modelVariables}, md


def test_fmu_outputs_equal_the_python_predictions(study, tmp_path):
    surrogates = read(study / "surrogate")
    fmu = export_surrogate_fmu(surrogates.to_json(), tmp_path / "objective.fmu")
    assert validate_fmu(str(fmu)) == []
    slave, vr, md = _slave(fmu, tmp_path)
    assert [v.name for v in md.modelVariables if v.causality == "parameter"] == ["u_a", "u_b", "u_c"]
    outputs = ["smooth", "smooth_std", "quadratic", "quadratic_std"]
    assert [v.name for v in md.modelVariables if v.causality == "output"] == outputs
    rng = np.random.default_rng(7)
    designs = pd.DataFrame(rng.random((40, 3)) * [1.2, 2.2, 2.2] - [0.1, 0.1, 1.1], columns=PARAMETERS)
    expected = surrogates.predict(designs)[["smooth", "smooth_std", "quadratic", "quadratic_std"]].to_numpy()
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    got = []
    for i, x in enumerate(designs.to_numpy()):
        slave.setReal([vr["u_a"], vr["u_b"], vr["u_c"]], list(x))
        for k in range(3):  # steps with the same parameters evaluate nothing again
            slave.doStep(0.01 * (3 * i + k), 0.01)
            got_now = slave.getReal([vr[o] for o in outputs])
        got.append(got_now)
    evaluations = slave.getReal([vr["evaluations"]])[0]
    slave.terminate()
    slave.freeInstance()
    np.testing.assert_allclose(np.array(got), expected, rtol=1e-12, atol=1e-12)
    assert evaluations == len(designs)
    assert np.all(np.array(got)[:, 1] > 0) and np.all(np.array(got)[:, 3] > 0)


def test_fmu_is_a_unit_of_a_spec(study, tmp_path):
    import cosim

    fmu = tmp_path / "objective.fmu"
    assert main(["export-surrogate", str(study), "-o", str(fmu), "--objective", "quadratic"]) == 0
    spec = {"name": "stand_in", "units": {"s": {"fmu": str(fmu)}}, "experiment": {"stop": 0.05, "step": 0.01},
            "objectives": {"q": {"signal": "s.quadratic", "reduce": "final"}}}
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    result = cosim.run(tmp_path / "spec.json", {"s.u_a": 0.3, "s.u_b": 1.1, "s.u_c": 0.0})
    assert result.ok, result.message
    x = np.array([[0.3, 1.1, 0.0]])
    assert result.objectives["q"] == pytest.approx(1 + 2 * 0.3 - 3 * 0.3 * 1.1 + 1.1 ** 2, abs=1e-3)
    assert result.objectives["q"] == read(study / "surrogate").objectives["quadratic"].fitted.model.predict(x)[0][0]


def test_export_surrogate_refuses_bad_input(study, tmp_path, capsys):
    for argv, words in (
            (["export-surrogate", str(study), "-o", str(tmp_path / "x.zip")], ["x.zip", "*.fmu"]),
            (["export-surrogate", str(study), "-o", str(tmp_path / "x.fmu"), "--objective", "nope"],
             ["nope", "smooth, quadratic"]),
            (["export-surrogate", str(tmp_path), "-o", str(tmp_path / "x.fmu")], ["cosim surrogate"])):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "Traceback" not in err and all(w in err for w in words), err
    assert not (tmp_path / "x.fmu").exists()


def test_fmi3_build_validates_and_predicts_the_same(study, tmp_path):
    from fmpy import simulate_fmu

    surrogates = read(study / "surrogate")
    fmu = export_surrogate_fmu(surrogates.to_json(), tmp_path / "objective3.fmu", ["smooth"], fmi_version=3)
    assert read_model_description(str(fmu)).fmiVersion == "3.0"
    assert validate_fmu(str(fmu)) == []
    result = simulate_fmu(str(fmu), stop_time=0.02, output_interval=0.01,
                          start_values={"u_a": 0.4, "u_b": 0.7, "u_c": -0.2}, output=["smooth", "smooth_std"])
    mean, std = surrogates.objectives["smooth"].fitted.model.predict(np.array([[0.4, 0.7, -0.2]]))
    assert result["smooth"][-1] == mean[0] and result["smooth_std"][-1] == std[0]
