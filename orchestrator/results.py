"""The results of a sweep on disk: one row per design point, written as they come.

Layout of a results folder ``DIR``:

- ``DIR/parts/part-NNNNNNNN.parquet``: rows appended during a sweep, one file
  per completed batch.  Each file is written under a temporary name and then
  renamed, so a kill -9 of the client leaves either a whole part or none: at
  most the points in flight are lost.
- ``DIR/results.parquet``: the compacted table (:meth:`ResultsStore.compact`,
  called at the end of a sweep): every point exactly once (a later row of the
  same point id replaces an earlier one).
- ``DIR/results.csv``: the same table as CSV, on request.
- ``DIR/metadata.json``: the spec and its digest, FMU checksums, package
  versions, host, start and end, counts by status.

Columns: ``point_id``, one per parameter (arrays as ``target[i]``), one per
objective (flat, e.g. ``e_el[3]``), ``status`` (ok, failed, timeout, crashed),
``message``, ``run_time`` (s) and ``worker``.
"""

from __future__ import annotations

import itertools
import json
import os
import re
import tempfile
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq

from .table_columns import STATUSES, TAIL_COLUMNS  # noqa: F401  (defined once, for writers and readers)

_PART = re.compile(r"^part-(\d+)\.parquet$")
COMPACT_WINDOW = 10_000  # rows held at once while merging parts into the final table
# Every MERGE_PARTS appended batches, the part files are merged into one: thousands of tiny files cost
# the final merge more memory (per-file reader state) than their rows do.
MERGE_PARTS = 128


def default_folder(spec_path: str | Path) -> Path:
    """Where ``cosim sweep`` writes without ``--out``: ``results/<spec name>`` (the file's stem without a name)."""
    try:
        name = json.loads(Path(spec_path).read_text(encoding="utf-8")).get("name") or Path(spec_path).stem
    except (OSError, ValueError, AttributeError, RecursionError):  # a broken spec: validation reports it next
        name = Path(spec_path).stem
    return Path("results") / re.sub(r"[^A-Za-z0-9_.-]+", "_", str(name))


class ResultsStore:
    """Rows of one sweep in folder ``folder`` (created when missing)."""

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)
        self.parts = self.folder / "parts"
        self.table_path = self.folder / "results.parquet"
        self.metadata_path = self.folder / "metadata.json"
        self.folder.mkdir(parents=True, exist_ok=True)
        self.parts.mkdir(exist_ok=True)
        self._next = max((int(m.group(1)) for m in map(_PART.match, os.listdir(self.parts)) if m), default=-1) + 1
        self._parts_written = 0

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

    def _write_part(self, table: pa.Table) -> None:
        """Write ``table`` as the next part file: temporary file, fsync, rename (whole or absent after a kill)."""
        final = self.parts / f"part-{self._next:08d}.parquet"
        self._next += 1
        fd, tmp = tempfile.mkstemp(dir=self.parts, suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as f:
                pq.write_table(table, f)
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

        The merged file gets the next number and is in place before the small
        parts are removed: a kill in between leaves rows twice, which the
        final merge resolves (latest row wins; they are the same rows).
        """
        parts = self._part_files()[-MERGE_PARTS:]
        if len(parts) < 2:
            return
        schema = _unified_schema(parts)
        table = pa.concat_tables([_conform(_read(p), schema) for p in parts])
        self._write_part(table)
        for part in parts:
            part.unlink()

    def write_metadata(self, metadata: Mapping[str, Any]) -> None:
        """Replace ``metadata.json`` atomically."""
        tmp = self.metadata_path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(metadata, indent=2, default=str))
        os.replace(tmp, self.metadata_path)

    # -- reading --------------------------------------------------------------
    def metadata(self) -> dict[str, Any] | None:
        """The stored metadata, or None when there is none yet."""
        try:
            return json.loads(self.metadata_path.read_text())
        except (FileNotFoundError, json.JSONDecodeError):
            return None

    def _part_files(self) -> list[Path]:
        return sorted(p for p in self.parts.iterdir() if _PART.match(p.name))

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
        df = df.drop_duplicates("point_id", keep="last")
        return _order_columns(df).reset_index(drop=True)

    def compact(self, order: Iterable[str] | None = None, csv: bool = False) -> dict[str, int]:
        """Merge parts into ``results.parquet`` (rows in ``order`` of point ids when given); returns counts by status.

        Each point appears once, its latest row winning.  The merge streams:
        it holds the point ids and at most ``COMPACT_WINDOW`` rows at a time,
        never the whole table, so a sweep's client memory does not grow with
        its size.  Rows whose ids are not in ``order`` follow, in the order
        they were written.  The parts are removed only after the new table is
        in place, so an interruption here loses nothing.
        """
        sources = ([self.table_path] if self.table_path.exists() else []) + self._part_files()
        counts = {s: 0 for s in STATUSES}
        where, position = _latest_rows_in_order(sources, order)
        schema = _unified_schema(sources)
        tmp = self.table_path.with_suffix(".parquet.tmp")
        csv_tmp = self.folder / "results.csv.tmp"
        csv_writer = None
        with pq.ParquetWriter(tmp, schema) as writer:
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
                if not pieces:
                    continue
                window = pa.concat_tables(pieces).sort_by("__position").drop_columns(["__position"])
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
        for part in self._part_files():
            part.unlink()
        return counts

    def table(self, columns: Sequence[str] | None = None) -> pd.DataFrame:
        """The compacted table (``results.parquet``) as a DataFrame, optionally only some columns."""
        return pd.read_parquet(self.table_path, columns=list(columns) if columns else None)


def _read(path: Path, columns: Sequence[str] | None = None) -> pa.Table:
    """One part file.  ``ParquetFile.read`` rather than ``pq.read_table``: the latter sets up the
    dataset machinery per call, and over thousands of small parts that costs tens of MB."""
    return pq.ParquetFile(path).read(columns=list(columns) if columns else None)


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


def _unified_schema(sources: Sequence[Path]) -> pa.Schema:
    """One schema for all parts (a failed batch lacks objective columns; an all-null column has no type)."""
    if not sources:
        return pa.schema([("point_id", pa.string()), ("status", pa.string()), ("message", pa.string()),
                          ("run_time", pa.float64()), ("worker", pa.string())])
    schema = pa.unify_schemas([pq.ParquetFile(p).schema_arrow.remove_metadata() for p in sources],
                              promote_options="permissive")
    names = schema.names
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
