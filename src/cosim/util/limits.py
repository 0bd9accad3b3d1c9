"""Limits that keep careless or hostile inputs from exhausting the machine, and how to raise them.

Every limit has a default meant to be far above what a real study needs and
an environment variable that replaces it on purpose, e.g.::

    COSIM_MAX_POINTS=5000000 cosim sweep big_study.json

A sweep hands the limits of the client to its worker processes (they travel
with the payload), so a limit raised where ``cosim`` is started also holds on
a remote Dask worker.  The table of limits is in the README (section
"Hostile and careless inputs").
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from cosim.errors import Problem, UserError


@dataclass(frozen=True)
class Limit:
    """One limit: its environment variable, default and what it bounds."""

    env: str
    default: float
    what: str
    integer: bool = True


LIMITS: dict[str, Limit] = {
    # FMU archives (cosim.util.archive)
    "fmu_unpacked_mb": Limit("COSIM_FMU_UNPACKED_MB", 1024, "megabytes an FMU may unpack to"),
    "fmu_members": Limit("COSIM_FMU_MEMBERS", 10_000, "files in an FMU archive"),
    "fmu_ratio": Limit("COSIM_FMU_RATIO", 1000, "uncompressed/compressed size of a member above 1 MB",
                       integer=False),
    # FMI 3.0 arrays (cosim.units.fmu.description): one object per element is made when an FMU is described
    "array_elements": Limit("COSIM_ARRAY_ELEMENTS", 1_000_000, "elements of the arrays of one FMU, all arrays "
                            "together (FMI 3.0 <Dimension>s and the structural parameters that size them)"),
    # SSP files read whole (cosim.ssp.bounds): lxml's tree takes about 13 times an XML file's size
    "ssp_file_mb": Limit("COSIM_SSP_FILE_MB", 64, "megabytes of one SSP file read whole (.ssd, .ssv, .ssm as XML; "
                         "a table component's .csv)",
                         integer=False),
    # spec.json and the design space (cosim.spec.loader, cosim.spec.design)
    "json_depth": Limit("COSIM_JSON_DEPTH", 64, "nesting depth of arrays and objects in spec.json"),
    "points": Limit("COSIM_MAX_POINTS", 1_000_000, "design points of a sweep (before a constraint)"),
    "steps": Limit("COSIM_MAX_STEPS", 100_000_000, "communication steps of one run, (stop - start) / step"),
    # expressions (cosim.spec.expressions)
    "expression_length": Limit("COSIM_EXPRESSION_LENGTH", 10_000, "characters of an expression"),
    "expression_depth": Limit("COSIM_EXPRESSION_DEPTH", 100, "nesting depth of an expression"),
    # Python units (cosim.units.python.unit, cosim.units.python.data_files)
    "import_seconds": Limit("COSIM_IMPORT_SECONDS", 120, "seconds a Python unit's module may take to import",
                            integer=False),
    "data_mb": Limit("COSIM_DATA_MB", 256, "megabytes of one data file or folder a Python unit declares (it "
                     "travels with every sweep's payload)", integer=False),
    # worker child processes (cosim.parallel.isolation)
    "child_memory_mb": Limit("COSIM_CHILD_MEMORY_MB", 8192, "megabytes of data memory of one child process"),
    "child_rss_mb": Limit("COSIM_CHILD_RSS_MB", 2048, "resident megabytes after which a child is replaced"),
    "child_points": Limit("COSIM_CHILD_POINTS", 5000, "points one child runs before it is replaced"),
    "child_message_mb": Limit("COSIM_CHILD_MESSAGE_MB", 64, "megabytes of one message from a child process to "
                              "its parent: a row, or a study's warm state (experiment.warm_start)", integer=False),
    # lock-step groups in a sweep's child (cosim.execution.lockstep)
    "lockstep_seconds": Limit("COSIM_LOCKSTEP_SECONDS", 0.25, "seconds a lock-step group of points is sized to "
                              "last (a tiny value turns lock-step off)", integer=False),
    "timeout_floor_seconds": Limit("COSIM_TIMEOUT_FLOOR", 60, "shortest default per-point timeout",
                                   integer=False),
    "timeout_first_seconds": Limit("COSIM_TIMEOUT_FIRST", 600, "default per-point timeout before a point "
                                   "time is measured", integer=False),
}


def limit(name: str) -> float:
    """The value of limit ``name``: its environment variable when set, else the default.

    Raises UserError (exit 2) when the variable is not a
    positive finite number (a whole number for counts).
    """
    spec = LIMITS[name]
    text = os.environ.get(spec.env)
    if text is None or not text.strip():
        return spec.default
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value <= 0 or (spec.integer and value != int(value)):
        kind = "a positive whole number" if spec.integer else "a positive number"
        raise UserError([Problem("environment", spec.env, f"'{text}' is not {kind}",
                                 f"set {spec.env} to {kind} ({spec.what}; default {shown(spec.default)}) "
                                 "or unset it")])
    return int(value) if spec.integer else value


def shown(value: float) -> str:
    """A limit's value as a person reads it: 1000000, not 1e+06; 0.25 as 0.25."""
    return str(int(value)) if float(value) == int(value) else f"{value:g}"


def settings() -> dict[str, str]:
    """The limit variables set in this process's environment (to hand to worker processes)."""
    return {s.env: os.environ[s.env] for s in LIMITS.values() if os.environ.get(s.env)}


def raise_hint(name: str) -> str:
    """How to raise limit ``name`` on purpose, for messages."""
    spec = LIMITS[name]
    return f"to raise the limit on purpose, set the environment variable {spec.env} (default {shown(spec.default)})"
