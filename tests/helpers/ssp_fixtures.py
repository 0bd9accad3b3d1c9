"""Building SSPs in tests: hand-written .ssd/.ssv/.ssm files from tests/data/ssp/ plus FMUs built from fmus/."""

from __future__ import annotations

import math
import zipfile
from pathlib import Path

from cosim.fmus.build import ensure_built
from tests.helpers.paths import DATA

SSP_FILES = DATA / "ssp"
RPM = 2 * math.pi / 60  # rad/s per rpm


def nested_ssd() -> str:
    return (SSP_FILES / "nested.ssd").read_text()


def nested_files(ssd_text: str | None = None) -> dict[str, bytes]:
    """The members of the 'nested' test SSP (tests/data/ssp/), with another SSD text if given."""
    ssd = ssd_text if ssd_text is not None else nested_ssd()
    fmu = Path(ensure_built("linear_ode", 2)).read_bytes()
    return {
        "SystemStructure.ssd": ssd.encode(),
        "resources/linear_ode.fmu": fmu,
        "resources/integrator.ssv": (SSP_FILES / "integrator.ssv").read_bytes(),
        "resources/start.ssv": (SSP_FILES / "start.ssv").read_bytes(),
        "resources/start.ssm": (SSP_FILES / "start.ssm").read_bytes(),
    }


