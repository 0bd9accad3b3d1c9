"""DesignSpace: grids without drift, lists, booleans, arrays, samplers, constraints, ids."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cosim.errors import SpecError
from cosim.spec.design import DesignSpace, expression_name, range_values
from cosim.spec.loader import spec_from_dict
from tests.helpers.tools import python_unit


def make_spec(design: dict, extra_units: dict | None = None):
    raw = {
        "units": {"ode": {"python": python_unit("LinearOde")}, **(extra_units or {})},
        "experiment": {"stop": 0.1, "step": 0.05},
        "objectives": {"y": {"signal": "ode.y", "reduce": "final"}},
        "design": design,
    }
    return spec_from_dict(raw, "/tmp/design_spec.json")


def test_range_is_inclusive_and_exact_in_decimal():
    assert range_values(0.0, 1.0, 0.1) == [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0]
    assert range_values(-0.4, 0.15, 0.05)[-1] == 0.15 and len(range_values(-0.4, 0.15, 0.05)) == 12
    assert range_values(-100, 20, 1) == list(range(-100, 21))
    assert all(isinstance(v, int) for v in range_values(-100, 20, 1))
    assert range_values(0.0, 0.95, 0.1)[-1] == 0.9  # max not on the grid: the last value below it
    assert range_values(1.5, 1.5, 0.1) == [1.5]
    with pytest.raises(ValueError):
        range_values(0, 1, 0)


def test_grid_of_range_list_and_bool_in_order():
    spec = make_spec({"parameters": {"ode.a": {"min": -1.0, "max": -0.8, "step": 0.1},
                                     "ode.x0": {"values": [1, 2]}, "ode.b": {"bool": True}}})
    space = DesignSpace.from_spec(spec)
    points = list(space)
    assert len(space) == len(points) == 12
    assert points[0].values == {"ode.a": -1.0, "ode.x0": 1, "ode.b": False}
    assert points[1].values == {"ode.a": -1.0, "ode.x0": 1, "ode.b": True}
    assert points[-1].values == {"ode.a": -0.8, "ode.x0": 2, "ode.b": True}
    assert [p.values["ode.a"] for p in points[::4]] == [-1.0, -0.9, -0.8]
    assert [p.index for p in points] == list(range(12))


def test_ids_are_deterministic_unique_and_depend_on_the_spec():
    design = {"parameters": {"ode.a": {"min": -1.0, "max": 0.0, "step": 0.25}}}
    ids1 = [p.id for p in DesignSpace.from_spec(make_spec(design))]
    ids2 = [p.id for p in DesignSpace.from_spec(make_spec(design))]
    assert ids1 == ids2 and len(set(ids1)) == 5 and all(len(i) == 16 for i in ids1)
    other = make_spec(design, {"g": {"python": python_unit("Gain")}})
    assert not set(ids1) & {p.id for p in DesignSpace.from_spec(other)}


def test_array_parameter_each_element_its_own_range_and_list_of_arrays():
    spec = make_spec({"parameters": {"ode.a": {"min": [0.0, 10], "max": [0.2, 20], "step": [0.1, 10]}}})
    space = DesignSpace.from_spec(spec)
    values = [p.values["ode.a"] for p in space]
    assert values == [[0.0, 10], [0.0, 20], [0.1, 10], [0.1, 20], [0.2, 10], [0.2, 20]]
    assert space.columns({"ode.a": [0.1, 20]}) == {"ode.a[1]": 0.1, "ode.a[2]": 20}
    listed = DesignSpace.from_spec(make_spec({"parameters": {"ode.a": {"values": [[1, 2], [3, 4]]}}}))
    assert [p.values["ode.a"] for p in listed] == [[1, 2], [3, 4]]


@pytest.mark.parametrize("method", ["lhs", "sobol", "random"])
def test_samplers_are_seeded_inside_bounds_and_snap_to_steps(method):
    design = {"method": method, "samples": 64, "seed": 7,
              "parameters": {"ode.a": {"min": -2.0, "max": -1.0}, "ode.x0": {"min": 0, "max": 10, "step": 2},
                             "ode.b": {"bool": True}}}
    a = list(DesignSpace.from_spec(make_spec(design)))
    b = list(DesignSpace.from_spec(make_spec(design)))
    assert [p.values for p in a] == [p.values for p in b]
    c = list(DesignSpace.from_spec(make_spec({**design, "seed": 8})))
    assert [p.values for p in a] != [p.values for p in c]
    xs = np.array([p.values["ode.a"] for p in a])
    assert xs.min() >= -2.0 and xs.max() <= -1.0 and len(set(xs)) == len(a)
    assert {p.values["ode.x0"] for p in a} <= {0, 2, 4, 6, 8, 10}
    assert {p.values["ode.b"] for p in a} == {False, True}
    assert len(a) == 64  # continuous 'a' makes every draw distinct


def test_lhs_stratifies_each_dimension():
    design = {"method": "lhs", "samples": 10, "seed": 1, "parameters": {"ode.a": {"min": 0.0, "max": 1.0}}}
    xs = sorted(p.values["ode.a"] for p in DesignSpace.from_spec(make_spec(design)))
    assert [int(x * 10) for x in xs] == list(range(10))  # one sample in each tenth


def test_constraint_names_targets_with_underscores_and_short_names():
    design = {"parameters": {"ode.a": {"min": 0, "max": 4, "step": 1}, "ode.x0": {"min": 0, "max": 4, "step": 1}},
              "constraint": "ode_a + x0 <= 4 and a != 2"}
    space = DesignSpace.from_spec(make_spec(design))
    points = list(space)
    assert len(space) == len(points) == 15 - 3
    assert all(p.values["ode.a"] + p.values["ode.x0"] <= 4 and p.values["ode.a"] != 2 for p in points)
    assert expression_name("traj.q_via[2]") == "traj_q_via_2"


def test_constraint_names_parameters_as_the_spec_does():
    """Dotted targets and elements, as written in design.parameters, mean the same as the identifier form."""
    design = {"parameters": {"ode.a": {"min": [0, 0], "max": [2, 2], "step": 1}, "ode.x0": {"values": [1, 3]}},
              "constraint": "ode.a[1] < ode.a[2] and ode.x0 > ode.a[2]"}
    values = [(p.values["ode.a"], p.values["ode.x0"]) for p in DesignSpace.from_spec(make_spec(design))]
    assert values == [([0, 1], 3), ([0, 2], 3), ([1, 2], 3)]
    element = {"parameters": {"ode.a[2]": {"min": 0, "max": 4, "step": 1}, "ode.x0": {"min": 0, "max": 4, "step": 1}},
               "constraint": "ode.a[2] > ode.x0"}  # a parameter of one element, named as its target
    points = list(DesignSpace.from_spec(make_spec(element)))
    assert len(points) == 10 and all(p.values["ode.a[2]"] > p.values["ode.x0"] for p in points)
    with pytest.raises(SpecError, match=r"unknown name\(s\) in the constraint: ode.b(.|\n)*known: ode.a, ode.x0"):
        DesignSpace.from_spec(make_spec({**design, "constraint": "ode.b < 1"}))


def test_spread_takes_points_across_the_whole_space():
    design = {"parameters": {"ode.a": {"min": 0, "max": 9, "step": 1}, "ode.x0": {"min": 0, "max": 9, "step": 1}},
              "constraint": "ode.a + ode.x0 != 5"}
    space = DesignSpace.from_spec(make_spec(design))
    points = list(space)
    assert len(points) == 94
    assert [p.index for p in space.spread(4)] == [0, 31, 62, 93]
    assert [p.values for p in space.spread(4)] == [points[i].values for i in (0, 31, 62, 93)]
    assert space.spread(200) == points and [p.index for p in space.spread(1)] == [0]


def test_stratified_covers_every_parameter_range_where_spread_covers_only_the_slowest():
    """Issue 39: a dry run's few samples must reach a dear region along any parameter. A 12 x 12 grid whose
    fastest-varying parameter decides the cost: spread(8) strides through the enumeration and samples b at 8
    values spread anyhow; stratified(8) puts one sample in each eighth of both axes."""
    design = {"parameters": {"ode.a": {"min": 0, "max": 11, "step": 1}, "ode.x0": {"min": 0, "max": 11, "step": 1}}}
    space = DesignSpace.from_spec(make_spec(design))
    chosen = space.stratified(8)
    assert len(chosen) == 8 and chosen == space.stratified(8)  # deterministic
    by_index = {p.index: p for p in space}
    assert all(by_index[p.index] == p for p in chosen)  # real points of the space, with their index and id
    for name in ("ode.a", "ode.x0"):  # one sample per eighth of each axis: the k-th lowest in cells 12k/8..
        for k, value in enumerate(sorted(p.values[name] for p in chosen)):
            assert math.floor(12 * k / 8) <= value <= math.ceil(12 * (k + 1) / 8) - 1, (name, k, value)
    assert space.stratified(8, seed=1) != chosen
    assert space.stratified(500) == list(space)


def test_stratified_on_a_constrained_grid_takes_accepted_points_near_each_target():
    design = {"parameters": {"ode.a": {"min": 0, "max": 9, "step": 1}, "ode.x0": {"min": 0, "max": 9, "step": 1}},
              "constraint": "ode.a + ode.x0 != 5"}
    space = DesignSpace.from_spec(make_spec(design))
    chosen = space.stratified(6)
    points = {p.index: p for p in space}
    assert 4 <= len(chosen) <= 6 and all(points[p.index] == p for p in chosen)
    assert all(p.values["ode.a"] + p.values["ode.x0"] != 5 for p in chosen)
    assert len({p.values["ode.a"] for p in chosen}) == len(chosen)  # still spread along each axis
    assert [p.index for p in chosen] == sorted(p.index for p in chosen)


def test_constraint_on_array_elements():
    design = {"parameters": {"ode.a": {"min": [0, 0], "max": [2, 2], "step": 1}},
              "constraint": "ode_a[1] < ode_a[2]"}
    values = [p.values["ode.a"] for p in DesignSpace.from_spec(make_spec(design))]
    assert values == [[0, 1], [0, 2], [1, 2]]


@pytest.mark.parametrize("design, fragment", [
    ({"parameters": {"ode.a": {"min": 0, "max": 1, "step": 0.1}}, "constraint": "k_m < 1"}, "unknown name"),
    ({"parameters": {"ode.a": {"min": 0, "max": 1, "step": 0.1}}, "constraint": "a <"}, "cannot parse"),
    ({"parameters": {"ode.a": {"min": 1, "max": 0, "step": 0.1}}}, "below min"),
    ({"parameters": {"ode.a": {"values": [1, 2, 1]}}}, "values repeat"),
    ({"parameters": {"ode.a": {"min": 0, "max": 1}}, "method": "sobol"}, "needs 'samples'"),
])
def test_bad_design_is_a_spec_error_with_its_path(design, fragment):
    with pytest.raises(SpecError) as info:
        DesignSpace.from_spec(make_spec(design))
    assert fragment in str(info.value) and "$.design" in str(info.value)


def test_large_grid_is_lazy_and_len_is_cheap():
    import tracemalloc
    from unittest import mock

    design = {"parameters": {"ode.a": {"min": 0, "max": 999, "step": 1}, "ode.x0": {"min": 0, "max": 99, "step": 1}}}
    space = DesignSpace.from_spec(make_spec(design))
    with mock.patch.object(DesignSpace, "_raw", side_effect=AssertionError("len() enumerated the grid")):
        assert len(space) == 100_000  # computed from the axes' lengths (its time: benchmarks/analysis_speed.py)
    tracemalloc.start()
    count = sum(1 for _ in space)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert count == 100_000 and peak < 5e6  # 100 000 points as dicts would take tens of MB
