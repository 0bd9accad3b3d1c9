"""Exact pruning, part 1: the direction of each objective while a design runs (cosim.spec.bounds), `cosim inspect`
listing it, and the PruneBound observer (cosim.execution.prune) stopping a real run of the drive_energy example
(a Python drive and the motor_gear_energy FMU built from our C sources) only when a finished design strictly
dominates its bound."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from cosim.cli.main import main
from cosim.errors import SpecError
from cosim.execution.point import run_point
from cosim.execution.prune import Front, PruneBound, PruneSettings, parse_constraint
from cosim.spec.bounds import DOWN, FIXED, UP, objective_bounds, reduction_bound, system_bounds
from cosim.spec.loader import ObjectiveSpec, load_spec
from cosim.system.validate import check_spec
from cosim.units.protocol import Variable
from tests.helpers.paths import REPO

EXAMPLE = REPO / "examples" / "drive_energy"
DESIGN = {"energy.gear_ratio": 100, "drive.duration": 1.0, "energy.recuperation": False}


@pytest.fixture(scope="module")
def spec_path(tmp_path_factory) -> Path:
    """drive_energy with energy without recuperation declared non-decreasing and minimized with peak power."""
    folder = tmp_path_factory.mktemp("drive")
    raw = json.loads((EXAMPLE / "spec.json").read_text())
    objectives = raw["objectives"]
    objectives["energy_no_recuperation"].update(monotone="non-decreasing", sense="minimize")
    objectives["energy"].pop("sense")
    objectives["duration"] = {"signal": "drive.omega", "reduce": "initial"}
    objectives["mixed"] = {"expr": "energy_no_recuperation - peak_power"}
    objectives["scaled"] = {"expr": "-2 * energy_no_recuperation + duration"}
    (folder / "spec.json").write_text(json.dumps(raw))
    shutil.copy(EXAMPLE / "drive_profile.py", folder)
    return folder / "spec.json"


@pytest.fixture(scope="module")
def system(spec_path):
    return check_spec(str(spec_path))


def _obj(name, **kw):
    return ObjectiveSpec(name=name, **kw)


def test_each_reduction_has_its_direction_and_reason():
    assert reduction_bound("a", "max").direction == UP
    assert reduction_bound("a", "min").direction == DOWN
    assert reduction_bound("a", "initial").direction == FIXED
    assert reduction_bound("a", "integral_abs").direction == UP
    assert reduction_bound("a", "mean").direction is None
    assert reduction_bound("a", "rms").direction is None
    assert reduction_bound("a", "time_of_max").direction is None
    assert reduction_bound("a", "final").direction is None
    assert reduction_bound("a", "final", monotone="constant").direction == FIXED
    assert reduction_bound("a", "final", monotone="non-increasing").direction == DOWN
    positive = Variable("p", "output", min=0.0)
    negative = Variable("n", "output", max=-1.0)
    free = Variable("f", "output")
    assert reduction_bound("a", "integral", positive).direction == UP
    assert reduction_bound("a", "integral", positive).check == "sign"
    assert reduction_bound("a", "integral", negative).direction == DOWN
    assert reduction_bound("a", "integral", free).direction is None
    assert "no declared sign" in reduction_bound("a", "integral", free).why


def test_expressions_are_bounded_only_where_monotonicity_is_provable():
    objectives = [_obj("up", signal="u.x", reduce="max"), _obj("down", signal="u.x", reduce="min"),
                  _obj("k", signal="u.x", reduce="initial"), _obj("free", signal="u.x", reduce="mean"),
                  _obj("sum_up", expr="up + k * 3"), _obj("diff", expr="up - down"), _obj("clash", expr="up + down"),
                  _obj("neg", expr="-2 * up"), _obj("prod", expr="up * down"), _obj("deg_sum", expr="deg(sum(up))"),
                  _obj("with_free", expr="up + free"), _obj("absolute", expr="abs(up)"),
                  _obj("chain", expr="sum_up + diff")]
    d = {n: b.direction for n, b in objective_bounds(objectives).items()}
    assert d == {"up": UP, "down": DOWN, "k": FIXED, "free": None, "sum_up": UP, "diff": UP, "clash": None,
                 "neg": DOWN, "prod": None, "deg_sum": UP, "with_free": None, "absolute": None, "chain": UP}
    broken = objective_bounds(objectives, broken={"up": "it decreased"})
    assert broken["up"].direction is None and broken["chain"].direction is None and broken["diff"] is not None


def test_monotone_is_refused_on_anything_but_final(write_spec, spec_path):
    raw = json.loads(spec_path.read_text())
    raw["objectives"]["peak_power"]["monotone"] = "non-decreasing"
    with pytest.raises(SpecError) as err:
        load_spec(write_spec(raw))
    assert "$.objectives.peak_power.monotone" in str(err.value) and "final" in str(err.value)
    raw["objectives"]["peak_power"]["monotone"] = "sometimes"
    with pytest.raises(SpecError):
        load_spec(write_spec(raw))


def test_inspect_lists_each_objectives_bound_and_why(spec_path, capsys):
    assert main(["inspect", str(spec_path)]) == 0
    out = capsys.readouterr().out
    listed = out.split("objective bounds while a design runs (--prune):\n")[1].splitlines()
    table = {line.split()[0]: line.split(None, 2)[1:] for line in listed if line.startswith("  ")}
    assert table["peak_power"] == ["non-decreasing", "max only grows"]
    assert table["energy"][0] == "unbounded" and "not declared monotone" in table["energy"][1]
    assert table["energy_no_recuperation"][0] == "non-decreasing"
    assert table["scaled"][0] == "non-increasing"
    assert table["mixed"][0] == "unbounded"


def test_system_bounds_read_the_spec_declarations(system):
    bounds = system_bounds(system)
    assert bounds["energy_no_recuperation"].check == "monotone"
    assert bounds["recuperated"].direction is None


SETTINGS = PruneSettings((("energy_no_recuperation", "minimize"), ("peak_power", "minimize")))


def _finished(system, **values):
    result = run_point(system, {**DESIGN, **values})
    assert result.status == "ok"
    return result.objectives


def test_a_strictly_dominated_design_stops_early_with_its_bound_below_its_final_value(system):
    best = _finished(system)
    front = Front(["A"], np.array([[best["energy_no_recuperation"], best["peak_power"]]]))
    observer = PruneBound(system, SETTINGS, front)
    pruned = run_point(system, {**DESIGN, "energy.gear_ratio": 160}, observers=[observer])
    full = _finished(system, **{"energy.gear_ratio": 160})
    assert pruned.status == "pruned"
    assert observer.dominated_by == "A" and "design A strictly dominates" in pruned.message
    assert pruned.end_time < 2.5 and observer.stop_time == pruned.end_time
    for name in ("energy_no_recuperation", "peak_power"):  # a bound never exceeds the final value
        assert best[name] <= pruned.objectives[name] <= full[name]
    assert pruned.objectives["energy_no_recuperation"] > best["energy_no_recuperation"]
    assert math.isnan(pruned.objectives["energy"])  # unbounded: no value claimed


def test_a_design_on_the_front_runs_to_the_end(system):
    best = _finished(system)
    front = Front(["A"], np.array([[best["energy_no_recuperation"], best["peak_power"]]]))
    other = _finished(system, **{"energy.gear_ratio": 50})  # lower peak power: not dominated
    observer = PruneBound(system, SETTINGS, front)
    result = run_point(system, {**DESIGN, "energy.gear_ratio": 50}, observers=[observer])
    assert result.status == "ok" and result.objectives["peak_power"] == other["peak_power"]
    assert observer.checks >= 1  # compared as often as its share of the run's time allows (OVERHEAD_SHARE)


def test_ties_never_prune(system):
    best = _finished(system)
    front = Front(["same"], np.array([[best["energy_no_recuperation"], best["peak_power"]]]))
    result = run_point(system, DESIGN, observers=[PruneBound(system, SETTINGS, front)])
    assert result.status == "ok" and result.objectives["peak_power"] == best["peak_power"]


def test_a_broken_constraint_on_a_bounded_objective_prunes(system):
    settings = PruneSettings(SETTINGS.objectives, (parse_constraint("peak_power <= 100"),))
    observer = PruneBound(system, settings, Front())
    result = run_point(system, DESIGN, observers=[observer])
    assert result.status == "pruned" and "constraint peak_power <= 100 is already broken" in result.message
    assert 100 < result.objectives["peak_power"]
    unbounded = PruneSettings(SETTINGS.objectives, (parse_constraint("energy <= 1"),))  # energy: unbounded
    assert run_point(system, DESIGN, observers=[PruneBound(system, unbounded, Front())]).status == "ok"


def test_a_broken_declaration_ends_the_bound_for_that_design(system, spec_path, tmp_path):
    # the drive's speed declared non-decreasing: wrong (it brakes to rest); the check finds the first decrease
    # and the objective is unbounded from then on (a declaration is the spec's word: a false one could prune
    # before it is found out, which is why nothing is bounded on past samples alone)
    raw = json.loads(spec_path.read_text())
    raw["objectives"]["speed_end"] = {"signal": "drive.omega", "reduce": "final", "monotone": "non-decreasing"}
    (tmp_path / "spec.json").write_text(json.dumps(raw))
    shutil.copy(spec_path.parent / "drive_profile.py", tmp_path)
    lying = check_spec(str(tmp_path / "spec.json"))
    final = run_point(lying, DESIGN).objectives
    settings = PruneSettings((("speed_end[1]", "minimize"),))
    front = Front(["high"], np.array([[10.0]]))  # above the peak speed (2.7): never dominates before the brake
    observer = PruneBound(lying, settings, front)
    result = run_point(lying, DESIGN, observers=[observer])
    broken = [p for p in observer._partials if p.broken]
    assert [p.name for p in broken] == ["speed_end"] and "decreased at t=" in broken[0].broken
    assert result.status == "ok" and result.objectives["speed_end[1]"] == final["speed_end[1]"]
    assert observer._bounds["speed_end"].direction is None


@pytest.mark.parametrize("text, parsed", [("a <= 1", ("a", "<=", 1.0)), ("2 > b", ("b", "<", 2.0)),
                                          ("x[3] >= -1.5", ("x[3]", ">=", -1.5)), ("a <= b", None),
                                          ("1 < a < 2", None), ("a +", None)])
def test_constraints_that_a_bound_can_break(text, parsed):
    assert parse_constraint(text) == parsed
