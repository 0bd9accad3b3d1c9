"""Compile the FMUs in ``fmus/<name>/`` into ``.fmu`` files.

Public API::

    build_fmu(name, fmi_version, out_dir, interfaces=None) -> Path   # always compiles
    ensure_built(name, fmi_version, interfaces=None) -> Path         # compiles once per source digest
    available_models() -> list[str]
    cache_dir() -> Path                             # $COSIM_FMU_CACHE or ~/.cache/cosim/fmus

File names are ``<name>_fmi2.fmu`` and ``<name>_fmi3.fmu``.  ``ensure_built``
keeps them in ``cache_dir()/<digest>/`` where the digest covers every input of
the build (the model's files, ``fmus/common``, the generator, the compiler
flags and the platform), so an edit rebuilds and nothing else does.
``interfaces`` picks what the FMU offers, ``("CoSimulation",)``,
``("ModelExchange",)`` or both; by default every interface the model's
``model.json`` supports.

Command line (rebuilds, no traceback on errors)::

    python -m cosim.fmus.build [--out DIR] [--fmi {2,3}] [--interfaces cs|me|cs,me] [NAME ...]

Without ``--out`` the FMUs are rebuilt into the cache; without names every
model is built, for both FMI versions.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

from cosim.errors import (
    FmuBuildError,  # one error family: a failed build is the user's to fix
)

from .model_description import (
    ModelJsonError,
    fmi2_model_description,
    fmi3_model_description,
    generated_header,
    generated_source,
    load_model,
)

FMUS_DIR = Path(__file__).resolve().parent
COMMON_DIR = FMUS_DIR / "common"
CFLAGS = ("-shared", "-fPIC", "-O2", "-std=c99", "-D_POSIX_C_SOURCE=200809L", "-fvisibility=hidden", "-Wall", "-Wextra")
FMI_VERSIONS = (2, 3)
INTERFACE_CHOICES = {"cs": ("CoSimulation",), "me": ("ModelExchange",), "cs,me": ("CoSimulation", "ModelExchange")}


def available_models() -> list[str]:
    """Names of the models in ``fmus/`` (folders holding a ``model.json``)."""
    return sorted(p.parent.name for p in FMUS_DIR.glob("*/model.json"))


def cache_dir() -> Path:
    """Where ``ensure_built`` keeps FMUs: ``$COSIM_FMU_CACHE`` or ``~/.cache/cosim/fmus``."""
    env = os.environ.get("COSIM_FMU_CACHE")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "cosim" / "fmus"


def fmu_filename(name: str, fmi_version: int) -> str:
    return f"{name}_fmi{fmi_version}.fmu"


def _model_dir(name: str) -> Path:
    folder = FMUS_DIR / name
    if not (folder / "model.json").is_file():
        raise FmuBuildError(f"no FMU model '{name}' (expected {folder}/model.json); available: {', '.join(available_models())}")
    return folder


def _check_version(fmi_version: int) -> None:
    if fmi_version not in FMI_VERSIONS:
        raise FmuBuildError(f"FMI version must be 2 or 3, not {fmi_version!r}")


def c_compiler() -> str:
    """The C compiler to build with ($CC, else gcc) as a path; FmuBuildError when it is not installed."""
    cc = os.environ.get("CC", "gcc")
    path = shutil.which(cc)
    if path is None:
        raise FmuBuildError(f"no C compiler '{cc}' found: install gcc (apt-get install gcc) or set CC to a C compiler")
    return path


def fmi_headers_folder() -> Path:
    """fmpy's folder of the FMI 2.0 and 3.0 headers; FmuBuildError when they are missing."""
    try:
        import fmpy
    except ImportError as exc:  # pragma: no cover - fmpy is a dependency
        raise FmuBuildError("fmpy is not installed (pip install fmpy); its c-code folder holds the FMI headers") from exc
    include = Path(fmpy.__file__).resolve().parent / "c-code"
    if not (include / "fmi2Functions.h").is_file() or not (include / "fmi3Functions.h").is_file():
        raise FmuBuildError(f"FMI headers not found in {include}; reinstall fmpy")
    return include


def binaries_platform(fmi_version: int) -> tuple[str, str]:
    """The binaries folder name and shared-library suffix fmpy looks for here."""
    import fmpy

    if not sys.platform.startswith("linux"):
        raise FmuBuildError(f"building FMUs is supported on Linux only (this is {sys.platform})")
    folder = fmpy.platform if fmi_version == 2 else fmpy.platform_tuple  # e.g. linux64 / x86_64-linux, aarch64-linux
    return folder, fmpy.sharedLibraryExtension


def _sources(name: str) -> list[Path]:
    folder = _model_dir(name)
    files = [p for p in sorted(folder.iterdir()) if p.is_file() and p.suffix in (".c", ".h", ".json")]
    files += sorted(p for p in COMMON_DIR.iterdir() if p.suffix in (".c", ".h"))
    files += [FMUS_DIR / "model_description.py", Path(__file__).resolve()]
    return files


def source_digest(name: str, fmi_version: int, interfaces: tuple[str, ...] | None = None) -> str:
    """Hex digest of every input of the build of ``name`` for ``fmi_version`` (and ``interfaces``, if chosen)."""
    _check_version(fmi_version)
    h = hashlib.sha256()
    for path in _sources(name):
        h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    h.update(repr((fmi_version, CFLAGS, binaries_platform(fmi_version), os.environ.get("CC", "gcc"))).encode())
    if interfaces is not None:  # the default build keeps the digest it had before interfaces could be chosen
        h.update(repr(sorted(interfaces)).encode())
    return h.hexdigest()


