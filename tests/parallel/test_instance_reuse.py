"""Instances reused across the points of a worker (cosim.parallel.isolation.point_runner.PointRunner): units reset between
points give every point the objectives of a fresh run bit for bit; a broken reset is found by the check on the
first point and turns reuse off; ``"reuse": false`` makes one unit anew for every point."""

from __future__ import annotations

import logging
import struct

import pytest

from cosim import Execution, build_system, load_spec
from cosim.execution.point import run_point
from cosim.fmus.build import ensure_built
from cosim.parallel.isolation.point_runner import PointRunner
from cosim.units.protocol import ElementRef

POINTS = [{"a.a": -1.0 - 0.3 * i, "b.a": -2.0 + 0.1 * i} for i in range(5)]



@pytest.fixture(autouse=True)
def _cosim_notes_reach_caplog(caplog):
    """cosim's notes are INFO records of the 'cosim' loggers; an in-process `cosim` command run earlier in this
    worker may have set that logger's level higher (cli.main does, for its own terminal): set it for each test."""
    caplog.set_level(logging.INFO, logger="cosim")

def system_of(write_spec, version: int = 2, reuse_a: bool = True):
    ode = str(ensure_built("linear_ode", version))
    spec = {"units": {"a": {"fmu": ode, "parameters": {"a": -1.0}}, "b": {"fmu": ode, "parameters": {"a": -2.0}}},
            "connections": [{"from": "a.y", "to": "b.u", "factor": 1.5}, {"from": "b.y", "to": "a.u"}],
            "experiment": {"stop": 1.0, "step": 0.01},
            "objectives": {"ay": {"signal": "a.y", "reduce": "integral"}, "by": {"signal": "b.y", "reduce": "max"}}}
    if not reuse_a:
        spec["units"]["a"]["reuse"] = False
    return build_system(load_spec(write_spec(spec)))


def bits(objectives: dict) -> dict:
    return {k: struct.pack("<d", v) for k, v in objectives.items()}


def fresh(system, values: dict) -> dict:
    return bits(run_point(system, values).objectives)


def test_reset_units_give_every_point_the_fresh_runs_bits(write_spec):
    for version in (2, 3):
        system = system_of(write_spec, version)
        assert system.kernel.kernel == "native"
        runner = PointRunner(system)
        first_units = None
        for i, values in enumerate(POINTS):
            row = runner.run(f"p{i}", values)
            assert row.status == "ok", row.message
            assert bits(row.objectives) == fresh(system, values)
            first_units = first_units or dict(runner.units)
            assert runner.units["a"] is first_units["a"]  # the same instance, reset, every point
        assert runner.reset_checked and not runner.reset_broken
        runner.close()


def test_a_broken_reset_is_found_once_and_reuse_stops(write_spec, caplog):
    system = system_of(write_spec)
    runner = PointRunner(system)
    runner.run("p0", POINTS[0])  # fresh units; the check has run the point again on reset ones
    assert runner.reset_checked and not runner.reset_broken
    # now an FMU whose reset forgets a start value (x0 back to 2, not 1), as broken resets in the wild do
    runner = PointRunner(system)
    runner.units = {n: su.unit_type.instantiate(n) for n, su in system.units.items()}
    unit = runner.units["b"]
    proper = unit.reset

    def forgetful_reset() -> None:
        proper()
        unit.set(unit.select([ElementRef("x0")]), [2.0])

    unit.reset = forgetful_reset
    row = runner.run("p0", POINTS[0])
    assert bits(row.objectives) == fresh(system, POINTS[0])  # the row is the fresh run's
    assert runner.reset_broken and runner.units is None
    assert "reset is not trusted" in caplog.text
    for i, values in enumerate(POINTS[1:]):  # fresh instances from now on: every point right
        row = runner.run(f"p{i}", values)
        assert bits(row.objectives) == fresh(system, values) and runner.units is None


def test_reuse_false_makes_that_unit_anew_for_every_point(write_spec):
    system = system_of(write_spec, reuse_a=False)
    assert system.units["a"].spec.options["reuse"] is False
    runner = PointRunner(system)
    seen_b = set()
    for i, values in enumerate(POINTS):
        row = runner.run(f"p{i}", values)
        assert row.status == "ok" and bits(row.objectives) == fresh(system, values)
        assert "a" not in runner.units  # terminated after the point
        seen_b.add(id(runner.units["b"]))
    assert len(seen_b) == 1
    result = Execution(system).run()
    assert result.ok
