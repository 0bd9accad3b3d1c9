"""The results of a sweep on disk: one row per design point, written as they come.

Layout of a results folder ``DIR``:

- ``DIR/parts/part-NNNNNNNN.parquet``: rows appended during a sweep, one file
  per completed batch.  Each file is written under a temporary name and then
  renamed, so a kill -9 of the client leaves either a whole part or none: at
  most the points in flight are lost.  The folder is made with the first part
  and removed by the final merge (:meth:`ResultsStore.compact`): a finished
  study has none, a stopped or running one has its rows there.
- ``DIR/results.parquet``: the compacted table (:meth:`ResultsStore.compact`,
  called at the end of a sweep): every point exactly once (a later row of the
  same point id replaces an earlier one).
- Rows a sweep writes carry their place in the design order in a column
  ``__design_index`` that only the part files have: the final merge puts them
  in order by it, streaming, without holding every point id.
- ``DIR/results.csv``: the same table as CSV, on request.
- ``DIR/damaged/``: files of rows that could not be read (truncated by a
  crash or a full disk), set aside by :meth:`ResultsStore.set_aside_damaged`
  so that a resume computes their points again instead of failing for good.
- ``DIR/metadata.json``: the spec and its digest, FMU checksums, package
  versions, host, start and end, counts by status; replaced atomically
  (temporary file, fsync, rename).
- Every part file and ``results.parquet`` also carry the study's *identity*
  (spec digest, kind of study, checksums of the unit and data files) in their
  Parquet metadata (:data:`IDENTITY_KEY`), so a resume can tell which model made
  the rows even when ``metadata.json`` is lost or damaged.

Columns: ``point_id``, one per parameter (arrays as ``target[i]``), one per
objective (flat, e.g. ``e_el[3]``), ``status`` (ok, failed, timeout, crashed),
``message``, ``run_time`` (s) and ``worker``.
"""

from __future__ import annotations

import importlib
import itertools
import json
import os
import re
import tempfile
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping, Sequence

import numpy as np

from cosim.results.columns import STATUSES, TAIL_COLUMNS


class _ImportedAtFirstUse:
    """A module imported when one of its attributes is first used.

    pandas and pyarrow take about 0.2 s to import, a tenth of the README's
    main job.  A sweep makes its ResultsStore before its cluster runs but
    writes the first rows only once they come back, so these imports happen
    while the first points run instead of before.
    """

    def __init__(self, name: str):
        self._name = name

    def __getattr__(self, attribute: str) -> Any:
        return getattr(importlib.import_module(self._name), attribute)


pd: Any = _ImportedAtFirstUse("pandas")
pa: Any = _ImportedAtFirstUse("pyarrow")
pa_csv: Any = _ImportedAtFirstUse("pyarrow.csv")
pq: Any = _ImportedAtFirstUse("pyarrow.parquet")


_PART = re.compile(r"^part-(\d+)\.parquet$")
_WRITING = re.compile(r"^tmp\w+\.tmp$")  # a part being written (tempfile.mkstemp's name in parts/), renamed when whole
COMPACT_WINDOW = 10_000  # rows held at once while merging parts into the final table
# The point's place in the design order, written by the sweep into part files only (never into results.parquet)
DESIGN_INDEX = "__design_index"
_SOURCE = "__source"  # which source file a row came from, while merging (a later source wins)
# Every MERGE_PARTS appended batches, the newest part files are merged into one: the final merge holds a
# buffer of rows per file, so the number of files must stay small.
MERGE_PARTS = 64
ROW_GROUP = 1024  # rows per row group of a merged part: what a streaming merge holds of each file
IDENTITY_KEY = b"cosim.identity"  # Parquet metadata key of the study's identity in every file of rows