def build_fmu(name: str, fmi_version: int, out_dir: str | os.PathLike,
              interfaces: tuple[str, ...] | None = None) -> Path:
    """Compile ``fmus/<name>`` into ``out_dir/<name>_fmi<version>.fmu`` and return its path.

    ``interfaces`` (``"CoSimulation"``, ``"ModelExchange"``) chooses what the
    FMU offers; by default all the model supports.

    The file appears atomically (written under a temporary name, then
    renamed), so concurrent builders and readers never see half an FMU.
    Raises :class:`FmuBuildError` for an unknown model or version, a missing
    compiler, a bad ``model.json``, an interface the model does not support
    or a compile error (with gcc's output).
    """
    _check_version(fmi_version)
    folder = _model_dir(name)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return build_model_folder(folder, fmi_version, out / fmu_filename(name, fmi_version), interfaces,
                              digest=source_digest(name, fmi_version, interfaces))


def build_model_folder(folder: Path, fmi_version: int, target: Path, interfaces: tuple[str, ...] | None = None,
                       digest: str = "", extra_sources: tuple[Path, ...] = ()) -> Path:
    """Compile the model in ``folder`` (``model.json``, ``model.c``; it need not lie in ``fmus/``) into the FMU
    ``target``, with ``extra_sources`` (C files; their folders are on the include path) compiled in too.

    ``digest`` goes into the instantiation token (default: one of the folder's files).  This is how a model
    written elsewhere (``cosim export-surrogate``'s generated one) reuses the framework in ``common/``.
    Raises :class:`FmuBuildError` as :func:`build_fmu` does; the model's name must be its folder's.
    """
    folder = Path(folder)
    name = folder.name
    if not digest:
        h = hashlib.sha256()
        for path in sorted(folder.iterdir()):
            if path.is_file():
                h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
        digest = h.hexdigest()
    try:
        model = load_model(folder / "model.json", digest=digest)
        offered = model.offers(tuple(interfaces) if interfaces is not None else None)
    except ModelJsonError as exc:
        raise FmuBuildError(str(exc)) from exc
    if model.name != name:
        raise FmuBuildError(f"{folder}/model.json: name is '{model.name}', expected the folder name '{name}'")
    cc = c_compiler()
    include = fmi_headers_folder()
    platform_folder, suffix = binaries_platform(fmi_version)
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    extra_includes = sorted({f"-I{Path(p).resolve().parent}" for p in extra_sources})

    with tempfile.TemporaryDirectory(prefix=f"build-{name}-", dir=target.parent) as tmp:
        work = Path(tmp)
        (work / "model_generated.h").write_text(generated_header(model, offered))
        (work / "model_generated.c").write_text(generated_source(model))
        xml = fmi2_model_description(model, offered) if fmi_version == 2 else fmi3_model_description(model, offered)
        library = work / f"{name}{suffix}"
        sources = [COMMON_DIR / "framework.c", COMMON_DIR / f"fmi{fmi_version}.c", COMMON_DIR / "model_exchange.c",
                   COMMON_DIR / f"fmi{fmi_version}_me.c", folder / "model.c", work / "model_generated.c",
                   *map(Path, extra_sources)]
        command = [cc, *CFLAGS, f"-I{work}", f"-I{COMMON_DIR}", f"-I{folder}", *extra_includes, f"-I{include}",
                   *map(str, sources), "-o", str(library), "-lm"]
        result = subprocess.run(command, capture_output=True, text=True)
        if result.returncode != 0:
            raise FmuBuildError(f"compiling {name} (FMI {fmi_version}) failed:\n{' '.join(command)}\n{result.stderr.strip()}")
        partial = work / "fmu.partial"
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.writestr("modelDescription.xml", xml)
            zf.write(library, f"binaries/{platform_folder}/{name}{suffix}")
        os.replace(partial, target)  # atomic on one file system: tmp is beside the target
    return target


def ensure_built(name: str, fmi_version: int, interfaces: tuple[str, ...] | None = None) -> Path:
    """Path of an up-to-date ``<name>_fmi<version>.fmu``, building it on first use.

    ``interfaces`` as for :func:`build_fmu` (each choice has its own cache folder).

    The FMU lives in ``cache_dir()/<digest>/``; it is rebuilt only when its
    sources change.  Safe when several processes call this at once: each
    builds into a temporary file and renames it into place.
    Raises :class:`FmuBuildError` like :func:`build_fmu`.
    """
    digest = source_digest(name, fmi_version, interfaces)
    folder = cache_dir() / digest[:20]
    target = folder / fmu_filename(name, fmi_version)
    if target.is_file():
        return target
    return build_fmu(name, fmi_version, folder, interfaces)


def main(argv: list[str] | None = None) -> int:
    """The ``python -m cosim.fmus.build`` command; returns the exit code."""
    parser = argparse.ArgumentParser(prog="python -m cosim.fmus.build", description="Build cosim's FMUs from fmus/<name>/.")
    parser.add_argument("names", nargs="*", metavar="NAME", help=f"models to build (default: all: {', '.join(available_models())})")
    parser.add_argument("--out", type=Path, help="write the .fmu files here (default: rebuild into the cache)")
    parser.add_argument("--fmi", type=int, choices=FMI_VERSIONS, action="append", help="FMI version (default: 2 and 3)")
    parser.add_argument("--interfaces", choices=sorted(INTERFACE_CHOICES),
                        help="cs (co-simulation), me (Model Exchange) or cs,me (default: what each model supports)")
    args = parser.parse_args(argv)
    names = args.names or available_models()
    interfaces = INTERFACE_CHOICES[args.interfaces] if args.interfaces else None
    try:
        for name in names:
            for version in args.fmi or FMI_VERSIONS:
                out = args.out if args.out else cache_dir() / source_digest(name, version, interfaces)[:20]
                print(build_fmu(name, version, out, interfaces))
    except FmuBuildError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
