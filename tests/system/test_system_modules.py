"""The system's checks live one concern per module, and a design range is checked in one place."""

from __future__ import annotations

import json

import pytest

from cosim.cli.main import main
from cosim.errors import SpecError
from cosim.spec.design import DesignSpace, range_problem, range_values
from tests.helpers.tools import python_unit


def test_each_name_of_the_system_is_imported_from_its_own_module():
    """The system's parts live in one module each; the old places that re-exported them are gone (issue 34)."""
    from cosim.master.loops import strongly_connected
    from cosim.system import builder
    from cosim.system.connection_checks import check_connections
    from cosim.system.signals import resolve_signal
    from cosim.system.stepping import check_algebraic_loops, stepping_order
    from cosim.system.study_checks import check_design
    from cosim.system.value_checks import assignment

    assert not hasattr(builder, "SETTABLE_AS_PARAMETER")  # it was re-exported there
    assert all(callable(f) for f in (check_connections, resolve_signal, check_algebraic_loops, stepping_order,
                                     strongly_connected, check_design, assignment))


def test_strongly_connected_components_and_order():
    from cosim.master.loops import strongly_connected

    edges = {"a": {"b"}, "b": {"c"}, "c": {"b", "d"}, "d": set()}
    components = strongly_connected(["a", "b", "c", "d"], edges)
    assert sorted(map(sorted, components)) == [["a"], ["b", "c"], ["d"]]
    assert components.index(["d"]) < components.index(next(c for c in components if "b" in c))  # reverse topological


@pytest.mark.parametrize("lo, hi, step, grid, message", [
    (0, 1, None, True, "a grid needs a 'step' for each range"),
    (0, 1, 0, True, "step must be positive, got 0"),
    (2, 1, 0.5, True, "max (1) is below min (2)"),
    (2, 1, None, False, "max (1) is below min (2)"),
    (0, 1, None, False, None),
])
def test_one_range_check_for_validate_and_the_design_space(tmp_path, capsys, lo, hi, step, grid, message):
    problem = range_problem(lo, hi, step, grid)
    assert (problem[0] if problem else None) == message
    parameter = {"min": lo, "max": hi} | ({"step": step} if step is not None else {})
    design = {"parameters": {"g.k": parameter}} | ({} if grid else {"method": "lhs", "samples": 4, "seed": 1})
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"units": {"g": {"python": python_unit("Gain")}},
                                "experiment": {"stop": 1, "step": 0.1}, "design": design}))
    code = main(["validate", str(spec)])
    err = capsys.readouterr().err
    if message is None:
        assert code == 0
        return
    assert code == 2 and f"$.design.parameters.g.k: {message}" in err  # validate's words ...
    from cosim.spec.loader import load_spec

    with pytest.raises(SpecError, match=message.replace("(", r"\(").replace(")", r"\)")):
        DesignSpace.from_spec(load_spec(spec))  # ... are the design space's
    if grid and step is not None:
        with pytest.raises(ValueError, match="step must be positive|is below min"):
            range_values(lo, hi, step)
