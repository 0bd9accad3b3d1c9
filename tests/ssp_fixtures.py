"""Building SSPs in tests: hand-written .ssd/.ssv/.ssm files from tests/ssp/ plus FMUs built from fmus/."""

from __future__ import annotations

import math
import zipfile
from pathlib import Path

from cosim.fmus.build import ensure_built

SSP_FILES = Path(__file__).resolve().parent / "ssp"
RPM = 2 * math.pi / 60  # rad/s per rpm


def nested_ssd() -> str:
    return (SSP_FILES / "nested.ssd").read_text()


def nested_files(ssd_text: str | None = None) -> dict[str, bytes]:
    """The members of the 'nested' test SSP (tests/ssp/), with another SSD text if given."""
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
    """tests/ssp/oms3.ssd: a system as OMSimulator 3 writes it (startElement="" for system connectors, a
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
