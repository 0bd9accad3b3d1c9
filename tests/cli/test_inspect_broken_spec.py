"""``cosim inspect`` on a spec with problems lists what it can (issue 28, item 7).

validate's advice for a misspelt port is "run 'cosim inspect' on the spec to list the variables"; before, inspect
of that very spec printed the problems again and listed nothing.
"""

from __future__ import annotations

import json

from cosim.cli.main import main
from tests.helpers.tools import python_unit


def test_inspect_of_a_broken_spec_lists_the_units_that_load(tmp_path, capsys):
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({
        "units": {"g": {"python": python_unit("Gain"), "parameters": {"kk": 2.0}},  # misspelt k
                  "energy": {"fmu": "builtin:motor_gear_energy_fmi3"},
                  "lost": {"fmu": "no_such.fmu"}},
        "connections": [{"from": "g.y", "to": "energy.omgea"}],
        "experiment": {"stop": 1.0, "step": 0.1}}))
    assert main(["validate", str(spec)]) == 2
    advice = capsys.readouterr().err
    assert "unit 'g' has no variable 'kk'" in advice and "run 'cosim inspect' on the spec" in advice

    assert main(["inspect", str(spec)]) == 2
    captured = capsys.readouterr()
    out = captured.out
    assert "has problems (listed after its units)" in out
    gain_rows = out.split("unit g:")[1].split("unit energy:")[0]
    assert "\n  k     parameter" in gain_rows and "\n  y     output" in gain_rows  # the name the spec meant
    energy_rows = out.split("unit energy:")[1].split("unit lost:")[0]
    assert "omega" in energy_rows and "input" in energy_rows and "e_total" in energy_rows
    assert "unit lost: does not load" in out and "no_such.fmu" in out
    assert "not shown until the problems below are fixed" in out
    assert "unit 'g' has no variable 'kk'" in captured.err and "omgea" in captured.err  # then the problems
    assert "Traceback" not in captured.err
