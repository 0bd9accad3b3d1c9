"""A results folder watched while its study runs: the decision room's view of a running sweep or optimisation.

A running study writes its rows to ``parts/part-*.parquet`` in its folder (and, when it ends, compacts them
into ``results.parquet``); :func:`cosim.analysis.table.load_results` reads both.  :class:`LiveStudy` keeps the
folder's current :class:`cosim.analysis.room.data.Study` for every browser tab of one server: it looks at the
files' names, sizes and times at most every ``every`` seconds and reads the table again when they changed.
Each tab asks from a periodic callback and, given a new Study, redraws with its filters, objectives, weights
and selection kept (:meth:`cosim.analysis.room.app.Room.reload`).
"""

from __future__ import annotations

import time
from pathlib import Path

from cosim.analysis.room.data import Study
from cosim.analysis.table import AnalysisError, load_results

EVERY = 1.0  # seconds between two looks at the folder


class LiveStudy:
    """The current Study of ``folder`` (module docstring); ``current()`` is None while it has no row yet."""

    def __init__(self, folder: str | Path, spec_path: str | None = None, every: float = EVERY):
        self.folder, self.spec_path, self.every = Path(folder), spec_path, every
        self._signature: tuple = ()
        self._looked = 0.0
        self._study: Study | None = None
        self.version = 0  # +1 for each new table read
        # why the folder's table could not be read at the last look (garbled, deleted), None when it could: the
        # room showed such a folder's last rows as a "complete" study
        self.problem: str | None = None
        self.current()

    def signature(self) -> tuple:
        """What changes when rows are written: the table files' names, sizes and modification times."""
        files = [self.folder / "results.parquet", self.folder / "metadata.json",
                 *sorted((self.folder / "parts").glob("part-*.parquet"))]
        out = []
        for f in files:
            try:
                st = f.stat()
            except OSError:  # not there (yet), or removed by a compaction between listing and stat
                continue
            out.append((f.name, st.st_size, st.st_mtime_ns))
        return tuple(out)

    def current(self) -> Study | None:
        """The folder's Study, read again when its files changed since the last look (at most every ``every``
        seconds); None while the folder has no row.  A table caught half-written keeps the last Study."""
        now = time.monotonic()
        if now - self._looked < self.every and self._study is not None:
            return self._study
        self._looked = now
        signature = self.signature()
        if signature == self._signature:
            return self._study
        try:
            table = load_results(self.folder, self.spec_path)
        except AnalysisError as exc:  # no rows yet, or a part being written: the next look reads it
            self.problem = _first_line(exc) if signature else "the table is gone: deleted or moved"
            return self._study
        except Exception as exc:  # noqa: BLE001 - a garbled file: pyarrow's and pandas' errors, one line kept
            self.problem = f"{type(exc).__name__}: {_first_line(exc)}"
            return self._study
        self.problem = None
        if not len(table.df):
            return self._study
        self._signature = signature
        self._study = Study(table, spec_path=self.spec_path)
        self.version += 1
        return self._study

    @property
    def name(self) -> str:
        """The study's name (its spec's), the folder's name before the first rows."""
        return self._study.name if self._study is not None else self.folder.name

    @property
    def running(self) -> bool:
        """Whether the folder holds rows not yet compacted (a study running, or interrupted)."""
        return any((self.folder / "parts").glob("part-*.parquet"))


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return (text.splitlines()[0] if text else type(exc).__name__)[:300]
