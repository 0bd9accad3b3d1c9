"""FMI conformance FMUs: small FMUs, one per FMI feature cosim must run exactly or refuse precisely.

Each folder ``fmus/conformance/<name>/`` holds ``model.c`` and a hand-written
``modelDescription2.xml`` and/or ``modelDescription3.xml`` (hand-written
because these FMUs use what the generator of ``fmus/model.json`` FMUs does not
express: Binary, String, every integer width, Enumeration, Clocks, arrays sized
by structural parameters).  ``model.c`` includes ``fmi2_runtime.c`` or
``fmi3_runtime.c`` from this folder.  They are built like the other FMUs (gcc,
fmpy's FMI headers, the same cache) but kept apart from ``fmus/common``.

    ensure_built(name, fmi_version) -> Path     # build once per source digest
    available() -> dict[str, tuple[int, ...]]    # name -> FMI versions it has

See ``docs/fmi-support.md`` for what each one checks.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import tempfile
import zipfile
from pathlib import Path

from ..build import CFLAGS, FmuBuildError, binaries_platform, c_compiler, cache_dir, fmi_headers_folder

HERE = Path(__file__).resolve().parent


def available() -> dict[str, tuple[int, ...]]:
    """Conformance FMUs by name, with the FMI versions each has a model description for."""
    out = {}
    for folder in sorted(p for p in HERE.iterdir() if (p / "model.c").is_file()):
        versions = tuple(v for v in (2, 3) if (folder / f"modelDescription{v}.xml").is_file())
        out[folder.name] = versions
    return out


def _inputs(name: str, fmi_version: int) -> list[Path]:
    folder = HERE / name
    return [folder / "model.c", folder / f"modelDescription{fmi_version}.xml", HERE / f"fmi{fmi_version}_runtime.c"]


def _digest(name: str, fmi_version: int) -> str:
    h = hashlib.sha256(b"conformance\0")
    for path in _inputs(name, fmi_version):
        h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    h.update(repr((fmi_version, CFLAGS, binaries_platform(fmi_version), os.environ.get("CC", "gcc"))).encode())
    return h.hexdigest()


def build(name: str, fmi_version: int, out_dir: str | os.PathLike) -> Path:
    """Compile conformance FMU ``name`` for ``fmi_version`` into ``out_dir/<name>_fmi<v>.fmu``.

    Raises FmuBuildError for an unknown name or version and for a failed compile (with gcc's output).
    """
    versions = available().get(name)
    if versions is None or fmi_version not in versions:
        raise FmuBuildError(f"no conformance FMU '{name}' for FMI {fmi_version}; available: {available()}")
    folder = HERE / name
    platform_folder, suffix = binaries_platform(fmi_version)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    target = out / f"{name}_fmi{fmi_version}.fmu"
    with tempfile.TemporaryDirectory(prefix=f"build-{name}-", dir=out) as tmp:
        library = Path(tmp) / f"{name}{suffix}"
        command = [c_compiler(), *CFLAGS, f"-DFMI_VERSION={fmi_version}", f"-I{fmi_headers_folder()}",
                   str(folder / "model.c"), "-o", str(library), "-lm"]
        result = subprocess.run(command, capture_output=True, text=True)
        if result.returncode != 0:
            raise FmuBuildError(f"compiling {name} (FMI {fmi_version}) failed:\n{' '.join(command)}\n"
                                f"{result.stderr.strip()}")
        partial = Path(tmp) / "fmu.partial"
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.write(folder / f"modelDescription{fmi_version}.xml", "modelDescription.xml")
            zf.write(library, f"binaries/{platform_folder}/{name}{suffix}")
        os.replace(partial, target)  # atomic: concurrent builders never see half an FMU
    return target


def ensure_built(name: str, fmi_version: int) -> Path:
    """Path of an up-to-date conformance FMU, built on first use (cache shared with cosim.fmus.build)."""
    target = cache_dir() / ("conformance-" + _digest(name, fmi_version)[:20]) / f"{name}_fmi{fmi_version}.fmu"
    return target if target.is_file() else build(name, fmi_version, target.parent)
