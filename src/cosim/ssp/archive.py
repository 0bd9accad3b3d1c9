"""Where the files of an SSP are: an .ssp archive, a folder, or one .ssd file.

An archive is extracted once per process into a temporary folder that is
removed when the process exits (the FMUs of its components are read from
there), by :func:`cosim.util.archive.safe_extract`: members that would leave
the folder, links, special files and archives that unpack beyond the limits
are refused.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass, field
from pathlib import Path

from cosim.errors import Problem, SpecError, did_you_mean
from cosim.util.archive import MEMBER_SEPARATOR, ArchiveError, extracted_ssp

SSD_NAME = "SystemStructure.ssd"


def is_ssp(path: str | Path) -> bool:
    """True for an .ssp archive, an .ssd file, or a folder holding SystemStructure.ssd."""
    path = Path(path)
    suffix = path.suffix.lower()
    return suffix in (".ssp", ".ssd") or (path.is_dir() and (path / SSD_NAME).is_file())


@dataclass(frozen=True)
class SspFiles:
    """The files of one SSP: ``root`` holds the SSD; ``beside`` is the folder around an archive."""

    given: str  # the path as the user gave it, for messages
    root: Path
    ssd: Path
    beside: Path | None
    archive: Path | None = None
    variants: dict[str, Path] = field(default_factory=dict)  # variant name -> its SSD (see :func:`variants_of`)
    variant: str | None = None  # the name of the variant read (the SSD's name)
    notes: tuple[str, ...] = ()  # what choosing the variant noted (two SSDs of one name)

    def label(self, path: Path) -> str:
        """How a message names a file of this SSP: ``system.ssp:resources/a.ssv``."""
        try:
            inner = path.resolve().relative_to(self.root.resolve()).as_posix()
        except ValueError:
            return str(path)
        return f"{self.given}:{inner}"

    def reference(self, path: Path) -> str:
        """How a spec names a file of this SSP: ``/abs/system.ssp!/resources/a.fmu`` for an archive member.

        The name stays the same in every process (the extraction folder does
        not), so a spec read from an SSP keeps its digest; see :func:`cosim.util.archive.member_file`.
        """
        if self.archive is not None and self.inside(path):
            return f"{self.archive}{MEMBER_SEPARATOR}{path.resolve().relative_to(self.root.resolve()).as_posix()}"
        return str(path)

    def inside(self, path: Path) -> bool:
        resolved = path.resolve()
        root = self.root.resolve()
        return resolved == root or root in resolved.parents


def open_ssp(path: str | Path, variant: str | None = None) -> SspFiles:
    """The files of the SSP at ``path``, with the SSD of ``variant`` (default: SystemStructure.ssd, or the
    given .ssd file); raises SpecError when there is none, or no variant of that name."""
    files = _locate(path)
    variants, notes = variants_of(files)
    chosen = files.ssd.resolve()
    if variant is not None:
        picked = variants.get(variant) or next((p for p in variants.values() if p.stem == variant), None)
        if picked is None:
            listed = ", ".join(f"{name} ({files.label(p)})" for name, p in variants.items())
            raise SpecError([Problem(files.given, "/", f"the SSP has no variant '{variant}'; its variants: {listed}."
                                     + did_you_mean(variant, list(variants)),
                                     "give --variant (or \"variant\" in the spec's \"system\") one of these names")])
        chosen = picked
    name = next((n for n, p in variants.items() if p == chosen), None)
    return SspFiles(files.given, files.root.resolve(), chosen, files.beside, files.archive, variants, name,
                    tuple(notes))


def variants_of(files: SspFiles) -> tuple[dict[str, Path], list[str]]:
    """The SSDs of an SSP by variant name (their root's ``name``, else the file stem), SystemStructure.ssd first,
    then every other .ssd at the root in name order (how OMSimulator 3 stores variants); and notes.

    When two SSDs give one name, SystemStructure.ssd (else the first) keeps it, with a note: OMSimulator 3 leaves
    a stale copy of a variant it made active.
    """
    default = files.ssd.resolve()
    candidates = [default] + sorted(p.resolve() for p in default.parent.glob("*.ssd")
                                    if p.is_file() and p.resolve() != default)
    variants: dict[str, Path] = {}
    notes = []
    for ssd in candidates:
        name = _ssd_name(ssd) or ssd.stem
        if name in variants:
            notes.append(f"{files.label(ssd)} names its variant '{name}' as {files.label(variants[name])} does: "
                         f"'{name}' is {files.label(variants[name])}")
            continue
        variants[name] = ssd
    return variants, notes


def _ssd_name(path: Path) -> str | None:
    """The ``name`` of an SSD's root element, read from its start only (None when it cannot be read)."""
    from lxml import etree

    try:
        for _, element in etree.iterparse(str(path), events=("start",), resolve_entities=False, no_network=True,
                                          load_dtd=False, huge_tree=False):
            return element.get("name")
    except (etree.XMLSyntaxError, OSError):
        return None
    return None


def _locate(path: str | Path) -> SspFiles:
    """The files of the SSP at ``path`` with its default SSD; raises SpecError when there is none."""
    path = Path(path)
    given = str(path)
    if not path.exists():
        raise SpecError([Problem(given, "/", "file not found", "check the path of the SSP")])
    if path.is_dir():
        ssd = path / SSD_NAME
        if not ssd.is_file():
            raise SpecError([Problem(given, "/", f"the folder has no {SSD_NAME}",
                                     "give an .ssp archive, an .ssd file, or the folder an SSP was unpacked into")])
        # absolute from here on: the spec resolves relative FMU paths against its own folder, not the cwd
        return SspFiles(given, path.resolve(), ssd.resolve(), None)
    if path.suffix.lower() == ".ssd":
        return SspFiles(str(path.parent), path.parent.resolve(), path.resolve(), None)
    if not zipfile.is_zipfile(path):
        raise SpecError([Problem(given, "/", "not a zip archive", "an .ssp file is a zip archive with "
                                 f"{SSD_NAME} at its root; re-export it from its tool")])
    try:
        folder = extracted_ssp(path)
    except ArchiveError as exc:
        raise SpecError(exc.problems) from None
    except (zipfile.BadZipFile, OSError) as exc:
        raise SpecError([Problem(given, "/", f"cannot extract the archive: {exc}", "re-export the SSP")]) from None
    ssd = folder / SSD_NAME
    if not ssd.is_file():
        raise SpecError([Problem(given, "/", f"the archive has no {SSD_NAME} at its root",
                                 f"an SSP archive holds its system in {SSD_NAME} at the top level")])
    return SspFiles(given, folder, ssd, path.resolve().parent, path.resolve())
