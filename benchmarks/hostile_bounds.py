"""Bounded and linear checks of hostile sizes (issue 29, items 1 and 7): time and peak memory of `cosim validate`.

    python benchmarks/hostile_bounds.py                  # 10^4 and 10^5 (about 5 minutes on the 2-core box)
    python benchmarks/hostile_bounds.py --sizes 10000    # quicker

Each case runs ``check_spec`` (what ``cosim validate`` does) in a fresh Python process, which reports its
own wall and CPU time for the check (imports excluded; on the shared, loaded box the CPU time is the figure
to trust) and its peak resident memory (``ru_maxrss``):

- an FMI 3.0 FMU (our gain_array, rewritten) declaring ``<Dimension start="1000000000"/>``: refused by
  ``COSIM_ARRAY_ELEMENTS`` before one object per element is made (target: under a second, flat memory);
- ``record: ["a.*"]`` on arrays of N elements (was quadratic: 40 000 elements 28 s, 10^5 over 300 s);
- N element connections ``a.y[i] -> b.u[i]`` between two such FMUs (target: linear in N), in a spec.json and
  as ``ssd:Connection``s of an SSP archive (the reader flattens them into the same spec connections);
- an SSP whose root system declares N connectors and holds N connections from names it does not declare:
  N problems, each at its own ``ssd:Connection[i]`` (was quadratic: a suggestion compared with every
  connector, and the siblings counted again, per problem).

Under load the wall times say little; the ratio between sizes shows whether a path is linear.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

CHILD = """
import json, resource, sys, time
from cosim.errors import UserError
from cosim.system.validate import check_spec
experiment = json.loads(sys.argv[2]) if len(sys.argv) > 2 else None
started, cpu = time.perf_counter(), time.process_time()
try:
    check_spec(sys.argv[1], experiment)
    outcome = "ok"
except UserError as exc:
    outcome = f"refused ({len(exc.problems)} problems): " + str(exc.problems[0].message)[:90]
