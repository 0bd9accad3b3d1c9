"""A watched results folder whose table changes under the room (issue 38.7): a table of another schema, a garbled
table, a deleted one.

Two real results folders (a sweep of the decay spec, an optimisation of the two bowls: other columns), a room of
a watched folder (LiveStudy) built into a bokeh Document as a page's session has it, and the folder's files
swapped under it.  Before: another schema raised at every look (a traceback on the server's terminal per second,
HTTP 500 for a new page); a garbled or deleted table left the last rows on the page, "the study is complete".
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from bokeh.document import Document

import cosim
from cosim.analysis.room.app import Room, make_document
from cosim.analysis.room.live import LiveStudy
from tests.analysis.room.test_room_browser import bowls_spec, decay_spec, write


@pytest.fixture(scope="module")
def two_folders(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("live_table")
    cosim.sweep(write(root / "sweep", decay_spec()), out=root / "sweep" / "out", workers=1, quiet=True)
    cosim.optimize(write(root / "optimize", {**bowls_spec(), "optimize": {"budget": 8, "batch": 4, "seed": 3}}),
                   root / "optimize" / "out", workers=1, quiet=True)
    return {"sweep": root / "sweep" / "out", "optimize": root / "optimize" / "out"}


def _watched(tmp_path: Path, source: Path) -> tuple[Path, LiveStudy, Document, Room]:
    folder = tmp_path / "watched"
    folder.mkdir()
    _copy(source, folder)
    live = LiveStudy(folder, every=0.0)
    doc = Document()
    room = Room(doc, live.current(), live=live)
    return folder, live, doc, room


def _copy(source: Path, folder: Path) -> None:
    for name in ("metadata.json", "results.parquet"):
        shutil.copy(source / name, folder / name)


def _count(doc: Document) -> str:
    return doc.get_model_by_name("count").text


def test_a_watched_table_of_another_schema_is_shown_and_the_change_said(tmp_path, two_folders):
    folder, live, doc, room = _watched(tmp_path, two_folders["sweep"])
    assert "of 24 designs" in _count(doc) and "min y_end, max y_int" in _count(doc)
    _copy(two_folders["optimize"], folder)  # the folder now holds another study's table
    room._look()  # raised AnalysisError ("no column 'y_end'") at every look before
    text = _count(doc)
    assert "of 8 designs" in text and "min f1, min f2" in text, text
    assert "the table&#x27;s columns changed (gone: ode.a, ode.x0, f.fail_at, y_end, y_int; new: b.x, b.y, f1, f2" \
           in text, text
    assert len(doc.roots) == 1  # the old room's models left the page
    page = Document()
    make_document(page, live)  # a new page (was HTTP 500 while the tab's room raised)
    assert "of 8 designs" in _count(page)
    rebuilt = [c for c in doc.session_callbacks]
    assert len(rebuilt) == 1  # one look per page: the old room's periodic callback went with it
    _copy(two_folders["sweep"], folder)  # and back
    room_now = rebuilt[0].callback
    room_now()
    assert "of 24 designs" in _count(doc)


@pytest.mark.parametrize("damage", ["garbled", "deleted"])
def test_a_garbled_or_deleted_table_is_not_shown_as_a_complete_study(tmp_path, two_folders, damage):
    folder, live, doc, room = _watched(tmp_path, two_folders["sweep"])
    assert "the study is complete" in _count(doc)
    if damage == "garbled":
        (folder / "results.parquet").write_bytes(b"not a parquet file " * 64)
        said = "Parquet magic bytes not found"
    else:
        (folder / "results.parquet").unlink()
        said = "no such results table"
    room._look()
    text = _count(doc)
    assert "complete" not in text, text
    assert "live: the table cannot be read now (" in text and said in text, text
    assert "shown: the 24 rows (12 ok, 12 failed) read before" in text, text
    _copy(two_folders["sweep"], folder)  # repaired: complete again
    room._look()
    assert "the study is complete" in _count(doc) and "cannot be read" not in _count(doc)
