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

import json
import os
import re
import tempfile
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

STATUSES = ("ok", "failed", "timeout", "crashed")
TAIL_COLUMNS = ("status", "message", "run_time", "worker")
_PART = re.compile(r"^part-(\d+)\.parquet$")


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

    # -- writing --------------------------------------------------------------
    def append(self, rows: Sequence[Mapping[str, Any]]) -> None:
        """Write ``rows`` as a new part file, durably (temporary file, fsync, rename)."""
        if not rows:
            return
        table = pa.Table.from_pandas(pd.DataFrame(list(rows)), preserve_index=False)
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

    def has_rows(self) -> bool:
        return self.table_path.exists() or bool(self._part_files())

    def done_ids(self) -> set[str]:
        """Ids of every point that already has a row (any status): what ``--resume`` skips."""
        ids: set[str] = set()
        for path in ([self.table_path] if self.table_path.exists() else []) + self._part_files():
            ids.update(pq.read_table(path, columns=["point_id"]).column("point_id").to_pylist())
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

    def compact(self, order: Iterable[str] | None = None, csv: bool = False) -> pd.DataFrame:
        """Merge parts into ``results.parquet`` (rows in ``order`` of point ids when given) and return it.

        The parts are removed only after the new table is in place, so an
        interruption here loses nothing.
        """
        df = self.read()
        if order is not None and len(df):
            rank = {pid: i for i, pid in enumerate(order)}
            df = df.iloc[df["point_id"].map(rank).fillna(len(rank)).argsort(kind="stable")].reset_index(drop=True)
        tmp = self.table_path.with_suffix(".parquet.tmp")
        df.to_parquet(tmp, index=False)
        os.replace(tmp, self.table_path)
        for part in self._part_files():
            part.unlink()
        if csv:
            df.to_csv(self.folder / "results.csv", index=False)
        return df


def counts_by_status(df: pd.DataFrame) -> dict[str, int]:
    """Number of rows per status (every status listed, zeros included)."""
    counts = {s: 0 for s in STATUSES}
    if len(df):
        for status, n in df["status"].value_counts().items():
            counts[str(status)] = int(n)
    return counts


def _order_columns(df: pd.DataFrame) -> pd.DataFrame:
    tail = [c for c in TAIL_COLUMNS if c in df.columns]
    middle = [c for c in df.columns if c != "point_id" and c not in tail]
    return df[["point_id", *middle, *tail]]