class ResultsStore:
    """Rows of one sweep in folder ``folder`` (created when missing)."""

    INDEX_COLUMN = DESIGN_INDEX  # rows that carry it are put in design order by it (see ``compact``)

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)
        self.parts = self.folder / "parts"
        self.table_path = self.folder / "results.parquet"
        self.metadata_path = self.folder / "metadata.json"
        self.folder.mkdir(parents=True, exist_ok=True)
        matches = (_PART.match(p.name) for p in self._part_files())  # every one matches: _part_files picks them
        self._next = max((int(m.group(1)) for m in matches if m), default=-1) + 1
        self._parts_written = 0
        # what made the rows (spec digest, kind, unit and data-file checksums): written into every file of rows
        # by the driver that sets it, read back by row_identities()
        self.identity: Mapping[str, Any] | None = None

    def _stamped(self, schema: pa.Schema) -> pa.Schema:
        """``schema`` with the study's identity added to its metadata (unchanged when no identity is set)."""
        if not self.identity:
            return schema
        return schema.with_metadata({**(schema.metadata or {}),
                                     IDENTITY_KEY: json.dumps(self.identity, sort_keys=True).encode()})

    # -- writing --------------------------------------------------------------
    def append(self, rows: Sequence[Mapping[str, Any]]) -> None:
        """Write ``rows`` as a new part file, durably (temporary file, fsync, rename)."""
        if not rows:
            return
        table = pa.Table.from_pandas(pd.DataFrame(list(rows)), preserve_index=False)
        self._write_part(table)
        self._parts_written += 1
        if self._parts_written % MERGE_PARTS == 0:
            self._merge_parts()

    def _write_part(self, table: pa.Table | Iterable[pa.Table], schema: pa.Schema | None = None) -> None:
        """Write ``table`` (or the tables of ``schema`` one after the other) as the next part file:
        temporary file, fsync, rename (whole or absent after a kill)."""
        final = self.parts / f"part-{self._next:08d}.parquet"
        self._next += 1
        self.parts.mkdir(exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=self.parts, suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as f:
                if isinstance(table, pa.Table):
                    pq.write_table(table.replace_schema_metadata(self._stamped(table.schema).metadata), f)
                else:
                    with pq.ParquetWriter(f, self._stamped(schema)) as writer:
                        for piece in table:
                            writer.write_table(piece, row_group_size=ROW_GROUP)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, final)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise

    def _merge_parts(self) -> None:
        """Merge the last MERGE_PARTS part files into one (keeps the final merge cheap for huge sweeps).

        Only the newest, small parts are merged, so a merge never reads more
        than MERGE_PARTS batches, however long the sweep.

        Parts with the design index are merged streaming, into one part in
        index order (so the final merge can stream too); others are
        concatenated in write order.

        The merged file gets the next number and is in place before the small
        parts are removed: a kill in between leaves rows twice, which the
        final merge resolves (latest row wins; they are the same rows).
        """
        parts = self._part_files()[-MERGE_PARTS:]
        if len(parts) < 2:
            return
        if all(_sorted_by_index(p) for p in parts):
            schema = _unified_schema(parts, keep_index=True)
            self._write_part(_windows_by_index(parts, schema), schema)
        else:
            schema = _unified_schema(parts)
            self._write_part(pa.concat_tables([_conform(_read(p), schema) for p in parts]))
        for part in parts:
            part.unlink()
        # Arrow's allocator keeps the merge's buffers (~50 MB for 64 parts of 2048 rows) for reuse; handed
        # back, the sweep's client returns to its size between merges instead of keeping their high-water mark
        pa.default_memory_pool().release_unused()

    def write_metadata(self, metadata: Mapping[str, Any]) -> None:
        """Replace ``metadata.json`` atomically and durably: temporary file, fsync, rename, fsync of the folder.

        A crash or a full disk leaves the old file or the new one, never an empty one.
        """
        tmp = self.metadata_path.with_suffix(".json.tmp")
        try:
            with open(tmp, "w", encoding="utf-8") as f:
                f.write(json.dumps(metadata, indent=2, default=str))
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, self.metadata_path)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
        _fsync_folder(self.folder)

    # -- reading --------------------------------------------------------------
    def metadata(self) -> dict[str, Any] | None:
        """The stored metadata, or None when there is none (or it cannot be read: see :meth:`metadata_state`)."""
        return self.metadata_state()[0]

    def metadata_state(self) -> tuple[dict[str, Any] | None, str | None]:
        """(the stored metadata, None) or (None, why it cannot be used: "missing", "empty", ...)."""
        try:
            text = self.metadata_path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return None, "missing"
        except (OSError, UnicodeDecodeError) as exc:
            return None, f"unreadable ({getattr(exc, 'strerror', None) or exc})"
        if not text.strip():
            return None, "empty"
        try:
            data = json.loads(text)
        except ValueError:
            return None, "not valid JSON (damaged)"
        if not isinstance(data, dict):
            return None, "not a JSON object (damaged)"
        return data, None

    def row_identities(self) -> dict[str, list[Path]]:
        """The identities the files of rows carry (see :data:`IDENTITY_KEY`), as JSON text -> files.

        Files written without one (by an older cosim, or by a driver that sets none) are listed under "".
        """
        found: dict[str, list[Path]] = {}
        for path in ([self.table_path] if self.table_path.exists() else []) + self._part_files():
            metadata = pq.ParquetFile(path).schema_arrow.metadata or {}
            found.setdefault(metadata.get(IDENTITY_KEY, b"").decode(), []).append(path)
        return found

    def damaged_files(self) -> list[tuple[Path, str]]:
        """Files of rows (``results.parquet``, parts) that cannot be read, each with the reader's reason.

        A file counts as readable when its footer and its ``point_id`` column
        read without error (a truncated file has no footer).
        """
        damaged = []
        for path in ([self.table_path] if self.table_path.exists() else []) + self._part_files():
            try:
                _read(path, ["point_id"])
            except (pa.ArrowException, OSError, ValueError, KeyError) as exc:
                damaged.append((path, str(exc).splitlines()[0][:200] if str(exc) else type(exc).__name__))
        return damaged

    def set_aside_damaged(self) -> list[str]:
        """Move every file of rows that cannot be read into ``DIR/damaged/``; returns one line per file moved.

        Their points then have no row, so a resume computes them again; the
        files are kept (not deleted) for whoever wants to look at them.
        """
        lines = []
        for path, reason in self.damaged_files():
            aside = self.folder / "damaged"
            aside.mkdir(exist_ok=True)
            target = aside / path.name
            number = 1
            while target.exists():
                target = aside / f"{path.stem}.{number}{path.suffix}"
                number += 1
            os.replace(path, target)
            lines.append(f"{path.relative_to(self.folder).as_posix()} cannot be read ({reason}); set aside as "
                         f"{target.relative_to(self.folder).as_posix()}")
        return lines

    def _part_files(self) -> list[Path]:
        if not self.parts.is_dir():  # no row written yet, or merged into the table (see compact)
            return []
        return sorted(p for p in self.parts.iterdir() if _PART.match(p.name))

    def _remove_parts_folder(self) -> None:
        """Remove ``parts/`` once its rows are in the table: with its part files, the temporary files a
        killed write left there (whole parts are renamed from them, so they never hold a row of their own).
        Anything else in it (not cosim's) keeps the folder."""
        if not self.parts.is_dir():
            return
        for path in self.parts.iterdir():
            if _PART.match(path.name) or _WRITING.match(path.name):
                path.unlink(missing_ok=True)
        try:
            self.parts.rmdir()
        except OSError:  # not empty: someone else's file
            pass

    def discard_rows(self) -> None:
        """Remove every stored row (table, CSV, parts); the metadata stays."""
        for path in [self.table_path, self.folder / "results.csv", *self._part_files()]:
            path.unlink(missing_ok=True)

    def has_rows(self) -> bool:
        return self.table_path.exists() or bool(self._part_files())

    def done_ids(self) -> set[str]:
        """Ids of every point that already has a row (any status): what ``--resume`` skips."""
        ids: set[str] = set()
        for path in ([self.table_path] if self.table_path.exists() else []) + self._part_files():
            ids.update(_read(path, ["point_id"]).column("point_id").to_pylist())
        return ids

    def ids_with_status(self, status: str) -> set[str]:
        """Ids of the points whose latest row has ``status`` (e.g. the pruned ones a resume without pruning
        runs again)."""
        table = self.read()
        if not len(table) or "status" not in table.columns:
            return set()
        return set(table.loc[table["status"].astype(str) == status, "point_id"].astype(str))

    def read(self) -> pd.DataFrame:
        """All rows so far (compacted table and parts), each point once, the latest row winning."""
        frames = []
        if self.table_path.exists():
            frames.append(pd.read_parquet(self.table_path))
        frames.extend(pd.read_parquet(p) for p in self._part_files())
        frames = [f for f in frames if len(f)]
        if not frames:
            return pd.DataFrame(columns=["point_id", *TAIL_COLUMNS])
        df = pd.concat(frames, ignore_index=True) if len(frames) > 1 else frames[0]
        df = df.drop_duplicates("point_id", keep="last").drop(columns=[DESIGN_INDEX], errors="ignore")
        return _order_columns(df).reset_index(drop=True)

    def compact(self, order: Iterable[str] | None = None, csv: bool = False) -> dict[str, int]:
        """Merge parts into ``results.parquet``, rows in design order; returns counts by status.

        Each point appears once, its latest row winning.  The merge streams and
        holds at most about ``COMPACT_WINDOW`` rows at a time:

        - when every part carries the design index (as a sweep writes them),
          rows are placed by it and nothing else is held, so the client's
          memory does not grow with the number of points; ``order`` is not read;
        - otherwise (parts of an older cosim, a compacted table being resumed,
          rows of ``cosim optimize``) rows go in ``order`` of point ids when
          given, then rows whose ids are not in it, in the order they were
          written; this holds the point ids (about 100 bytes a point).

        The parts are removed only after the new table is in place, so an
        interruption here loses nothing; then the ``parts/`` folder goes too
        (a resume makes it again when it writes rows).
        """
        sources = ([self.table_path] if self.table_path.exists() else []) + self._part_files()
        schema = _unified_schema(sources)
        if sources and all(_sorted_by_index(p) for p in sources):
            windows = _windows_by_index(sources, schema)
        else:
            windows = _windows_by_id(sources, schema, order)
        counts = {s: 0 for s in STATUSES}
        tmp = self.table_path.with_suffix(".parquet.tmp")
        csv_tmp = self.folder / "results.csv.tmp"
        csv_writer = None
        with pq.ParquetWriter(tmp, self._stamped(schema)) as writer:
            for window in windows:
                writer.write_table(window)
                for status, n in zip(*np.unique(window.column("status").to_numpy(zero_copy_only=False),
                                                return_counts=True)):
                    counts[str(status)] = counts.get(str(status), 0) + int(n)
                if csv:
                    if csv_writer is None:
                        csv_writer = pa_csv.CSVWriter(csv_tmp, schema)
                    csv_writer.write_table(window)
        if csv and csv_writer is None:
            pa_csv.CSVWriter(csv_tmp, schema).close()
        elif csv_writer is not None:
            csv_writer.close()
        os.replace(tmp, self.table_path)
        if csv:
            os.replace(csv_tmp, self.folder / "results.csv")
        self._remove_parts_folder()
        return counts

    def table(self, columns: Sequence[str] | None = None) -> pd.DataFrame:
        """The compacted table (``results.parquet``) as a DataFrame, optionally only some columns."""
        return pd.read_parquet(self.table_path, columns=list(columns) if columns else None)


