"""Which binding sets a parameter when several do (issue 33 item 6): every pairing of binding places.

SSP 1.0/2.0, section ParameterBindings: "bindings at a higher hierarchy level take precedence over lower levels,
i.e. bindings at a system level take precedence over bindings at a sub-system or component level", and at one
level a later ParameterBinding takes priority over an earlier one.  A value reaching a parameter through a
parameter connection counts as bound where the system connector's value was bound (OMSimulator's
import_export_parameters2: the component's own .ssv says k1 = 10, the system's .ssv gives its connector
k_cref = 30, connected to k1, and the tool runs with 30).

The SSDs are written here in OMSimulator's shape (``startElement=""`` for a system's own connector) around
linear_ode built from src/cosim/fmus/: root system ``root`` (parameter connector ``k``, component ``D``) holding
system ``sub`` (parameter connector ``g``) holding component ``C``.  Every place binds the initial state
``x0`` of C (or D) with a value of its own, in every form (inline ssv:ParameterSet, an .ssv file, an .ssv with
an .ssm mapping, an inline set with ``prefix``).  A few pairings also run, so the FMU is seen to start from
the chosen value (linear_ode: y(0) = x0).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest

from cosim.execution.run import Execution
from cosim.fmus.build import ensure_built
from cosim.ssp import read_ssp
from cosim.system.validate import check_spec
from tests.helpers.ssp_fixtures import write_archive

NS = ('xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
      'xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
      'xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" '
      'xmlns:ssm="http://ssp-standard.org/SSP1/SystemStructureParameterMapping"')

# place -> (the element whose ssd:ParameterBindings holds it, the name it binds, its hierarchy level, value)
PLACES = {
    "C": ("sub.C", "x0", 2, 1.0),  # the component's own binding
    "sub": ("sub", "C.x0", 1, 2.0),  # the enclosing system names the component's parameter
    "sub:g": ("sub", "g", 1, 3.0),  # the enclosing system binds its connector g, connected to C.x0
    "root": ("", "sub.C.x0", 0, 4.0),  # the root names it through both levels
    "root:sub.g": ("", "sub.g", 0, 5.0),  # the root binds sub's connector g
    "root:k": ("", "k", 0, 6.0),  # the root binds its connector k, connected to sub.g, connected to C.x0
}
FORMS = ("inline", "ssv", "ssm", "prefix")


def _parameter_set(parameters: dict[str, float]) -> str:
    entries = "".join(f'<ssv:Parameter name="{name}"><ssv:Real value="{value!r}"/></ssv:Parameter>'
                      for name, value in parameters.items())
    return f'<ssv:ParameterSet {NS} version="1.0" name="parameters"><ssv:Parameters>{entries}</ssv:Parameters>' \
           '</ssv:ParameterSet>'


def _binding(place: str, name: str, value: float, form: str, files: dict[str, bytes]) -> str:
    """One ssd:ParameterBinding of ``name = value`` in ``form``; files it refers to go into ``files``."""
    stem = place.replace(":", "_").replace(".", "_")
    if form == "inline":
        return f'<ssd:ParameterBinding><ssd:ParameterValues>{_parameter_set({name: value})}' \
               '</ssd:ParameterValues></ssd:ParameterBinding>'
    if form == "prefix" and "." in name:  # prefix + the name's last part, as a tool binding a subtree writes
        head, tail = name.rsplit(".", 1)
        return f'<ssd:ParameterBinding prefix="{head}."><ssd:ParameterValues>{_parameter_set({tail: value})}' \
               '</ssd:ParameterValues></ssd:ParameterBinding>'
    if form == "ssm":  # the .ssv names a source of its own, the .ssm maps it to the target
        files[f"resources/{stem}.ssv"] = _parameter_set({f"value_{stem}": value}).encode()
        files[f"resources/{stem}.ssm"] = (
            f'<ssm:ParameterMapping {NS} version="1.0"><ssm:MappingEntry source="value_{stem}" '
            f'target="{name}"/></ssm:ParameterMapping>').encode()
        return f'<ssd:ParameterBinding source="resources/{stem}.ssv">' \
               f'<ssd:ParameterMapping source="resources/{stem}.ssm"/></ssd:ParameterBinding>'
    files[f"resources/{stem}.ssv"] = _parameter_set({name: value}).encode()  # "ssv", or prefix of a plain name
    return f'<ssd:ParameterBinding source="resources/{stem}.ssv"/>'


def _component(name: str, bindings: str) -> str:
    return (f'<ssd:Component name="{name}" type="application/x-fmu-sharedlibrary" source="resources/linear_ode.fmu">'
            '<ssd:Connectors><ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>'
            '<ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector>'
            '<ssd:Connector name="x0" kind="parameter"><ssc:Real/></ssd:Connector></ssd:Connectors>'
            f'{bindings}</ssd:Component>')


def build(bindings: list[tuple[str, str]], extra: dict[str, list[tuple[str, float]]] | None = None
          ) -> dict[str, bytes]:
    """The members of the test SSP with ``bindings`` [(place, form)] in that order; ``extra`` adds
    (name, value) bindings (inline) to an element ("", "sub", "sub.C", "D")."""
    files: dict[str, bytes] = {}
    held: dict[str, list[str]] = {"": [], "sub": [], "sub.C": [], "D": []}
    for place, form in bindings:
        element, name, _, value = PLACES[place]
        held[element].append(_binding(place, name, value, form, files))
    for element, pairs in (extra or {}).items():
        for name, value in pairs:
            held[element].append(_binding(f"x{len(files)}", name, value, "inline", files))

    def block(element: str) -> str:
        return f"<ssd:ParameterBindings>{''.join(held[element])}</ssd:ParameterBindings>" if held[element] else ""

    ssd = f'''<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription {NS} name="precedence" version="1.0">
  <ssd:System name="root">
    <ssd:Connectors><ssd:Connector name="k" kind="parameter"><ssc:Real/></ssd:Connector></ssd:Connectors>
    {block("")}
    <ssd:Elements>
      {_component("D", block("D"))}
      <ssd:System name="sub">
        <ssd:Connectors><ssd:Connector name="g" kind="parameter"><ssc:Real/></ssd:Connector></ssd:Connectors>
        {block("sub")}
        <ssd:Elements>{_component("C", block("sub.C"))}</ssd:Elements>
        <ssd:Connections>
          <ssd:Connection startElement="" startConnector="g" endElement="C" endConnector="x0"/>
        </ssd:Connections>
      </ssd:System>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="" startConnector="k" endElement="sub" endConnector="g"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="0.1"/>
</ssd:SystemStructureDescription>
'''
    return {"SystemStructure.ssd": ssd.encode(),
            "resources/linear_ode.fmu": Path(ensure_built("linear_ode", 2)).read_bytes(), **files}


def _x0(tmp_path: Path, name: str, members: dict[str, bytes], unit: str = "sub.C") -> float:
    system = read_ssp(write_archive(tmp_path / f"{name}.ssp", members))
    return system.raw["units"][unit]["parameters"]["x0"]


ACROSS_LEVELS = [(low, high) for low, high in itertools.combinations(PLACES, 2) if PLACES[low][2] > PLACES[high][2]]


def test_the_pairings_cover_every_place_at_every_level():
    assert len(ACROSS_LEVELS) == 11  # C below 5 places, each of sub's 2 below the root's 3
    assert {p for pair in ACROSS_LEVELS for p in pair} == set(PLACES)


@pytest.mark.parametrize("low,high", ACROSS_LEVELS)
def test_the_higher_level_wins_in_every_form_and_either_order(tmp_path, low, high):
    want = PLACES[high][3]
    for (n, (form_low, form_high)) in enumerate(itertools.product(FORMS, FORMS)):
        for order in ((low, form_low), (high, form_high)), ((high, form_high), (low, form_low)):
            got = _x0(tmp_path, f"{n}{order[0][0]}".replace(":", "_"), build(list(order)))
            assert got == want, (order, got)


@pytest.mark.parametrize("place", list(PLACES))
def test_each_place_alone_sets_the_parameter(tmp_path, place):
    for form in FORMS:
        assert _x0(tmp_path, form, build([(place, form)])) == PLACES[place][3], form


def test_a_system_binding_beats_the_components_own_ssv_on_a_component_of_the_root(tmp_path):
    # D sits in the root: its own .ssv (level 1) loses to the root's inline "D.x0" (level 0), in either order
    for form in FORMS:
        files: dict[str, bytes] = {}
        own = _binding("D", "x0", 7.0, form, files)
        members = build([], extra={"": [("D.x0", 8.0)]})
        ssd = members["SystemStructure.ssd"].decode().replace(
            '</ssd:Connectors></ssd:Component>',
            f'</ssd:Connectors><ssd:ParameterBindings>{own}</ssd:ParameterBindings></ssd:Component>', 1)
        assert _x0(tmp_path, form, {**members, **files, "SystemStructure.ssd": ssd.encode()}, "D") == 8.0


def test_at_one_level_the_later_binding_wins(tmp_path):
    # two bindings of one element name the same parameter: the later in element order is used (SSP)
    for element, name in (("sub.C", "x0"), ("sub", "C.x0"), ("", "sub.C.x0")):
        first = _x0(tmp_path, "a", build([], extra={element: [(name, 11.0), (name, 12.0)]}))
        assert first == 12.0, element
    assert _x0(tmp_path, "b", build([("sub", "ssv"), ("sub", "inline")])) == 2.0
    # the same system binding the parameter directly and through its connector: the direct binding is kept
    # (SSP orders bindings, not connections), with a note naming both
    system = read_ssp(write_archive(tmp_path / "tie.ssp", build([("sub:g", "ssv"), ("sub", "inline")])))
    assert system.raw["units"]["sub.C"]["parameters"]["x0"] == 2.0
    assert any("bound directly" in n and "'sub.C.x0'" in n for n in system.notes)


def test_a_connector_without_a_value_passes_the_lower_binding_through(tmp_path):
    # k is connected to sub.g but bound by nobody: sub's value of g still reaches C.x0 and beats C's own
    assert _x0(tmp_path, "g", build([("C", "inline"), ("sub:g", "ssv")])) == 3.0


def test_the_overridden_value_is_named_in_one_note(tmp_path):
    system = read_ssp(write_archive(tmp_path / "note.ssp", build([("C", "ssv"), ("root:k", "ssv")])))
    [note] = [n for n in system.notes if "overrides" in n]
    assert "'sub.C.x0'" in note and "6.0" in note and "1.0" in note and "resources/C.ssv" in note


@pytest.mark.parametrize("bindings,want", [
    ([("C", "ssv"), ("sub", "ssv")], 2.0),
    ([("C", "ssm"), ("root:k", "ssv")], 6.0),
    ([("C", "inline"), ("sub:g", "ssm"), ("root", "prefix")], 4.0),
])
def test_the_chosen_value_is_the_one_the_fmu_starts_from(tmp_path, bindings, want):
    path = write_archive(tmp_path / "run.ssp", build(bindings))
    result = Execution(check_spec(path, {"step": 0.05}), record=True).run()
    assert result.ok, result.message
    assert float(result.traces["sub.C.y"].iloc[0]) == want


def test_a_sub_systems_bound_connector_behind_an_unbound_root_connector_is_a_signal_and_takes_set(tmp_path):
    # root.k (no value) -> sub.g (sub binds 3) -> C.x0 (C binds 1): g's 3 is recorded as 'root.sub.g' and used;
    # --set root.sub.g=9 sets C.x0 through the parameter connection
    import json

    import pandas as pd

    from cosim.cli.main import main

    write_archive(tmp_path / "g.ssp", build([("C", "inline"), ("sub:g", "ssv")]))
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"system": "g.ssp", "experiment": {"step": 0.05},
                                "record": ["root.sub.g", "sub.C.y"]}))
    system = check_spec(spec)
    assert system.units["root.sub"].spec.options["feeds"] == {"g": [{"to": "sub.C.x0", "factor": 1.0,
                                                                     "offset": 0.0}]}
    result = Execution(system, record=True).run()
    assert result.ok and float(result.traces["root.sub.g"].iloc[0]) == 3.0
    assert float(result.traces["sub.C.y"].iloc[0]) == 3.0
    out = tmp_path / "t.csv"
    assert main(["run", str(spec), "--set", "root.sub.g=9", "--out", str(out)]) == 0
    traces = pd.read_csv(out)
    assert float(traces["sub.C.y"].iloc[0]) == 9.0 and float(traces["root.sub.g"].iloc[0]) == 9.0


def test_a_calculated_parameter_connector_binds_and_records_as_a_parameter_connector(tmp_path):
    # OMSimulator writes kind="calculatedParameter" for a system connector computed from others: bound, it is a
    # parameter connector like any (a signal, feeding what it is connected to)
    import json

    members = build([("C", "inline"), ("root:sub.g", "ssv")])
    ssd = members["SystemStructure.ssd"].decode().replace('name="g" kind="parameter"', 'name="g" kind="calculatedParameter"')
    assert 'kind="calculatedParameter"' in ssd
    write_archive(tmp_path / "calc.ssp", {**members, "SystemStructure.ssd": ssd.encode()})
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"system": "calc.ssp", "experiment": {"step": 0.05},
                                "record": ["root.sub.g"], "objectives": {"g": {"signal": "root.sub.g",
                                                                               "reduce": "final"}}}))
    result = Execution(check_spec(spec), record=True).run()
    assert result.ok and result.objectives["g"] == 5.0
    assert _x0(tmp_path, "calc2", {**members, "SystemStructure.ssd": ssd.encode()}) == 5.0
