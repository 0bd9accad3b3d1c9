"""Notes of one SSP's reading, many alike written as one line with a count.

A generated or hostile SSP may hold thousands of parameters that match no
variable, or thousands of elements in a tool's older form: a note each would
print thousands of lines (a 30 MB .ssv printed 500 000).  :class:`AlikeNotes`
keeps the first note of a kind in full and counts the others, naming the first
few of them, so the reader prints one line per kind.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Hashable, NamedTuple

SHOWN = 5  # how many of the other items a line names


class Note(NamedTuple):
    """One note for :meth:`AlikeNotes.add`: its key, text, the item it is about, and what more of it are."""

    key: Hashable
    text: str
    item: str
    more: str


@dataclass
class _Alike:
    first: str  # the first note, in full
    more: str  # what the others are, after their count: "more parameters of x.ssv match no variable"
    items: list[str] = field(default_factory=list)  # the first SHOWN others, as the line names them
    count: int = 1


class AlikeNotes:
    """Notes grouped by a key; :meth:`lines` gives one line per key, in the order keys were first seen."""

    def __init__(self) -> None:
        self._groups: dict[Hashable, _Alike] = {}

    def add(self, key: Hashable, text: str, item: str, more: str) -> None:
        """Note ``text`` (about ``item``, e.g. ``'p7'``) under ``key``; ``more`` says what further notes of the
        key are, after their count (``"more parameters of x.ssv match no variable"``)."""
        group = self._groups.get(key)
        if group is None:
            self._groups[key] = _Alike(text, more)
            return
        group.count += 1
        if len(group.items) < SHOWN:
            group.items.append(item)

    def lines(self) -> list[str]:
        """One line per key: its note alone, or its first note and ``'; 41,999 more ...: a, b, c, d, e, ...'``."""
        lines = []
        for group in self._groups.values():
            if group.count == 1:
                lines.append(group.first)
                continue
            others = group.count - 1
            named = ", ".join(group.items) + (", ..." if others > len(group.items) else "")
            lines.append(f"{group.first}; {others:,} {group.more}: {named}")
        return lines

    def clear(self) -> None:
        self._groups.clear()