def _fsync_folder(folder: Path) -> None:
    """Make a rename in ``folder`` durable (where the system allows opening a folder)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _read(path: Path, columns: Sequence[str] | None = None) -> pa.Table:
    """One part file.  ``ParquetFile.read`` rather than ``pq.read_table``: the latter sets up the
    dataset machinery per call, and over thousands of small parts that costs tens of MB."""
    return pq.ParquetFile(path).read(columns=list(columns) if columns else None)


def _windows_by_id(sources: Sequence[Path], schema: pa.Schema,
                   order: Iterable[str] | None) -> Iterator[pa.Table]:
    """The final table in windows of at most COMPACT_WINDOW rows, placed by point id (see ``compact``)."""
    where, position = _latest_rows_in_order(sources, order)
    for low in range(0, len(position), COMPACT_WINDOW):
        chosen = np.flatnonzero((position >= low) & (position < low + COMPACT_WINDOW))
        if len(chosen) == 0:
            continue
        chosen = chosen[np.argsort(where[chosen, 0], kind="stable")]  # grouped by source file
        splits = np.flatnonzero(np.diff(where[chosen, 0])) + 1
        pieces = []
        for group in np.split(chosen, splits):
            path = sources[int(where[group[0], 0])]
            table = _conform(_read(path).take(pa.array(where[group, 1])), schema)
            pieces.append(table.append_column("__position", pa.array(position[group])))
            if len(pieces) >= 64:  # thousands of tiny tables cost more than their rows: merge early
                pieces = [pa.concat_tables(pieces).combine_chunks()]
        if pieces:
            yield pa.concat_tables(pieces).sort_by("__position").drop_columns(["__position"])


def _sorted_by_index(path: Path) -> bool:
    """Whether the file has a DESIGN_INDEX for every row, in increasing order (reads only that column)."""
    if DESIGN_INDEX not in pq.ParquetFile(path).schema_arrow.names:
        return False
    column = _read(path, [DESIGN_INDEX]).column(DESIGN_INDEX)
    if column.null_count:
        return False
    index = column.to_numpy()
    return bool(np.all(index[1:] >= index[:-1]))


class _IndexedSource:
    """One part file read in index order, ROW_GROUP rows at a time (parts are sorted by DESIGN_INDEX)."""

    def __init__(self, path: Path, number: int, schema: pa.Schema):
        self._batches = pq.ParquetFile(path).iter_batches(batch_size=ROW_GROUP)
        self.number, self.schema = number, schema
        self.buffer: pa.Table | None = None
        self._pull()

    def _pull(self) -> None:
        """Refill the buffer when it is empty; None when the file is exhausted."""
        while self.buffer is None or len(self.buffer) == 0:
            batch = next(self._batches, None)
            if batch is None:
                self.buffer = None
                return
            self.buffer = pa.Table.from_batches([batch])

    def head(self) -> int | None:
        """The smallest index not yet taken, None when exhausted."""
        return None if self.buffer is None else self.buffer.column(DESIGN_INDEX)[0].as_py()

    def take_below(self, high: int) -> list[pa.Table]:
        """Every row of this file with an index below ``high`` (not taken before), with the file's number."""
        pieces = []
        while self.buffer is not None:
            index = self.buffer.column(DESIGN_INDEX).to_numpy()
            cut = int(np.searchsorted(index, high))
            if cut:
                piece = _conform(self.buffer.slice(0, cut), self.schema)
                pieces.append(piece.append_column(_SOURCE, pa.array(np.full(cut, self.number, dtype=np.int64))))
            if cut < len(index):
                self.buffer = self.buffer.slice(cut)
                break
            self.buffer = None
            self._pull()
        return pieces


