"""ResultsStore: durable part files, compaction, resume ids, metadata."""

from __future__ import annotations

import math

import pandas as pd

from cosim.results.columns import STATUSES
from cosim.results.store import DESIGN_INDEX, ResultsStore


def counts_by_status(df: pd.DataFrame) -> dict[str, int]:
    """Rows per status, every status listed (zeros included), counted from the table itself."""
    counts = {s: 0 for s in STATUSES}
    for status in df["status"]:
        counts[str(status)] += 1
    return counts


def rows(ids, status="ok", **extra):
    return [{"point_id": i, "p.x": n, **extra, "status": status, "message": "", "run_time": 0.1, "worker": "w"}
            for n, i in enumerate(ids)]


def test_append_then_read_and_compact_in_order(tmp_path):
    store = ResultsStore(tmp_path / "out")
    store.append(rows(["c", "d"], y=1.0))
    store.append(rows(["a"], status="failed"))  # a failed batch has no objective column
    assert store.done_ids() == {"a", "c", "d"}
    counts = store.compact(order=["a", "b", "c", "d"], csv=True)
    df = store.table()
    assert list(df["point_id"]) == ["a", "c", "d"]
    assert list(df.columns) == ["point_id", "p.x", "y", "status", "message", "run_time", "worker"]
    assert math.isnan(df.loc[0, "y"]) and df.loc[1, "y"] == 1.0
    assert not (tmp_path / "out" / "parts").exists()  # the rows are in the table: no part, no parts folder
    assert pd.read_csv(tmp_path / "out" / "results.csv")["point_id"].tolist() == ["a", "c", "d"]
    assert counts_by_status(df) == counts == {"ok": 2, "failed": 1, "timeout": 0, "crashed": 0}


def test_reopened_store_continues_numbering_and_latest_row_wins(tmp_path):
    ResultsStore(tmp_path).append(rows(["a", "b"], y=1.0))
    store = ResultsStore(tmp_path)  # as after a client restart
    store.append(rows(["b"], y=2.0))
    assert len(list((tmp_path / "parts").glob("part-*.parquet"))) == 2
    df = store.read()
    assert sorted(df["point_id"]) == ["a", "b"] and df.set_index("point_id").loc["b", "y"] == 2.0
    store.compact()
    store.append(rows(["e"], y=3.0))
    assert store.done_ids() == {"a", "b", "e"} and len(store.read()) == 3


def test_partial_temporary_file_is_ignored(tmp_path):
    store = ResultsStore(tmp_path)
    store.append(rows(["a"]))
    (tmp_path / "parts" / "tmpabc.tmp").write_bytes(b"half a parquet file")  # a write cut by kill -9
    assert store.done_ids() == {"a"} and len(store.read()) == 1


def test_metadata_round_trip(tmp_path):
    store = ResultsStore(tmp_path)
    assert store.metadata() is None and not store.has_rows()
    store.write_metadata({"spec_digest": "abc", "counts": {"ok": 1}})
    assert store.metadata() == {"spec_digest": "abc", "counts": {"ok": 1}}


def test_compaction_streams_in_windows_and_keeps_design_order(tmp_path, monkeypatch):
    import cosim.results.store as results

    monkeypatch.setattr(results, "COMPACT_WINDOW", 3)  # force several windows over 8 rows
    store = ResultsStore(tmp_path)
    order = [f"p{i}" for i in range(8)]
    store.append(rows(["p5", "p1", "p7"], y=1.0))
    store.append(rows(["p0", "p3"], status="failed"))
    store.append(rows(["p2", "p6", "p4", "p1"], y=2.0))  # p1 again: this row wins
    store.append(rows(["zz"], y=9.0))                     # not in the design order: last
    counts = store.compact(order=order)
    df = store.table()
    assert list(df["point_id"]) == order + ["zz"]
    assert df.set_index("point_id").loc["p1", "y"] == 2.0 and math.isnan(df.set_index("point_id").loc["p3", "y"])
    assert counts == {"ok": 7, "failed": 2, "timeout": 0, "crashed": 0}


def test_parts_are_merged_as_they_accumulate_without_losing_rows(tmp_path, monkeypatch):
    import cosim.results.store as results

    monkeypatch.setattr(results, "MERGE_PARTS", 3)
    store = ResultsStore(tmp_path)
    for b in range(7):
        store.append(rows([f"p{b}-{i}" for i in range(4)], y=float(b)))
    store.append(rows(["p0-0"], y=99.0))  # a later row of an early point still wins
    # merges after batches 3 and 6 (each of the 3 newest parts), then 2 new parts
    assert len(list((tmp_path / "parts").glob("part-*.parquet"))) == 4
    assert len(store.done_ids()) == 28
    store.compact()
    df = store.table().set_index("point_id")
    assert len(df) == 28 and df.loc["p0-0", "y"] == 99.0 and df.loc["p6-3", "y"] == 6.0


