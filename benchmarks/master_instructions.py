"""Two Executions of two coupled linear_ode FMUs for N steps: the workload counted by callgrind in
benchmarks/master_overhead.md (usage: valgrind --tool=callgrind python benchmarks/master_instructions.py N FMI ALGORITHM)."""
import json
import sys
import tempfile
from pathlib import Path

from cosim import Execution, build_system, load_spec

steps, version, algorithm = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
h = 1e-3
spec = {"units": {"one": {"fmu": f"builtin:linear_ode_fmi{version}"}, "two": {"fmu": f"builtin:linear_ode_fmi{version}"}},
        "connections": [{"from": "one.y", "to": "two.u"}, {"from": "two.y", "to": "one.u"}],
        "experiment": {"stop": steps * h, "step": h, "algorithm": algorithm},
        "record": [], "objectives": {"y": {"signal": "one.y", "reduce": "final"}}}
with tempfile.TemporaryDirectory() as folder:
    path = Path(folder) / "spec.json"
    path.write_text(json.dumps(spec))
    system = build_system(load_spec(path))
    Execution(system).run()  # warm: extract, load
    result = Execution(system).run()
assert result.ok and result.steps == steps
