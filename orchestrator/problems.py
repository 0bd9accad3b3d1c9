"""User-facing problems: what is wrong, where (file and JSON path), and the fix.

Every check in cosim collects :class:`Problem` objects instead of stopping at
the first one, and raises :class:`SpecError` with all of them at the end, so a
user sees every mistake of a spec in one go.  Both belong to the error family
of :mod:`orchestrator.errors`.
"""

from __future__ import annotations

import difflib
from typing import Iterable

from .errors import Problem, UserError

__all__ = ["Problem", "SpecError", "did_you_mean", "json_path"]


class SpecError(UserError):
    """A spec cannot be used; ``problems`` lists every reason found."""


def did_you_mean(name: str, candidates: Iterable[str]) -> str:
    """' Did you mean 'x'?' for the closest candidate, or '' when none is close."""
    close = difflib.get_close_matches(name, list(candidates), n=1, cutoff=0.6)
    return f" Did you mean '{close[0]}'?" if close else ""


def json_path(parts: Iterable[object]) -> str:
    """``$.units.a.parameters[0]`` from a sequence of keys and indices."""
    text = "$"
    for part in parts:
        text += f"[{part}]" if isinstance(part, int) else f".{part}"
    return text
