"""The payload of a study: its system and the bytes of every file its units read, for a child anywhere.

:func:`make_payload` carries the pickled :class:`~cosim.system.builder.System` together with the bytes of the
files its unit types read (FMUs, ``file.py`` units, played tables); the child (:mod:`.child`) writes them into
its own temporary folder and points the unit types there (:func:`load_payload`), so no shared filesystem is
assumed.
"""

from __future__ import annotations

import hashlib
import pickle
from dataclasses import replace
from pathlib import Path
from typing import Any

from cosim.execution.point_row import PointRow
from cosim.util.limits import limit


def make_payload(system: Any, timeout: float | None = None) -> dict[str, Any]:
    """Everything a child needs to run points of ``system``, with no file shared with this process.

    Keys: ``key`` (a digest of the whole payload), ``system`` (pickled System),
    ``files`` (unit name -> [(file name, bytes), ...]): the files each unit
    type reads (:meth:`~cosim.units.protocol.UnitType.files`: FMUs, ``file.py``
    units, played tables, a plug-in kind's files).  A spec with ``experiment.warm_start`` is warmed up here,
    once, in a child process (:func:`warm_up_isolated`), within ``timeout`` seconds (a study's ``--timeout``; None:
    the ``timeout_first_seconds`` limit): the pickled System carries the units' serialized states.
    Raises OSError when a unit's file cannot be read, UserError when the warm-up cannot be made.
    """
    if system.spec.experiment.warm_start is not None and system.warm_start is None:
        # the warm-up runs once, in a child process like any point (it may crash or hang); its states travel
        system = replace(system, warm_start=warm_up_isolated(_plain_payload(system, "-warm-up"), system, timeout))
    return _plain_payload(system)


def _plain_payload(system: Any, key_suffix: str = "") -> dict[str, Any]:
    """The payload of ``system`` as it is (see :func:`make_payload`); ``key_suffix`` sets its key apart."""
    files: dict[str, list[tuple[str, bytes]]] = {}
    for name, system_unit in system.units.items():
        paths = system_unit.unit_type.files()
        if paths:
            files[name] = [(Path(p).name, Path(p).read_bytes()) for p in paths]
    blob = pickle.dumps(system, protocol=pickle.HIGHEST_PROTOCOL)
    h = hashlib.sha256(system.spec.digest.encode())
    for name in sorted(files):
        h.update(name.encode())
        for _, data in files[name]:
            h.update(hashlib.sha256(data).digest())
    from cosim.util.limits import settings

    # the client's limits hold in every worker child, wherever it runs (cosim.util.limits)
    # where each file came from: a message the child writes names the user's file, not the child's copy
    origins = {name: [str(Path(p).resolve()) for p in system.units[name].unit_type.files()] for name in files}
    return {"key": h.hexdigest()[:16] + key_suffix, "system": blob, "files": files, "limits": settings(),
            "origins": origins}


def warm_up_isolated(payload: dict[str, Any], system: Any, timeout: float | None = None) -> Any:
    """The warm state of ``system`` (:mod:`cosim.execution.warm_start`), made in a child process loaded with
    ``payload`` (its system without a warm state), within ``timeout`` seconds (None: the ``timeout_first_seconds``
    limit; a hanging warm-up obeyed only that limit, 600 s, whatever a study's ``--timeout`` said).

    Raises UserError naming the spec's ``experiment.warm_start`` when the warm-up cannot be made: a unit fails,
    cannot save its state, the child crashes or hangs.
    """
    from cosim.errors import Problem, UserError
    from cosim.parallel.isolation.runner import IsolatedRunner  # a child imports this module, not the runner

    runner = IsolatedRunner(payload)
    try:
        state, why = runner.warm_up(float(limit("timeout_first_seconds")) if timeout is None else timeout,
                                    "the study's timeout" if timeout is not None else "COSIM_TIMEOUT_FIRST")
    finally:
        runner.close()
    if state is None:
        if isinstance(why, UserError):
            raise why
        raise UserError([Problem(system.spec.path, "$.experiment.warm_start", f"the warm-up run to t="
                                 f"{system.spec.experiment.warm_start:g} failed: {why}",
                                 "fix what makes the run with the spec's own values fail, or remove warm_start")])
    return state


def load_payload(payload: dict[str, Any], folder: str, origins: dict[str, str] | None = None) -> Any:
    """The System of ``payload``, its unit files written under ``folder`` and used from there.

    ``origins``, when given, is filled with each copy's path -> the path of the file it was copied from on the
    client (for :func:`named_for_the_user`)."""
    system = pickle.loads(payload["system"])
    for name, unit_files in payload["files"].items():
        copies = []
        sources = payload.get("origins", {}).get(name, [])
        for i, (file_name, data) in enumerate(unit_files):
            unit_folder = Path(folder) / name / str(i)  # one folder per unit and file: names may repeat
            unit_folder.mkdir(parents=True, exist_ok=True)
            local = unit_folder / file_name
            local.write_bytes(data)
            copies.append(local)
            if origins is not None and i < len(sources):
                origins[str(local)] = sources[i]
        system.units[name].unit_type.relocate(copies)
    return system


def named_for_the_user(row: PointRow, origins: dict[str, str]) -> PointRow:
    """``row`` with the paths of the child's copies of unit files in its message replaced by the user's own
    paths (issue 39: a unit's traceback named /tmp/cosim_worker_*/payload_*/b/0/unit.py, a file the user never
    saw and which is gone when the sweep ends)."""
    message = row.message
    for local, original in origins.items():
        if local in message:
            message = message.replace(local, original)
    return row if message == row.message else replace(row, message=message)