def write_archive(path: Path, members: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    return path


def write_folder(folder: Path, members: dict[str, bytes]) -> Path:
    for name, data in members.items():
        target = folder / name
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(data)
    return folder


def nested_expected(algorithm: str, stop: float = 1.0, step: float = 0.01, factor: float = RPM,
                    sink_b: float = 1.0) -> dict[str, float]:
    """Final values of the nested SSP, computed here from its equations (not by cosim).

    source: y = 3 (a = b = 0, x0 = 3 from the root binding, which beats the
    component's own x0 = 5); SuT.integrator: a = 0, b = 2 (external .ssv with
    prefix), x0 = 2 * 0.5 (.ssm mapping with factor 2), input = factor * 3
    (rpm -> rad/s); sink: a = 0, b = sink_b, input = 10 * integrator.y + 1.
    linear_ode integrates exactly: with a = 0, y(t + h) = y + h * b * u.
    """
    n = round(stop / step)
    u = factor * 3.0
    integrator, sink = 1.0, 0.0
    for _ in range(n):
        if algorithm == "jacobi":  # every unit sees the outputs at the start of the step
            sink += step * sink_b * (10 * integrator + 1)
            integrator += step * 2 * u
        else:  # gauss-seidel: source, SuT.integrator, sink; the sink sees the new integrator output
            integrator += step * 2 * u
            sink += step * sink_b * (10 * integrator + 1)
    return {"source.y": 3.0, "SuT.integrator.y": integrator, "sink.y": sink}


def oms3_ssd() -> str:
    """tests/data/ssp/oms3.ssd: a system as OMSimulator 3 writes it (startElement="" for system connectors, a
    parameter connection root.k -> sub.gain -> sub.B.b, inline values on the root and on each component)."""
    return (SSP_FILES / "oms3.ssd").read_text()


def oms3_files(ssd_text: str | None = None, **extra: bytes) -> dict[str, bytes]:
    """The members of the OMSimulator-3-form test SSP; ``extra`` adds members by name (``resources/x.ssv``)."""
    members = {
        "SystemStructure.ssd": (ssd_text if ssd_text is not None else oms3_ssd()).encode(),
        "resources/linear_ode.fmu": Path(ensure_built("linear_ode", 2)).read_bytes(),
    }
    members.update(extra)
    return members


def oms3_expected(t: float, x0_a: float = 2.0, x0_b: float = 0.0, b_b: float = -0.5) -> dict[str, float]:
    """Values of the OMS3-form SSP at time t, from its equations (not by cosim).

    A: a = b = 0, so y = x0_a for ever; sub.B: a = 0, b = b_b, input = A.y held constant, so B integrates
    exactly: y = x0_b + b_b * x0_a * t (under either algorithm: initialization already sets B.u = A.y).
    """
    return {"A.y": x0_a, "sub.B.y": x0_b + b_b * x0_a * t}


TABLE_COMPONENT = ('      <ssd:Component name="setpoint" type="text/csv" source="resources/setpoint.csv">\n'
                   '        <ssd:Connectors>\n          <ssd:Connector name="speed" kind="output">\n'
                   '            <ssc:Real/>\n          </ssd:Connector>\n        </ssd:Connectors>\n'
                   '      </ssd:Component>\n')
SETPOINT = b'"time","speed"\n0,0\n0.5,0\n1.5,1\n2,1\n'  # OMSimulator's result CSVs quote the names


def table_ssd() -> str:
    """oms3.ssd with a table component 'setpoint' (as OMSimulator 3 writes it) feeding sub.speed instead of A;
    its CSV is resources/setpoint.csv (:data:`SETPOINT`)."""
    ssd = oms3_ssd().replace('      <ssd:System name="sub">', TABLE_COMPONENT + '      <ssd:System name="sub">', 1)
    return ssd.replace('startElement="A" startConnector="y" endElement="sub"',
                       'startElement="setpoint" startConnector="speed" endElement="sub"')


_DC_MOTOR = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" name="{root}" version="1.0">
  <ssd:System name="{root}">
    <ssd:Connectors>
      <ssd:Connector name="{phi}" kind="output"><ssc:Real/></ssd:Connector>
      <ssd:Connector name="{gain}" kind="parameter"><ssc:Real/></ssd:Connector>
    </ssd:Connectors>
    <ssd:ParameterBindings>
      <ssd:ParameterBinding>
        <ssd:ParameterValues>
          <ssv:ParameterSet version="1.0" name="{root}">
            <ssv:Parameters>
              <ssv:Parameter name="stimuli.a"><ssv:Real value="0"/></ssv:Parameter>
              <ssv:Parameter name="stimuli.b"><ssv:Real value="0"/></ssv:Parameter>
              <ssv:Parameter name="stimuli.x0"><ssv:Real value="2"/></ssv:Parameter>
              <ssv:Parameter name="{sub}.{machine}.a"><ssv:Real value="0"/></ssv:Parameter>
              <ssv:Parameter name="{sub}.{machine}.x0"><ssv:Real value="0"/></ssv:Parameter>
              <ssv:Parameter name="{sub}.{mass}.a"><ssv:Real value="0"/></ssv:Parameter>
              <ssv:Parameter name="{sub}.{mass}.b"><ssv:Real value="0.5"/></ssv:Parameter>
              <ssv:Parameter name="{sub}.{mass}.x0"><ssv:Real value="1"/></ssv:Parameter>
              <ssv:Parameter name="{gain}"><ssv:Real value="1"/></ssv:Parameter>
            </ssv:Parameters>
          </ssv:ParameterSet>
        </ssd:ParameterValues>
      </ssd:ParameterBinding>
    </ssd:ParameterBindings>
    <ssd:Elements>
      <ssd:Component name="stimuli" type="application/x-fmu-sharedlibrary" source="resources/linear_ode.fmu">
        <ssd:Connectors><ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector></ssd:Connectors>
      </ssd:Component>
      <ssd:System name="{sub}">
        <ssd:Connectors>
          <ssd:Connector name="{tau}" kind="input"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="{phi}" kind="output"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="{gain}" kind="parameter"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
        <ssd:Elements>
          <ssd:Component name="{machine}" type="application/x-fmu-sharedlibrary" source="resources/linear_ode.fmu">
            <ssd:Connectors>
              <ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>
              <ssd:Connector name="b" kind="parameter"><ssc:Real/></ssd:Connector>
              <ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector>
            </ssd:Connectors>
          </ssd:Component>
          <ssd:Component name="{mass}" type="application/x-fmu-sharedlibrary" source="resources/linear_ode.fmu">
            <ssd:Connectors>
              <ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>
              <ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector>
            </ssd:Connectors>
          </ssd:Component>
        </ssd:Elements>
        <ssd:Connections>
          <ssd:Connection startConnector="{tau}" endElement="{machine}" endConnector="u"/>
          <ssd:Connection startConnector="{gain}" endElement="{machine}" endConnector="b"/>
          <ssd:Connection startElement="{machine}" startConnector="y" endElement="{mass}" endConnector="u"/>
          <ssd:Connection startElement="{mass}" startConnector="y" endConnector="{phi}"/>
        </ssd:Connections>
      </ssd:System>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="stimuli" startConnector="y" endElement="{sub}" endConnector="{tau}"/>
      <ssd:Connection startConnector="{gain}" endElement="{sub}" endConnector="{gain}"/>
      <ssd:Connection startElement="{sub}" startConnector="{phi}" endConnector="{phi}"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="1"/>
</ssd:SystemStructureDescription>
"""

DC_MOTOR_NAMES = {"root": "DC-Motor", "sub": "SuT", "machine": "emachine_model", "mass": "edrive_mass",
                  "phi": "phiB", "tau": "tau", "gain": "gain"}


def dc_motor_ssd(**names: str) -> str:
    """A DC motor as Dymola exports it (issue 33): root system 'DC-Motor' with an output connector and a
    parameter connector bound inline, a stimuli FMU, a nested system 'SuT' holding 'emachine_model' and
    'edrive_mass' (linear_ode each) with system connectors of its own. ``names`` replaces any of
    :data:`DC_MOTOR_NAMES` (a hyphen, space, dot or non-ASCII letter where SSP allows one)."""
    return _DC_MOTOR.format(**{**DC_MOTOR_NAMES, **names})


def dc_motor_expected(t_end: float, step: float, gain: float = 1.0) -> dict[str, float]:
    """The DC motor's final values under jacobi, from its equations (not by cosim): stimuli y = 2;
    emachine_model: b = gain (the parameter connector), u = 2, so y += step * 2 * gain; edrive_mass: b = 0.5,
    x0 = 1, u = the machine's y at the start of each step."""
    machine, mass = 0.0, 1.0
    for _ in range(round(t_end / step)):
        mass += step * 0.5 * machine
        machine += step * 2.0 * gain
    return {"machine": machine, "mass": mass}
