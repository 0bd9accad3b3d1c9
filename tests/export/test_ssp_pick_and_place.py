"""The pick-and-place study exported as an SSP (its Python units built into FMUs) gives the same objectives."""

from __future__ import annotations

import zipfile

import cosim
from cosim.cli.main import main
from tests.helpers.paths import REPO

SPEC = REPO / "examples" / "pick_and_place" / "spec_coarse.json"


def test_exported_pick_and_place_gives_the_objectives_of_its_spec(tmp_path):
    archive = tmp_path / "pick_and_place.ssp"
    assert main(["export", str(SPEC), "-o", str(archive)]) == 0
    with zipfile.ZipFile(archive) as zf:
        fmus = sorted(n for n in zf.namelist() if n.endswith(".fmu"))
    # traj and robot are Python units, now FMI 2.0 FMUs built by pythonfmu; energy is the C FMU
    assert fmus == ["resources/PandaInverseDynamics.fmu", "resources/TrajectoryGenerator.fmu",
                    "resources/motor_gear_energy_fmi3.fmu"]
    companion = tmp_path / "pick_and_place.spec.json"
    exported = cosim.load_spec(companion)
    assert {u.name: u.kind for u in exported.units} == {"traj": "fmu", "robot": "fmu", "energy": "fmu"}
    # two designs of the coarse grid (the spec's default and one corner), each a full run
    for values in ({}, {"traj.waypoints[9]": -100, "traj.waypoints[11]": 140}):
        original = cosim.run(SPEC, values, record=False)
        again = cosim.run(companion, values, record=False)
        assert original.ok and again.ok, (original.message, again.message)
        assert again.objectives == original.objectives  # bit for bit
        assert original.objectives["e_total"] > 0