def indexed(ids_and_indices, status="ok", **extra):
    """Rows as a sweep writes them: each with its place in the design order."""
    return [{"point_id": pid, DESIGN_INDEX: i, "p.x": i, **extra, "status": status, "message": "", "run_time": 0.1,
             "worker": "w"} for pid, i in ids_and_indices]


def test_rows_with_the_design_index_are_merged_by_it_in_windows_latest_row_winning(tmp_path, monkeypatch):
    import cosim.results.store as results

    monkeypatch.setattr(results, "COMPACT_WINDOW", 3)  # several windows over 10 points
    monkeypatch.setattr(results, "MERGE_PARTS", 3)  # and parts merged (streaming) on the way
    monkeypatch.setattr(results, "ROW_GROUP", 2)
    store = ResultsStore(tmp_path)
    design = [f"id{i}" for i in range(10)]
    batches = [[7, 8, 9], [0, 1], [4, 5, 6], [2, 3]]  # batches complete out of order
    for b in batches[:2]:
        store.append(indexed([(design[i], i) for i in b], y=float(b[0])))
    store.append(indexed([(design[i], i) for i in batches[2]], status="failed"))  # no objective column
    store.append(indexed([(design[i], i) for i in batches[3]], y=2.0))
    store.append(indexed([(design[1], 1)], y=99.0))  # a later row of point 1 wins
    assert len(list((tmp_path / "parts").glob("part-*.parquet"))) == 3  # 3 merged into 1, then 2 new
    assert DESIGN_INDEX not in store.read().columns
    counts = store.compact(order=iter(()))  # the order of ids is not needed (and not read) with the index
    df = store.table()
    assert list(df["point_id"]) == design
    assert list(df.columns) == ["point_id", "p.x", "y", "status", "message", "run_time", "worker"]
    y = df.set_index("point_id")["y"]
    assert y["id1"] == 99.0 and y["id0"] == 0.0 and y["id9"] == 7.0 and y["id3"] == 2.0
    assert all(math.isnan(y[f"id{i}"]) for i in (4, 5, 6))
    assert counts == {"ok": 7, "failed": 3, "timeout": 0, "crashed": 0}
    assert not (tmp_path / "parts").exists()


def test_the_parts_folder_exists_only_while_rows_wait_for_the_final_merge(tmp_path):
    out = tmp_path / "out"
    ResultsStore(out)
    assert out.is_dir() and not (out / "parts").exists()  # a study stopped before its first row leaves none
    store = ResultsStore(out)
    store.append(rows(["a", "b"], y=1.0))
    store.append(rows(["c"], y=2.0))
    assert sorted(p.name for p in (out / "parts").iterdir()) == ["part-00000000.parquet", "part-00000001.parquet"]
    reopened = ResultsStore(out)  # an interrupted study, resumed: its parts are read and numbered on
    assert reopened.done_ids() == {"a", "b", "c"}
    (out / "parts" / "tmpk3j9x_2q.tmp").write_bytes(b"PAR1")  # a part whose writing a kill -9 cut short
    reopened.append(rows(["d"], y=3.0))
    assert (out / "parts" / "part-00000002.parquet").is_file()
    assert reopened.compact(order=["a", "b", "c", "d"]) == {"ok": 4, "failed": 0, "timeout": 0, "crashed": 0}
    assert list(reopened.table()["y"]) == [1.0, 1.0, 2.0, 3.0]
    assert sorted(p.name for p in out.iterdir()) == ["results.parquet"]  # parts/ and the cut-short part gone

    again = ResultsStore(out)  # a finished study resumed: rows go to a new parts folder, merged into the table
    again.append(rows(["e"], y=4.0))
    (out / "parts" / "notes.txt").write_text("not cosim's")
    assert again.compact(order=["a", "b", "c", "d", "e"])["ok"] == 5
    assert list(again.table()["point_id"]) == ["a", "b", "c", "d", "e"]
    assert sorted(p.name for p in (out / "parts").iterdir()) == ["notes.txt"]  # someone else's file is kept


def test_the_index_merge_and_the_id_merge_give_the_same_table(tmp_path):
    design = [f"q{i:03d}" for i in range(40)]
    tables = []
    for name, with_index in (("by_index", True), ("by_id", False)):
        store = ResultsStore(tmp_path / name)
        for start in (30, 0, 20, 10):
            batch = indexed([(design[i], i) for i in range(start, start + 10)], y=float(start))
            store.append(batch if with_index else [{k: v for k, v in r.items() if k != DESIGN_INDEX} for r in batch])
        store.compact(order=design)
        tables.append(store.table())
    pd.testing.assert_frame_equal(tables[0], tables[1])
