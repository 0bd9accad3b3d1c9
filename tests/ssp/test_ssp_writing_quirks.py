"""Writing quirks of vendor SSPs (issue 33, item 4), each read as the tool that wrote it reads it, with one note
printed once, or refused naming the element and the reason: ssd:Connectors out of the schema's order, a connector
fed twice (the same connection written twice; two sources), notes shown once by cosim inspect.  Units in brackets:
tests/data/ssp/test_ssp_vendor_forms.py::test_a_unit_in_brackets_is_read_without_them_with_one_note.

The SSP is the DC motor in Dymola's shape (tests/helpers/ssp_fixtures.py) around linear_ode built from src/cosim/fmus/;
values are checked against dc_motor_expected (its equations)."""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd
import pytest

from cosim.cli.main import main
from cosim.errors import SpecError
from cosim.ssp import read_ssp
from tests.helpers.ssp_fixtures import dc_motor_expected, dc_motor_ssd, ensure_built, write_archive


def _archive(tmp_path: Path, ssd: str, name: str = "quirk.ssp") -> Path:
    fmu = Path(ensure_built("linear_ode", 2)).read_bytes()
    return write_archive(tmp_path / name, {"SystemStructure.ssd": ssd.encode(), "resources/linear_ode.fmu": fmu})


def _run_final(tmp_path: Path, path: Path) -> pd.Series:
    out = tmp_path / "t.csv"
    assert main(["run", str(path), "--step", "0.1", "--algorithm", "jacobi", "--out", str(out)]) == 0
    return pd.read_csv(out).iloc[-1]


def test_connectors_out_of_the_schemas_order_are_read_with_one_note_each(tmp_path):
    ssd = dc_motor_ssd()
    inner = re.search(r"        <ssd:Connectors>\n.*?        </ssd:Connectors>\n", ssd, re.S).group(0)
    ssd = ssd.replace(inner, "", 1).replace("        </ssd:Connections>\n      </ssd:System>",
                                            "        </ssd:Connections>\n" + inner + "      </ssd:System>")
    outer = re.search(r"    <ssd:Connectors>\n.*?    </ssd:Connectors>\n", ssd, re.S).group(0)
    ssd = ssd.replace(outer, "", 1).replace("    </ssd:ParameterBindings>\n", "    </ssd:ParameterBindings>\n" + outer, 1)
    path = _archive(tmp_path, ssd)
    notes = [n for n in read_ssp(path).notes if "order the schema does not give" in n]
    assert len(notes) == 2, notes  # one per element, each naming it
    assert "ssd:System[@name='DC-Motor'] has its children in an order the schema does not give " \
        "(ssd:ParameterBindings before ssd:Connectors)" in notes[0]
    assert "ssd:System[@name='SuT'] has its children in an order the schema does not give (ssd:Elements before " \
        "ssd:Connectors)" in notes[1]
    final = _run_final(tmp_path, path)
    want = dc_motor_expected(1.0, 0.1)
    assert final["SuT.edrive_mass.y"] == pytest.approx(want["mass"], rel=1e-12)
    assert final["DC_Motor.phiB"] == pytest.approx(want["mass"], rel=1e-12)


def test_the_same_connection_written_twice_is_read_once_with_a_note(tmp_path):
    line = '      <ssd:Connection startElement="stimuli" startConnector="y" endElement="SuT" endConnector="tau"/>\n'
    ssd = dc_motor_ssd()
    assert line in ssd
    path = _archive(tmp_path, ssd.replace(line, line + line))
    [note] = [n for n in read_ssp(path).notes if "repeats the connection" in n]
    assert "repeats the connection stimuli.y -> SuT.tau of" in note and note.endswith(": read once")
    assert _run_final(tmp_path, path)["SuT.edrive_mass.y"] == pytest.approx(dc_motor_expected(1.0, 0.1)["mass"])


def test_a_nested_system_connector_fed_by_two_sources_is_refused_naming_both(tmp_path, capsys):
    # the valve composite: SuT.tau fed from the stimuli outside and from edrive_mass inside
    inside = ('          <ssd:Connection startElement="edrive_mass" startConnector="y" endConnector="phiB"/>\n')
    ssd = dc_motor_ssd()
    assert inside in ssd
    path = _archive(tmp_path, ssd.replace(inside, inside + inside.replace('endConnector="phiB"',
                                                                           'endConnector="tau"')))
    with pytest.raises(SpecError) as caught:
        read_ssp(path)
    [problem] = caught.value.problems
    assert problem.message.startswith("connector 'tau' of 'SuT' is fed by ") and "a connector holds one value" \
        in problem.message and "OMSimulator refuses" in problem.message
    assert "stimuli.y" in problem.message and "SuT.edrive_mass.y" in problem.message
    # at the connection read second, naming the first
    assert problem.path.endswith("ssd:System[@name='DC-Motor']/ssd:Connections/ssd:Connection[1]")
    assert "(/ssd:SystemStructureDescription[@name='DC-Motor']/ssd:System[@name='DC-Motor']/ssd:Elements/" \
        "ssd:System[@name='SuT']/ssd:Connections/ssd:Connection[5])" in problem.message
    assert main(["validate", str(path)]) == 2
    assert "Traceback" not in capsys.readouterr().err


def test_inspect_shows_each_note_once(tmp_path, capsys):
    path = _archive(tmp_path, dc_motor_ssd())
    assert main(["inspect", str(path)]) == 0
    captured = capsys.readouterr()
    shown = captured.out + captured.err
    assert shown.count("system 'DC-Motor' is called 'DC_Motor'") == 1
    assert shown.count("the SSP gives no step size") == 1