def _windows_by_index(sources: Sequence[Path], schema: pa.Schema) -> Iterator[pa.Table]:
    """The final table in windows of about COMPACT_WINDOW design indices, read in step from every source.

    Each source is sorted by DESIGN_INDEX, so a window takes a prefix of each;
    of rows with the same index the one from the later source wins.  Held at
    once: one window and about a row group per source.  The windows have
    ``schema``'s columns (with DESIGN_INDEX when it has it: merging parts).
    """
    indexed = schema if DESIGN_INDEX in schema.names else _unified_schema(sources, keep_index=True)
    readers = [_IndexedSource(path, number, indexed) for number, path in enumerate(sources)]
    while True:
        heads = [h for h in (r.head() for r in readers) if h is not None]
        if not heads:
            return
        high = min(heads) + COMPACT_WINDOW
        window = pa.concat_tables([piece for r in readers for piece in r.take_below(high)])
        index = window.column(DESIGN_INDEX).to_numpy()
        source = window.column(_SOURCE).to_numpy()
        by_index = np.lexsort((source, index))  # by index, then by source: the last of each index wins
        last = np.append(index[by_index][1:] != index[by_index][:-1], True)
        yield _conform(window.take(pa.array(by_index[last])), schema)


def _latest_rows_in_order(sources: Sequence[Path], order: Iterable[str] | None) -> tuple[np.ndarray, np.ndarray]:
    """Which rows to keep and where they go.

    Returns ``where`` (one (source index, row index) pair per kept row: the
    latest row of each point id) and ``position`` (each kept row's place in the
    final table: design ``order`` first, ids not in it after, in write order).
    The bookkeeping is in flat numpy arrays (about 100 bytes a point); Arrow's
    hash group-by and join cost several times more for this job.
    """
    if not sources:
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0, dtype=np.int64)
    id_parts = [np.array(_read(path, ["point_id"]).column("point_id").to_pylist(), dtype=str) for path in sources]
    lengths = np.array([len(a) for a in id_parts], dtype=np.int64)
    ids = np.concatenate(id_parts)
    del id_parts
    source_of = np.repeat(np.arange(len(sources), dtype=np.int64), lengths)
    row_of = np.arange(len(ids), dtype=np.int64) - np.repeat(np.cumsum(lengths) - lengths, lengths)
    _, first_from_end = np.unique(ids[::-1], return_index=True)
    seq = np.sort(len(ids) - 1 - first_from_end)  # the latest row of each id, in write order
    kept = ids[seq]
    del ids
    key = seq.copy()
    if order is not None:
        order_ids = _order_array(order)
        if len(order_ids):
            sorter = np.argsort(order_ids, kind="stable")
            found_at = np.clip(np.searchsorted(order_ids, kept, sorter=sorter), 0, len(order_ids) - 1)
            rank = sorter[found_at]
            known = order_ids[rank] == kept
            key = np.where(known, rank, len(order_ids) + seq)
    position = np.empty(len(key), dtype=np.int64)
    position[np.argsort(key, kind="stable")] = np.arange(len(key))
    where = np.stack([source_of[seq], row_of[seq]], axis=1)
    return where, position