print(json.dumps({"seconds": time.perf_counter() - started, "cpu": time.process_time() - cpu, "outcome": outcome,
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def sized_fmu(folder: Path, size: int) -> Path:
    """gain_array (FMI 3.0) with its arrays u and y declared as ``size`` elements each."""
    sys.path.insert(0, str(REPO / "src"))
    from cosim.fmus.build import ensure_built

    target = folder / f"gain_array_{size}.fmu"
    with zipfile.ZipFile(ensure_built("gain_array", 3)) as zin, zipfile.ZipFile(target, "w") as zout:
        for info in zin.infolist():
            data = zin.read(info)
            if info.filename == "modelDescription.xml":
                data = data.replace(b'start="0.0 0.0 0.0"', b'start="0.0"')
                data = data.replace(b'<Dimension start="3"/>', f'<Dimension start="{size}"/>'.encode())
            zout.writestr(info, data)
    return target


def ssp_of_connections(folder: Path, fmu: Path, size: int, wrong: bool = False) -> Path:
    """An SSP archive with components a and b (``fmu``) and ``size`` connections ``a.y[i] -> b.u[i]``; with
    ``wrong``, ``size`` declared root connectors ``c<i>`` and connections from undeclared ``x<i>`` instead."""
    if wrong:
        connectors = "".join(f'<ssd:Connector name="c{i}" kind="output"><ssc:Real/></ssd:Connector>\n'
                             for i in range(size))
        connections = "".join(f'<ssd:Connection startConnector="x{i}" endElement="b" endConnector="u[1]"/>\n'
                              for i in range(size))
    else:
        connectors = ""
        connections = "".join(f'<ssd:Connection startElement="a" startConnector="y[{i}]" endElement="b" '
                              f'endConnector="u[{i}]"/>\n' for i in range(1, size + 1))
    ssd = ('<?xml version="1.0" encoding="UTF-8"?>\n<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.'
           'org/SSP1/SystemStructureDescription" xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
           'name="wide" version="2.0"><ssd:System name="Root">'
           + (f"<ssd:Connectors>{connectors}</ssd:Connectors>" if connectors else "")
           + '<ssd:Elements><ssd:Component name="a" source="resources/wide.fmu"/>'
           '<ssd:Component name="b" source="resources/wide.fmu"/></ssd:Elements>'
           f'<ssd:Connections>{connections}</ssd:Connections></ssd:System>'
           '<ssd:DefaultExperiment startTime="0" stopTime="0.1"/></ssd:SystemStructureDescription>\n')
    target = folder / f"{'wrong' if wrong else 'wide'}_{size}.ssp"
    with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("SystemStructure.ssd", ssd)
        archive.write(fmu, "resources/wide.fmu")
    return target


def measure(spec: dict | Path, folder: Path, name: str) -> dict:
    if isinstance(spec, Path):  # an SSP: the step from the command line, as `cosim validate x.ssp --step 0.1`
        path, extra = spec, [json.dumps({"step": 0.1})]
    else:
        path, extra = folder / f"{name}.json", []
        path.write_text(json.dumps(spec))
    done = subprocess.run([sys.executable, "-c", CHILD, str(path), *extra], capture_output=True, text=True,
                          env={"PYTHONPATH": str(REPO / "src"), "PATH": "/usr/bin:/bin"}, timeout=1800)
    if done.returncode:
        raise RuntimeError(done.stderr)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", default="10000,100000")
    sizes = [int(s) for s in parser.parse_args().sizes.split(",")]
    load = Path("/proc/loadavg").read_text().split()[:3] if Path("/proc/loadavg").exists() else ["?"] * 3
    print(f"machine: {platform.machine()}, {platform.processor() or platform.system()}, Python "
          f"{platform.python_version()}; load average {' '.join(load)}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        experiment = {"stop": 0.1, "step": 0.1}
        huge = sized_fmu(folder, 1_000_000_000)
        result = measure({"units": {"a": {"fmu": str(huge)}}, "experiment": experiment}, folder, "huge")
        print("| case | check wall | check CPU | peak memory | outcome |")
        print(f"| 1e9-element array declared | {result['seconds']:.3f} s | {result['cpu']:.3f} s | "
              f"{result['peak_mb']:.0f} MB | {result['outcome']} |")
        for size in sizes:
            fmu = sized_fmu(folder, size)
            result = measure({"units": {"a": {"fmu": str(fmu)}}, "record": ["a.*"], "experiment": experiment},
                             folder, f"record{size}")
            print(f"| record a.* on 2 arrays of {size} | {result['seconds']:.2f} s | {result['cpu']:.2f} s | "
                  f"{result['peak_mb']:.0f} MB | {result['outcome']} |")
            connections = [{"from": f"a.y[{i}]", "to": f"b.u[{i}]"} for i in range(1, size + 1)]
            result = measure({"units": {"a": {"fmu": str(fmu)}, "b": {"fmu": str(fmu)}},
                              "connections": connections, "experiment": experiment}, folder, f"connections{size}")
            print(f"| {size} element connections (spec.json) | {result['seconds']:.2f} s | {result['cpu']:.2f} s | "
                  f"{result['peak_mb']:.0f} MB | {result['outcome']} |")
            result = measure(ssp_of_connections(folder, fmu, size), folder, f"ssp{size}")
            print(f"| {size} element connections (SSP) | {result['seconds']:.2f} s | {result['cpu']:.2f} s | "
                  f"{result['peak_mb']:.0f} MB | {result['outcome']} |")
            result = measure(ssp_of_connections(folder, fmu, size, wrong=True), folder, f"wrong{size}")
            print(f"| {size} SSP connections from undeclared connectors | {result['seconds']:.2f} s | "
                  f"{result['cpu']:.2f} s | {result['peak_mb']:.0f} MB | {result['outcome'][:60]} |")
    load = Path("/proc/loadavg").read_text().split()[:3] if Path("/proc/loadavg").exists() else ["?"] * 3
    print(f"load average at the end: {' '.join(load)}")


if __name__ == "__main__":
    main()
