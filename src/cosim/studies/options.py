"""A study's options, in four typed records: where its rows go, how its points run, when it stops, what it says.

Every study (a sweep, an optimisation, a sensitivity study: :mod:`cosim.studies.runner`) takes the same four:

- :class:`Where`: the results folder (``out``), whether to finish the study already in it (``resume``), to
  discard rows made by other unit files (``recompute``), to also write ``results.csv`` (``csv``);
- :class:`How`: the cluster (``workers`` of a local one, a ``scheduler`` address or a ``cluster`` file), the
  per-point ``timeout``, the points per task (``batch_size``), exact pruning (``prune``), and whether the local
  cluster starts while the study is prepared (``start_early``);
- :class:`Stop`: when an open-ended study stops (an optimiser's ``budget`` of evaluations and its limit on
  proposals); a design grid stops when its points are done;
- :class:`Show`: the progress stream, ``quiet``, the decision room served while it runs (``explore``) and the
  ``words`` its messages name options with (Python's by default, :data:`PYTHON_WORDS`; the command line gives its
  own, so no library message names a command-line option).

:func:`split_options` takes the flat keyword arguments of the study front doors (``Sweep(spec, out=...,
workers=2, quiet=True)``, as ``cosim.sweep`` takes them) into these records: one table,
:data:`KEYWORDS`, says which record each name belongs to.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence, TextIO

from cosim.errors import UserError

# How a message names an option when the study runs from Python (the command line has its own: cosim.cli.wording)
PYTHON_WORDS: Mapping[str, str] = {
    "out": "out folder", "out_dir": "out=DIR", "resume": "resume=True", "recompute": "recompute=True",
    "again": "the same study", "n": "n", "n_is": "n=", "seed": "seed", "method": "method",
    "storage": "storage", "study_name": "study_name",
}


@dataclass(frozen=True)
class Where:
    """Where a study's rows go: ``out`` (its results folder; None: a temporary one, for a sweep whose table is
    only returned), ``resume`` (finish the study already in ``out``), ``recompute`` (with ``resume``: discard
    the rows of unit or data files that changed instead of refusing), ``csv`` (also write ``results.csv``)."""

    out: Path | None = None
    resume: bool = False
    recompute: bool = False
    csv: bool = False


@dataclass(frozen=True)
class How:
    """How a study's points run: ``workers`` (of a local cluster; default one per core), a running
    ``scheduler`` (address) or a ``cluster`` file (at most one of the two), ``timeout`` (seconds a point may
    run; None: from the points measured), ``batch_size`` (points per task; None: automatic), ``prune`` (stop a
    design once a finished one strictly dominates its bound; ``prune_objectives`` and ``prune_constraints`` say
    on what, default the spec's ``optimize`` section), ``start_early`` (a local cluster starts in the background
    while the study is prepared)."""

    workers: int | None = None
    scheduler: str | None = None
    cluster: str | Path | None = None
    timeout: float | None = None
    batch_size: int | None = None
    prune: bool = False
    prune_objectives: Sequence[tuple[str, str]] | None = None
    prune_constraints: Sequence[str] = ()
    start_early: bool = False

    def checked(self, error: type[UserError]) -> "How":
        """This record with ``workers`` filled in (one per core); raises ``error`` for a timeout that is not a
        positive, finite number of seconds or fewer than one worker."""
        if self.timeout is not None and not (isinstance(self.timeout, (int, float)) and math.isfinite(self.timeout)
                                             and self.timeout > 0):
            # NaN, infinity, zero or a negative number would make every point crashed or never stop a hanging one
            raise error(f"the timeout must be a positive number of seconds, got {self.timeout}")
        if self.workers is not None and self.workers < 1:
            raise error(f"workers must be at least 1, got {self.workers}")
        return dataclasses.replace(self, workers=self.workers or os.cpu_count() or 1)


@dataclass(frozen=True)
class Stop:
    """When an open-ended study stops: after ``budget`` evaluations (rows; None: the source's default), or
    after ``proposals_per_evaluation`` times the budget in proposals (a sampler that keeps proposing designs
    already evaluated or outside the design constraint)."""

    budget: int | None = None
    proposals_per_evaluation: int = 20


@dataclass(frozen=True)
class Show:
    """What a study says: its progress line and messages on ``progress`` (default stderr) unless ``quiet``; the
    decision room of its folder served while it runs (``explore``); ``words``: how its messages name options
    (:data:`PYTHON_WORDS` by default)."""

    progress: TextIO | None = None
    quiet: bool = False
    explore: bool = False
    words: Mapping[str, str] = field(default_factory=lambda: dict(PYTHON_WORDS))

    def word(self, option: str) -> str:
        """How this study's messages name ``option`` (a key of :data:`PYTHON_WORDS`)."""
        return self.words.get(option, PYTHON_WORDS.get(option, option))


# the flat keyword arguments of the front doors -> the record holding each
KEYWORDS: Mapping[str, type] = {
    **{f.name: Where for f in dataclasses.fields(Where)},
    **{f.name: How for f in dataclasses.fields(How)},
    **{f.name: Stop for f in dataclasses.fields(Stop)},
    **{f.name: Show for f in dataclasses.fields(Show)},
}


@dataclass(frozen=True)
class Options:
    """The four records of one study."""

    where: Where = Where()
    how: How = How()
    stop: Stop = Stop()
    show: Show = Show()


def split_options(where: Where | None = None, how: How | None = None, stop: Stop | None = None,
                  show: Show | None = None, **keywords: Any) -> Options:
    """The records given, each updated with the flat ``keywords`` that belong to it (:data:`KEYWORDS`).

    Raises TypeError for a keyword no record has, as a call with an unknown keyword argument does.
    """
    unknown = sorted(set(keywords) - set(KEYWORDS))
    if unknown:
        raise TypeError(f"unexpected keyword argument(s): {', '.join(unknown)}")
    records: dict[type, Any] = {Where: where or Where(), How: how or How(), Stop: stop or Stop(),
                                Show: show or Show()}
    for record in records:
        given = {k: v for k, v in keywords.items() if KEYWORDS[k] is record}
        if record is Where and given.get("out") is not None:
            given["out"] = Path(given["out"])
        if given:
            records[record] = dataclasses.replace(records[record], **given)
    return Options(records[Where], records[How], records[Stop], records[Show])
