"""The decision room's state in its link, so a view can be bookmarked and sent to a colleague (issue 39).

The page's address carries, after the token, the query parameters of the view:

- ``x``, ``y``: the cloud's columns (``x=traj.waypoints%5B9%5D``); ``colour``, ``size``: a column or ``(none)``;
- ``min``, ``max``: an objective minimised or maximised, repeated (``min=e_total&min=duration``; ``min=``
  alone: no objective at all);
- ``rank``: the ranking method (``rank=topsis``); ``w``: an objective's weight, ``name~weight``
  (``w=duration~0.5``);
- ``f``: a narrowed range filter, ``name~lo~hi`` (``f=duration~1.589~1.75``);
- ``pin``: a design of the shortlist, repeated (``pin=ec9cab11ed867126``);
- ``tab``: the tab shown (0 Points, 1 Decide, 2 Selection, 3 Study, 4 Dimensions, 5 Surrogate when the folder has
  surrogates).

``name~...`` splits at the last ``~`` (a column name may hold one; a number never does).  The server writes
the query (:func:`encode`) into the ``view-link`` model's ``tags`` after every change and the page's own
CustomJS (:data:`REPLACE_JS`, no inline script: the page's policy allows bokeh's CustomJS only) puts it into
the address bar with ``history.replaceState``, keeping the token the page was opened with.  A page opened with
such a link starts in that state (:func:`decode`); what the table does not have (a column, a design) is left
out and named in a note, escaped like every string from outside.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from urllib.parse import urlencode

NONE = "(none)"

# the page's address: the query of the view after the token it was opened with (the colleague needs it too)
REPLACE_JS = """
const query = (state.tags && state.tags.length) ? state.tags[0] : '';
const token = new URLSearchParams(window.location.search).get('token');
const parts = [];
if (token !== null) parts.push('token=' + encodeURIComponent(token));
if (query) parts.push(query);
const next = window.location.pathname + (parts.length ? '?' + parts.join('&') : '') + window.location.hash;
if (next !== window.location.pathname + window.location.search + window.location.hash) {
  window.history.replaceState(window.history.state, '', next);
}
"""


@dataclass
class ViewState:
    """A view of the room as its link gives it; None (or empty) where the link says nothing."""

    x: str | None = None
    y: str | None = None
    colour: str | None = None  # a column or NONE
    size: str | None = None
    minimise: list[str] | None = None
    maximise: list[str] | None = None
    method: str | None = None
    weights: dict[str, float] = field(default_factory=dict)
    filters: dict[str, tuple[float, float]] = field(default_factory=dict)
    pinned: list[str] | None = None
    tab: int | None = None


def encode(state: ViewState) -> str:
    """The query text of ``state`` (without the token), in the order of the module's table."""
    pairs: list[tuple[str, str]] = []
    for key in ("x", "y", "colour", "size"):
        value = getattr(state, key)
        if value is not None:
            pairs.append((key, value))
    pairs += [("min", c) for c in state.minimise or []] + [("max", c) for c in state.maximise or []]
    if state.minimise == [] and state.maximise == []:
        pairs.append(("min", ""))  # no objective at all, which is not the table's defaults
    if state.method:
        pairs.append(("rank", state.method))
    pairs += [("w", f"{name}~{weight!r}") for name, weight in state.weights.items()]
    pairs += [("f", f"{name}~{lo!r}~{hi!r}") for name, (lo, hi) in state.filters.items()]
    pairs += [("pin", i) for i in state.pinned or []]
    if state.tab:
        pairs.append(("tab", str(state.tab)))
    return urlencode(pairs)


def decode(arguments: Mapping[str, Sequence[bytes | str]], columns: Sequence[str], methods: Sequence[str],
           ids: Sequence[str], tabs: int) -> tuple[ViewState, list[str]]:
    """The view a page's query ``arguments`` (tornado's: name -> list of bytes) asks for, checked against the
    table's numeric ``columns``, the ranking ``methods``, the design ``ids`` and the number of ``tabs``; and
    a note per value left out (plain text: the caller escapes it).  Never raises: a link is typed by hand."""
    def values(key: str) -> list[str]:
        return [v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v) for v in arguments.get(key, [])]

    known, notes, state = set(columns), [], ViewState()

    def column(key: str, value: str, none_ok: bool = False) -> str | None:
        if value in known or (none_ok and value == NONE):
            return value
        notes.append(f"{key}={value}: no such numeric column")
        return None

    for key, none_ok in (("x", False), ("y", False), ("colour", True), ("size", True)):
        given = values(key)
        if given:
            setattr(state, key, column(key, given[-1], none_ok))
    if "min" in arguments or "max" in arguments:
        state.minimise = [c for c in values("min") if c and column("min", c) is not None]
        state.maximise = [c for c in values("max") if c and column("max", c) is not None and c not in state.minimise]
    for method in values("rank")[-1:]:
        if method in methods:
            state.method = method
        else:
            notes.append(f"rank={method}: not one of {', '.join(methods)}")
    for text in values("w"):
        name, _, number = text.rpartition("~")
        weight = _number(number)
        if column("w", name) is not None:
            if weight is None or weight < 0:
                notes.append(f"w={text}: the weight is not a number >= 0")
            else:
                state.weights[name] = weight
    for text in values("f"):
        parts = text.rsplit("~", 2)
        lo, hi = (_number(parts[1]), _number(parts[2])) if len(parts) == 3 else (None, None)
        if len(parts) == 3 and column("f", parts[0]) is not None:
            if lo is None or hi is None:
                notes.append(f"f={text}: the range is not two numbers")
            else:
                state.filters[parts[0]] = (min(lo, hi), max(lo, hi))
        elif len(parts) != 3:
            notes.append(f"f={text}: not name~lo~hi")
    if "pin" in arguments:
        present = set(map(str, ids))
        state.pinned = [i for i in dict.fromkeys(values("pin")) if i in present]
        notes += [f"pin={i}: no such design" for i in dict.fromkeys(values("pin")) if i not in present]
    for tab in values("tab")[-1:]:
        if tab.isdigit() and int(tab) < tabs:
            state.tab = int(tab)
        else:
            notes.append(f"tab={tab}: not a tab")
    return state, notes


def _number(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None
