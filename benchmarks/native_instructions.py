"""Instructions per unit and communication step (callgrind, independent of the machine's load): the native
kernel's loop against the C harness on the same two FMI 2.0 linear_ode instances.

    python benchmarks/native_instructions.py [--steps 20000]

* C harness (benchmarks/c_harness.c): the whole program counted at ``--steps`` and at half of it; the
  difference over the extra steps is the loop alone (2 getReal, 2 setReal, 2 doStep a step; start-up cancels).
* native kernel (benchmarks/kernel_harness.c: kernel.c itself, compiled with the kernel's flags, given the tables
  NativeFixedStep builds for the ring, the objective's column probed every step, as master_overhead.py's
  "native ... loop"), gauss-seidel and jacobi, also at ``--steps`` and half, differenced the same way.  No Python
  in the process: callgrind counts the loop, not an interpreter's start-up.

Prints instructions per unit-step for each and the kernel's ratio to the harness, and the kernel's own
overhead (its count minus the harness's: what the master adds to the FMU calls).
"""

from __future__ import annotations

import argparse
import re
import subprocess
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
def callgrind(command: list[str], toggle: str | None) -> int:
    """Instructions (Ir) callgrind counts for ``command`` (only inside ``toggle`` and what it calls, if given)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        options = ["--tool=callgrind", f"--callgrind-out-file={out}"]
        if toggle:
            options += ["--collect-atstart=no", f"--toggle-collect={toggle}"]
        subprocess.run(["valgrind", *options, *command], check=True, capture_output=True, text=True)
        text = out.read_text()
    match = re.search(r"^summary:\s+(\d+)", text, re.M) or re.search(r"^totals:\s+(\d+)", text, re.M)
    assert match, "no totals in callgrind's output"
    return int(match.group(1))


def fmu_arguments(steps: int) -> list[str]:
    from fmpy import extract, read_model_description

    from cosim.fmus.build import ensure_built

    path = str(ensure_built("linear_ode", 2))
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    folder = extract(path)
    library = Path(folder) / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
    return [Path(folder, "resources").as_uri(), str(library), md.guid, str(steps), "0.001", str(vr["y"]), str(vr["u"])]


def compiled(source: str, flags: list[str]) -> str:
    from cosim.fmus.build import c_compiler

    binary = Path(tempfile.gettempdir()) / f"cosim_{Path(source).stem}_{int((HERE / source).stat().st_mtime)}"
    if not binary.exists():
        subprocess.run([c_compiler(), *flags, "-o", str(binary), str(HERE / source), "-ldl", "-lm"], check=True)
    return str(binary)


def per_unit_step(command: list[str], full: int, half: int) -> float:
    """Instructions per unit-step of ``command`` + the FMU arguments + ``extra``: the count at ``full`` steps
    minus the count at ``half``, over the extra steps and the 2 units."""
    def count(steps: int) -> int:
        return callgrind([command[0], *fmu_arguments(steps), *command[1:]], None)
    return (count(full) - count(half)) / (full - half) / 2


def main() -> None:
    from cosim.master.native.library import CFLAGS

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=20000)
    args = parser.parse_args()
    full, half = args.steps, args.steps // 2
    print(f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; callgrind instruction counts (load-independent)")
    harness = per_unit_step([compiled("c_harness.c", ["-O2", "-std=c99"])], full, half)
    print(f"C harness: {harness:.1f} instructions per unit-step")
    flags = [f for f in CFLAGS if f not in ("-shared", "-fPIC")]
    kernel_binary = compiled("kernel_harness.c", flags)
    for algorithm in ("gauss-seidel", "jacobi"):
        kernel = per_unit_step([kernel_binary, algorithm], full, half)
        print(f"native {algorithm}: {kernel:.1f} instructions per unit-step, {kernel / harness:.2f}x the "
              f"harness; the kernel's own {kernel - harness:.1f} on top of the same FMU calls")


if __name__ == "__main__":
    main()
