"""An optimisation's trials also in an Optuna storage (``storage="sqlite:///study.db"``).

The results folder stays what a study *is* (its rows, metadata and resume); the storage is a mirror of it in
Optuna's own form, for Optuna's tools: ``optuna-dashboard sqlite:///study.db``, ``optuna.load_study(...)`` and
``optuna.visualization``.  Each trial carries the objective values (named as in the spec), the constraint
violations, and as user attributes the row's ``point_id`` and ``status``; the study carries the results
folder.  A resume replays the stored run into a new study of the same name, so the storage then holds the
whole run once, as the folder does.  While a run writes a study, the study is locked to it
(:mod:`cosim.studies.storage_lock`).
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path
from typing import Any, Literal, Mapping, Sequence

from cosim.errors import OptimizeError
from cosim.studies.options import PYTHON_WORDS

Direction = Literal["minimize", "maximize"]  # an objective's sense, as the spec's schema allows it and Optuna takes it

STORAGE_FIX = ("give a database URL Optuna can open, e.g. sqlite:///study.db (a file beside you) or "
               "postgresql://user@host/db, and check that its folder exists")


def default_study_name(out: str | Path) -> str:
    """The study's name in the storage: the results folder's absolute path (one storage may hold many)."""
    return str(Path(out).resolve())


def shown_url(url: str) -> str:
    """``url`` with any password replaced by ``***`` (it goes into metadata.json and onto the terminal)."""
    try:
        from sqlalchemy.engine import make_url

        return make_url(url).render_as_string(hide_password=True)
    except Exception:  # noqa: BLE001 - not a URL sqlalchemy parses: shown as given (it is refused later)
        return url


def open_storage(url: str, words: Mapping[str, str] = PYTHON_WORDS) -> Any:
    """Optuna's RDBStorage at ``url``, its tables created when the database is new.

    Two runs opening one new database at the same moment both create its tables, and the second's creation
    fails (a UNIQUE constraint, "table ... already exists", "database is locked"): that is not a bad URL, so
    the opening is tried again, when the first creator has finished.  Raises OptimizeError (exit 2) when the
    storage cannot be opened; a database still busy after the tries is named as such.
    """
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)  # Optuna's INFO notes are not cosim's terminal's
    word = {**PYTHON_WORDS, **words}
    last: Exception | None = None
    for attempt in range(5):
        try:
            return optuna.storages.RDBStorage(url)
        except Exception as exc:  # noqa: BLE001 - sqlalchemy's and optuna's errors: a bad URL, a missing folder
            last = exc
            if not _concurrent(exc):
                break
            time.sleep(0.2 * (attempt + 1))
    assert last is not None
    first = str(last).splitlines()[0] if str(last) else type(last).__name__
    if _concurrent(last):
        raise OptimizeError(f"{word['storage']} {shown_url(url)}: the database stayed busy while another process created or "
                            f"wrote it ({first}); run again when that process is done (a SQLite file serves one "
                            "writer at a time: for many writers at once use a database server, e.g. "
                            "postgresql://user@host/db)") from None
    raise OptimizeError(f"{word['storage']} {shown_url(url)}: cannot open it ({first}); {STORAGE_FIX}") from None


def _concurrent(exc: Exception) -> bool:
    """Whether opening failed because another process created or wrote the database at the same moment."""
    text = str(exc)
    return type(exc).__name__ in ("IntegrityError", "OperationalError") and any(
        sign in text for sign in ("UNIQUE constraint failed", "already exists", "database is locked"))


def open_storage_study(url: str, name: str, directions: Sequence[Direction], metric_names: Sequence[str],
                       sampler: Any, resume: bool, out: str | Path, words: Mapping[str, str] = PYTHON_WORDS,
                       storage: Any = None) -> Any:
    """A new Optuna study ``name`` in the storage at ``url`` (``storage``: that storage, already open), with ``sampler``.

    On ``resume`` a study of that name is replaced: the run is replayed into it from the results folder.
    Raises OptimizeError (exit 2) when the storage cannot be opened, or when a fresh run finds a study of
    that name already there (another run's trials, which a fresh run must not mix with its own); ``words``
    name the options (:data:`cosim.studies.options.PYTHON_WORDS` by default).
    """
    word = {**PYTHON_WORDS, **words}
    import optuna

    storage = storage if storage is not None else open_storage(url, words)
    existing = {s.study_name for s in storage.get_all_studies()}
    if name in existing:
        if not resume:
            raise OptimizeError(f"{word['storage']} {shown_url(url)} already holds a study named {name!r} (an "
                                f"earlier optimisation into {out}); resume it with {word['resume']}, give another "
                                f"{word['study_name']}, or delete it with Optuna's command: optuna delete-study "
                                f"--storage {shown_url(url)} --study-name '{name}'")
        optuna.delete_study(study_name=name, storage=storage)
    study = optuna.create_study(storage=storage, study_name=name, directions=list(directions), sampler=sampler)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        study.set_metric_names(list(metric_names))  # optuna-dashboard and the plots name the objectives
    study.set_user_attr("cosim_results", str(Path(out).resolve()))
    return study
