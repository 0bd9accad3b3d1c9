"""The decision room's view in its link (cosim.analysis.room.link, issue 39.2), without a browser: a view
written into a query and read back is the same view; what a hand-typed or hostile link holds that the table
does not (a column, a design, a method, a number) is left out and named, never raised.  The browser's side
(the address bar following the view, a fresh chromium opening it) is in test_room_browser.py."""

from __future__ import annotations

from urllib.parse import parse_qs

from cosim.analysis.room.link import NONE, ViewState, decode, encode

COLUMNS = ["traj.waypoints[9]", "e_total", "duration", "odd~name", "peak_tau_ratio[2]"]
METHODS = ["weighted_sum", "topsis"]
IDS = ["ec9cab11ed867126", "0011", "a&b=c"]


def arguments(query: str) -> dict[str, list[bytes]]:
    """The query as tornado gives it to the page's handler: name -> list of bytes."""
    return {k: [v.encode() for v in vs] for k, vs in parse_qs(query, keep_blank_values=True).items()}


def test_a_view_survives_its_link():
    view = ViewState(x="traj.waypoints[9]", y="e_total", colour="peak_tau_ratio[2]", size=NONE,
                     minimise=["e_total", "duration"], maximise=["peak_tau_ratio[2]"], method="topsis",
                     weights={"e_total": 1.0, "duration": 0.1 + 0.2, "odd~name": 0.5},
                     filters={"duration": (1.589, 1.75), "odd~name": (-1e-300, 3.0)}, pinned=["a&b=c", "0011"], tab=1)
    query = encode(view)
    assert query.startswith("x=traj.waypoints%5B9%5D&y=e_total&colour=peak_tau_ratio%5B2%5D&size=%28none%29&min=")
    back, notes = decode(arguments(query), COLUMNS, METHODS, IDS, 5)
    assert notes == []
    assert back == view  # floats exactly (repr), a '~' in a column name, '&' and '=' in an id


def test_a_link_without_a_view_changes_nothing():
    back, notes = decode({}, COLUMNS, METHODS, IDS, 5)
    assert back == ViewState() and notes == []
    # no objective at all is written as such, and read back so: not the table's defaults
    query = encode(ViewState(minimise=[], maximise=[]))
    assert query == "min="
    back, notes = decode(arguments(query), COLUMNS, METHODS, IDS, 5)
    assert back.minimise == [] and back.maximise == [] and notes == []


def test_what_the_table_lacks_is_left_out_and_named():
    hostile = "<img src=x onerror=alert(1)>"
    query = encode(ViewState(x=hostile, colour="nope", minimise=["e_total", hostile], maximise=["e_total"],
                             method="best", weights={"e_total": -1.0, hostile: 1.0},
                             filters={"duration": (2.0, 1.0)}, pinned=["0011", hostile], tab=9))
    query += "&f=duration~x~1&f=justaname&w=duration~nan"
    back, notes = decode(arguments(query), COLUMNS, METHODS, IDS, 5)
    assert back.x is None and back.colour is None and back.method is None and back.tab is None
    assert back.minimise == ["e_total"] and back.maximise == []  # a column is minimised or maximised, not both
    assert back.weights == {} and back.pinned == ["0011"]
    assert back.filters == {"duration": (1.0, 2.0)}  # the bounds in order
    assert notes == [f"x={hostile}: no such numeric column", "colour=nope: no such numeric column",
                     f"min={hostile}: no such numeric column", "rank=best: not one of weighted_sum, topsis",
                     "w=e_total~-1.0: the weight is not a number >= 0", f"w={hostile}: no such numeric column",
                     "w=duration~nan: the weight is not a number >= 0",
                     "f=duration~x~1: the range is not two numbers", "f=justaname: not name~lo~hi",
                     f"pin={hostile}: no such design", "tab=9: not a tab"]