def _order_array(order: Iterable[str], chunk: int = 10_000) -> np.ndarray:
    """The design order's ids as a numpy string array, built in chunks (never one big Python list)."""
    arrays, it = [], iter(order)
    while ids := list(itertools.islice(it, chunk)):
        arrays.append(np.array(ids, dtype=str))
    return np.concatenate(arrays) if arrays else np.array([], dtype=str)


def _unified_schema(sources: Sequence[Path], keep_index: bool = False) -> pa.Schema:
    """One schema for all parts (a failed batch lacks objective columns; an all-null column has no type).

    Without ``keep_index``, the schema of the final table: no DESIGN_INDEX.
    """
    if not sources:
        return pa.schema([("point_id", pa.string()), ("status", pa.string()), ("message", pa.string()),
                          ("run_time", pa.float64()), ("worker", pa.string())])
    schema = pa.unify_schemas([pq.ParquetFile(p).schema_arrow.remove_metadata() for p in sources],
                              promote_options="permissive")
    names = [n for n in schema.names if keep_index or n != DESIGN_INDEX]
    tail = [c for c in TAIL_COLUMNS if c in names]
    middle = [c for c in names if c != "point_id" and c not in tail]
    fields = [schema.field(n) for n in ["point_id", *middle, *tail] if n in names]
    return pa.schema([f.with_type(pa.float64()) if pa.types.is_null(f.type) else f for f in fields])


def _conform(table: pa.Table, schema: pa.Schema) -> pa.Table:
    """``table`` with exactly ``schema``'s columns and types (missing ones as nulls)."""
    columns = [table.column(f.name).cast(f.type) if f.name in table.column_names else pa.nulls(len(table), f.type)
               for f in schema]
    return pa.Table.from_arrays(columns, schema=schema)


def _order_columns(df: pd.DataFrame) -> pd.DataFrame:
    tail = [c for c in TAIL_COLUMNS if c in df.columns]
    middle = [c for c in df.columns if c != "point_id" and c not in tail]
    return df[["point_id", *middle, *tail]]
