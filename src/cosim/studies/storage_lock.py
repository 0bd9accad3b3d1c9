"""One cosim run at a time per study in an Optuna storage (``cosim optimize --storage URL``).

A results folder is locked to one cosim process (:mod:`cosim.results.lock`); a study in an Optuna storage is
shared wider: two optimisations into two folders may name one study (``--study-name``), one storage may serve
several machines.  Two runs writing one study mixed their trials (28 trials from two runs, a duplicate trial
number).  So a run holds the study's lock while it writes: a second study in the same storage, named
``cosim-lock:<study name>``, created by the holder (Optuna creates a study atomically: the database's unique
study name refuses the second creator, on SQLite and on a database server alike), carrying the holder's host,
pid, start time and results folder as user attributes, and deleted when the run ends in any way Python sees.
A run killed with ``kill -9`` leaves its lock behind: on the same host the next run finds the holder's process
gone and takes the lock over; a lock from another host is only reported, with the command that releases it.
"""

from __future__ import annotations

import os
import socket
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterator, Mapping

from cosim.errors import OptimizeError
from cosim.studies.options import PYTHON_WORDS

LOCK_PREFIX = "cosim-lock:"


def lock_name(study_name: str) -> str:
    """The name of the study that marks ``study_name`` as in use."""
    return LOCK_PREFIX + study_name


@contextmanager
def study_locked(storage: Any, shown: str, study_name: str, out: str | Path,
                 words: Mapping[str, str] = PYTHON_WORDS) -> Iterator[None]:
    """Hold the lock of study ``study_name`` in ``storage`` (an Optuna RDBStorage) for the block.

    ``shown`` is the storage's URL as it may be printed (no password).  Raises OptimizeError (exit 2) naming
    the storage, the study, the run that holds it and what to do (its options named by ``words``), when another
    live run holds it.
    """
    holder = _acquire(storage, shown, study_name, out, {**PYTHON_WORDS, **words})
    try:
        yield
    finally:
        _release(storage, study_name, holder)


def _me(out: str | Path) -> dict[str, Any]:
    return {"host": socket.gethostname(), "pid": os.getpid(), "results": str(Path(out).resolve()),
            "started": datetime.now(timezone.utc).isoformat(timespec="seconds")}


def _acquire(storage: Any, shown: str, study_name: str, out: str | Path, word: Mapping[str, str]) -> dict[str, Any]:
    import optuna

    me = _me(out)
    for _ in range(3):  # a stale lock taken over, then (rarely) another taker first: try again
        try:
            study_id = storage.create_new_study(directions=[optuna.study.StudyDirection.MINIMIZE],
                                                study_name=lock_name(study_name))
        except optuna.exceptions.DuplicatedStudyError:
            holder = _holder(storage, study_name)
            if holder is None:
                continue  # released meanwhile
            if not _gone(holder):
                raise OptimizeError(_in_use(shown, study_name, holder, word)) from None
            _delete(storage, study_name)  # its run was killed on this host: the lock is free
            continue
        for key, value in me.items():
            storage.set_study_user_attr(study_id, key, value)
        return me
    raise OptimizeError(f"{word['storage']} {shown}: the study {study_name!r} is being taken by other runs at this "
                        f"moment; wait for them, or give another {word['study_name']}")


def _holder(storage: Any, study_name: str) -> dict[str, Any] | None:
    """The lock's holder ({} while it is being written), None when there is no lock any more."""
    import optuna

    try:
        study_id = storage.get_study_id_from_name(lock_name(study_name))
        return dict(storage.get_study_user_attrs(study_id))
    except KeyError:  # optuna raises KeyError for a study that does not exist
        return None
    except optuna.exceptions.OptunaError:
        return None


def _gone(holder: dict[str, Any]) -> bool:
    """Whether the holder's process has ended: known only for a process on this host."""
    if holder.get("host") != socket.gethostname() or not isinstance(holder.get("pid"), int):
        return False
    try:
        os.kill(holder["pid"], 0)
    except ProcessLookupError:
        return True
    except PermissionError:  # alive, another user's
        return False
    return False


def _in_use(shown: str, study_name: str, holder: dict[str, Any], word: Mapping[str, str]) -> str:
    who = (f"pid {holder['pid']} on {holder.get('host', '?')}, started {holder.get('started', '?')}, results in "
           f"{holder.get('results', '?')}" if "pid" in holder else "a run starting at this moment")
    return (f"{word['storage']} {shown}: the study {study_name!r} is in use by another cosim optimize ({who}); two "
            f"runs would mix their trials in it. Wait for that run to finish, or give this one another "
            f"{word['study_name']}. "
            "If that run is gone (killed on another machine), release the study: optuna delete-study --storage "
            f"{shown} --study-name '{lock_name(study_name)}'")


def _delete(storage: Any, study_name: str) -> None:
    try:
        storage.delete_study(storage.get_study_id_from_name(lock_name(study_name)))
    except KeyError:  # another taker deleted it first
        pass


def _release(storage: Any, study_name: str, me: dict[str, Any]) -> None:
    """Delete the lock when it is still this run's (never another run's that took a lock thought stale)."""
    holder = _holder(storage, study_name)
    if holder is not None and holder.get("pid") == me["pid"] and holder.get("host") == me["host"]:
        _delete(storage, study_name)


@contextmanager
def locked_storage(url: str | None, study_name: str, out: str | Path,
                   words: Mapping[str, str] = PYTHON_WORDS) -> Iterator[Any]:
    """The Optuna storage at ``url`` (None when no ``url``: no storage), its study ``study_name`` locked to this run
    for the block.  Raises OptimizeError (exit 2) when it cannot be opened or another run holds the study."""
    if not url:
        yield None
        return
    from cosim.studies.optuna_storage import open_storage, shown_url

    storage = open_storage(url, words)
    with study_locked(storage, shown_url(url), study_name, out, words):
        yield storage
