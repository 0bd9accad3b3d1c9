"""One reading of one SSP: its files, the problems and notes collected so far, and the elements read.

Every step of the reader (:mod:`.elements`, :mod:`.connections`, :mod:`.bindings`, :mod:`.experiment`) records
its problems here (file inside the archive, element path, fix) instead of raising, so that all of them are
reported at once; the reader raises them as one SpecError.
"""

from __future__ import annotations

import contextlib
import logging
import urllib.parse
from pathlib import Path
from typing import Any, Iterator

from cosim.errors import AnnotationNumberError, Problem
from cosim.ssp.annotations import Solvers
from cosim.ssp.archive import SspFiles
from cosim.ssp.model import Edge, Node
from cosim.ssp.notes import AlikeNotes
from cosim.ssp.tolerant import tolerated
from cosim.ssp.xml import display_name, element_path, parse_file, schema_problems
from cosim.util.quantities import UnitDefinition

log = logging.getLogger("cosim.ssp")
_LOGGED: set[tuple[str, str]] = set()


_HELD: list[list[str]] = []  # notes held by held_notes() instead of logged, innermost last


def log_once(given: str, text: str) -> None:
    """Log the note ``text`` about the SSP ``given`` once per process (an SSP is often read twice: validate,
    then run; a spec naming it, then the SSP alone); inside :func:`held_notes`, keep it there instead."""
    if (given, text) in _LOGGED:
        return
    _LOGGED.add((given, text))
    if _HELD:
        _HELD[-1].append(text)
    else:
        log.warning("%s: %s", given, text)


@contextlib.contextmanager
def held_notes() -> Iterator[list[str]]:
    """The notes of the SSPs read inside, each once, in a list (for a command that prints them itself, e.g.
    ``cosim inspect``: logged as well they would show twice).  Logged after all when the block raises."""
    held: list[str] = []
    _HELD.append(held)
    try:
        yield held
    except BaseException:
        for text in held:
            log.warning("%s", text)
        raise
    finally:
        _HELD.remove(held)


class Reading:
    """The state of reading one SSP: shared by the reader's steps."""

    def __init__(self, files: SspFiles):
        self.files = files
        self.label = files.label(files.ssd)
        self.problems: list[Problem] = []
        self.notes: list[str] = []
        self.alike = AlikeNotes()  # notes of which a file may hold thousands: one line per kind (see .notes)
        for note in files.notes:
            self.note(note)
        self.units: dict[str, UnitDefinition] = {}  # ssd:Units
        self.nodes: dict[tuple[str, ...], Node] = {}
        self.edges: list[Edge] = []
        self.solvers = Solvers()
        self.hints: list[str] = []  # OSP step size hints, for one note
        self.bracketed: set[str] = set()  # where a unit in brackets was noted (a value is converted repeatedly)

    def note(self, text: str) -> None:
        """Keep a note for the user; log it once per SSP and process (an SSP is often read twice)."""
        self.notes.append(text)
        log_once(self.files.given, text)

    def flush_alike(self) -> None:
        """Turn the notes kept in :attr:`alike` into one note per kind (at the end of a reading)."""
        for line in self.alike.lines():
            self.note(line)
        self.alike.clear()

    def problem(self, element: Any, message: str, fix: str, label: str | None = None) -> None:
        """Record a problem at ``element`` of the file ``label`` (the SSD when None)."""
        where = element_path(element) if element is not None else "/"
        self.problems.append(Problem(label or self.label, where, message, fix))

    def bad_number(self, exc: AnnotationNumberError) -> None:
        """A problem for an annotation attribute that is no positive number (once, though read twice)."""
        message = f"{display_name(exc.element)} {exc}"
        if any(p.message == message and p.path == element_path(exc.element) for p in self.problems):
            return  # read twice (a system's solvers and the experiment's step)
        self.problem(exc.element, message, f"write {exc.attribute} as a positive number, e.g. {exc.attribute}=\"0.01\"")

    def parse(self, path: Path, label: str, kind: str) -> Any:
        """The root of an SSP file checked against the schema, or None (its problems recorded).

        A file in a form popular tools write against the schema (see :mod:`.tolerant`) is read as corrected,
        with a note per correction; when the correction does not satisfy the schema either, the original's
        problems are reported, so that they point at the user's own file.
        """
        root, problems = parse_file(path, label, kind)
        if root is not None and problems and (fixed := self._tolerated(root, label, kind)) is not None:
            return fixed
        self.problems.extend(problems)
        return None if problems else root

    def checked_inline(self, root: Any, label: str, kind: str) -> Any:
        """An inline ssv:ParameterSet or ssm:ParameterMapping checked against its schema (tolerated forms
        corrected, as :meth:`parse`), or None with its problems recorded."""
        problems = schema_problems(root, label, kind)
        if not problems:
            return root
        if (fixed := self._tolerated(root, label, kind)) is not None:
            return fixed
        self.problems.extend(problems)
        return None

    def _tolerated(self, root: Any, label: str, kind: str) -> Any:
        """``root`` corrected to the standard's forms (:mod:`.tolerant`), its notes recorded, when a correction
        was made and satisfies the schema; else None (nothing recorded)."""
        fixed, notes = tolerated(root, label)
        if not notes or schema_problems(fixed, label, kind):
            return None
        for note in notes:
            self.alike.add(*note)
        return fixed

    def resolve(self, uri: str, base: Path) -> Path | None:
        """A file a component or binding refers to: inside the SSP first, then next to the archive; a
        ``file:`` URI where it names.  A file read from outside the SSP gets a note saying where from.

        Call :meth:`leaves_ssp` first: a relative path that leaves the SSP is refused there.
        """
        parsed = urllib.parse.urlparse(uri)
        if parsed.scheme == "file":
            if parsed.netloc not in ("", "localhost"):
                return None  # another host's file: no network
            candidate = Path(urllib.parse.unquote(parsed.path))
            return self._outside(uri, candidate, "a file: URI") if candidate.is_file() else None
        if parsed.scheme:
            return None  # no network: http(s) sources are not fetched
        relative = urllib.parse.unquote(parsed.path)
        candidate = base / relative
        if self.files.inside(candidate) and candidate.is_file():
            return candidate
        if self.files.beside is not None:
            folder = self.files.beside.resolve()
            for beside in (self.files.beside / relative, self.files.beside / Path(relative).name):
                if folder in beside.resolve().parents and beside.is_file():
                    return self._outside(uri, beside, "not in the archive: next to it")
        return None

    def _outside(self, uri: str, path: Path, how: str) -> Path:
        """``path``, noted once: ''uri' is read from outside the SSP: /abs/path (how)'."""
        text = f"'{uri}' is read from outside the SSP: {path.resolve()} ({how})"
        if text not in self.notes:
            self.note(text)
        return path

    def leaves_ssp(self, uri: str, base: Path, element: Any) -> bool:
        """Whether the relative path ``uri`` leads out of the SSP (``../``, an absolute path, a link out of an
        SSP folder), with a problem at ``element`` if so: an SSP's files are read from inside it (a missing one
        also from next to the archive, with a note); a file elsewhere must be named by a ``file:`` URI."""
        parsed = urllib.parse.urlparse(uri)
        if parsed.scheme:
            return False
        if self.files.inside(base / urllib.parse.unquote(parsed.path)):
            return False
        self.problem(element, f"'{uri}' leads outside the SSP: cosim reads an SSP's files from inside it",
                     "put the file under resources/ of the SSP and refer to it as resources/NAME (a file that must "
                     "stay elsewhere: name it by a file: URI, file:///abs/path)")
        return True
