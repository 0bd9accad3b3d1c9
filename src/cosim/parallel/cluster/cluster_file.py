"""A cluster file: the Dask cluster a study starts, named by class, with its arguments and its scaling.

A cluster file (YAML or JSON) names a Dask cluster class by import path, its keyword arguments and its
scaling (how cosim chooses a cluster at all: :mod:`cosim.parallel.cluster.choice`)::

    type: dask_jobqueue.SLURMCluster      # or distributed.LocalCluster, dask_kubernetes.operator.KubeCluster
    kwargs: {cores: 1, memory: 4GB, walltime: "01:00:00"}
    scale: {jobs: 20}                     # or {n: 20} workers; or instead:
    adapt: {minimum: 2, maximum: 50}

(the shape dask-ctl and ESMValCore use).  :func:`read_cluster_file` checks it, :func:`start_cluster` imports
the class -- only then, so dask-jobqueue and dask-kubernetes are optional -- makes the cluster and scales it
(``scale``) or lets Dask adapt it (``adapt``).

Every mistake in a cluster file is a :class:`~cosim.errors.ClusterFileError` (a UserError) naming the file,
the field and the fix (exit code 2).
"""

from __future__ import annotations

import gc
import importlib
import inspect
import logging
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

from cosim.errors import ClusterFileError, Problem
from cosim.parallel.cluster.interrupts import processes_started_here_ignore_ctrl_c
from cosim.parallel.cluster.local import ALLOWED_FAILURES

# the package a cluster class comes from -> how to install it (the optional extras of pyproject.toml)
EXTRAS = {
    "dask_jobqueue": "pip install 'cosim[jobqueue]'  (or: pip install dask-jobqueue)",
    "dask_kubernetes": "pip install 'cosim[kubernetes]'  (or: pip install dask-kubernetes)",
}


@dataclass(frozen=True)
class ClusterFile:
    """A checked cluster file: ``type`` (import path), ``kwargs``, and ``scale`` or ``adapt`` (or neither)."""

    path: str
    type: str
    kwargs: dict[str, Any] = field(default_factory=dict)
    scale: dict[str, int] | None = None  # {"jobs": N} or {"n": N}
    adapt: dict[str, int] | None = None  # {"minimum": A, "maximum": B}


def read_cluster_file(path: str | Path) -> ClusterFile:
    """The cluster file at ``path`` (YAML, so JSON too), checked; raises ClusterFileError listing every mistake."""
    import yaml

    file = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise ClusterFileError(f"cannot read the cluster file: {exc.strerror or exc}", file=file,
                               fix="give the path of a YAML or JSON cluster file") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        raise ClusterFileError(f"not valid YAML/JSON: {getattr(exc, 'problem', None) or exc}", file=file,
                               path=where, fix="correct the syntax") from None
    if not isinstance(data, dict):
        raise ClusterFileError("a cluster file is a mapping with 'type' and optional 'kwargs', 'scale' or "
                               "'adapt'", file=file, fix="e.g. {type: distributed.LocalCluster, scale: {n: 2}}")
    problems: list[Problem] = []
    for key in data:
        if key not in ("type", "kwargs", "scale", "adapt"):
            problems.append(Problem(file, str(key), "unknown field",
                                    "use only 'type', 'kwargs', 'scale' and 'adapt'"))
    type_ = data.get("type")
    if not isinstance(type_, str) or "." not in type_.replace(":", "."):
        problems.append(Problem(file, "type", f"must name a cluster class by import path, got {type_!r}",
                                "e.g. type: distributed.LocalCluster or type: dask_jobqueue.SLURMCluster"))
    kwargs = data.get("kwargs", {})
    if kwargs is None:
        kwargs = {}
    if not isinstance(kwargs, dict) or not all(isinstance(k, str) for k in kwargs):
        problems.append(Problem(file, "kwargs", "must be a mapping of keyword arguments of the cluster class",
                                "e.g. kwargs: {n_workers: 2, threads_per_worker: 1}"))
        kwargs = {}
    scale = _scaling(data, "scale", ("jobs", "n"), exactly_one=True, file=file, problems=problems)
    adapt = _scaling(data, "adapt", ("minimum", "maximum"), exactly_one=False, file=file, problems=problems)
    if scale is not None and adapt is not None:
        problems.append(Problem(file, "adapt", "give either 'scale' or 'adapt', not both",
                                "remove one of them"))
    if adapt is not None and adapt.get("minimum", 0) > adapt.get("maximum", adapt.get("minimum", 0)):
        problems.append(Problem(file, "adapt", f"minimum {adapt['minimum']} is above maximum {adapt['maximum']}",
                                "make minimum <= maximum"))
    if problems:
        raise ClusterFileError(problems)
    assert isinstance(type_, str)  # anything else is one of the problems raised above
    return ClusterFile(file, type_, dict(kwargs), scale, adapt)


def _scaling(data: dict, key: str, names: tuple[str, ...], exactly_one: bool, file: str,
             problems: list[Problem]) -> dict[str, int] | None:
    if data.get(key) is None:
        return None
    value = data[key]
    wanted = " or ".join(names) if exactly_one else " and/or ".join(names)
    example = f"{key}: {{{names[0]}: 4}}" if exactly_one else f"{key}: {{{names[0]}: 1, {names[1]}: 20}}"
    if not isinstance(value, dict) or not value:
        problems.append(Problem(file, key, f"must be a mapping with {wanted}", example))
        return None
    found = True
    for name, number in value.items():
        if name not in names:
            problems.append(Problem(file, f"{key}.{name}", "unknown field", f"use {wanted}"))
            found = False
        elif isinstance(number, bool) or not isinstance(number, int) or number < 0:
            problems.append(Problem(file, f"{key}.{name}", f"must be a whole number >= 0, got {number!r}",
                                    example))
            found = False
    if exactly_one and len(value) != 1:
        problems.append(Problem(file, key, f"give exactly one of {wanted}", example))
        found = False
    return dict(value) if found else None


def import_cluster_class(config: ClusterFile) -> Any:
    """The class (or factory function) ``config.type`` names; raises ClusterFileError naming a missing extra."""
    module_name, _, attr = config.type.replace(":", ".").rpartition(".")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        top = module_name.split(".")[0]
        missing = getattr(exc, "name", None) or top
        fix = (EXTRAS[top] if top in EXTRAS and missing.split(".")[0] == top
               else f"install the package that provides '{module_name}' where cosim runs, or correct the name")
        raise ClusterFileError(f"cannot import '{module_name}': {exc}", file=config.path, path="type",
                               fix=fix) from None
    try:
        cls = getattr(module, attr)
    except AttributeError:
        names = sorted(n for n in dir(module) if n.endswith("Cluster"))
        raise ClusterFileError(f"'{module_name}' has no '{attr}'", file=config.path, path="type",
                               fix=f"cluster classes there: {', '.join(names) or 'none'}") from None
    if not callable(cls):
        raise ClusterFileError(f"'{config.type}' is not a class", file=config.path, path="type",
                               fix="name a Dask cluster class") from None
    return cls


def start_cluster(config: ClusterFile) -> Any:
    """Make the cluster ``config`` names and apply its scale/adapt; the caller closes it.

    A task whose worker dies is re-run once elsewhere
    (``distributed.scheduler.allowed-failures`` = 1 for the scheduler made
    here).  Raises ClusterFileError for an unknown class, keyword arguments
    it refuses, a missing optional extra, or a failing scale/adapt.
    """
    import dask

    cls = import_cluster_class(config)
    kwargs = dict(config.kwargs)
    if "silence_logs" not in kwargs and _accepts(cls, "silence_logs"):
        kwargs["silence_logs"] = logging.CRITICAL  # Dask's own tracebacks (a worker refusing an argument) stay off
    failure = None
    with dask.config.set({"distributed.scheduler.allowed-failures": ALLOWED_FAILURES}), _quiet_dask_logs(), \
            processes_started_here_ignore_ctrl_c():  # a terminal's Ctrl-C is for cosim's client alone
        try:
            cluster = cls(**kwargs)
        except TypeError as exc:
            failure = ClusterFileError(f"{config.type} refused these keyword arguments: {exc}", file=config.path,
                                       path="kwargs", fix=f"use only arguments {config.type} accepts")
        except Exception as exc:
            failure = _start_failure(config, exc)
    if failure is not None:
        # Raised outside the except block, holding no exception, and the half-made cluster collected now: a class
        # that registers its instances for an exit hook (dask-kubernetes' KubeCluster) must not find it at exit
        # and print a traceback trying to close it.
        gc.collect()
        raise failure
    if not hasattr(cluster, "scheduler_address"):
        _close_quietly(cluster)
        raise ClusterFileError(f"{config.type} did not make a Dask cluster (no scheduler_address)",
                               file=config.path, path="type", fix="name a Dask cluster class")
    try:
        if config.scale is not None:
            cluster.scale(**config.scale)
        elif config.adapt is not None:
            cluster.adapt(**config.adapt)
    except Exception as exc:
        _close_quietly(cluster)
        key = "scale" if config.scale is not None else "adapt"
        raise ClusterFileError(f"{config.type} could not {key}: {type(exc).__name__}: {exc}", file=config.path,
                               path=key, fix=f"check '{key}' and that the cluster's job system works") from None
    return cluster


def _start_failure(config: ClusterFile, exc: BaseException) -> ClusterFileError:
    """The error for a cluster class that raised ``exc`` while starting, naming the root cause."""
    cause = _root_cause(exc)  # e.g. "Nanny failed to start" hides the TypeError of a bad worker argument
    if isinstance(cause, OSError):  # refused, timed out, no route: what the class talks to is not reachable
        fix = ("check that what the class connects to is reachable from here (the Kubernetes API server of your "
               "kubeconfig, the job system's host), then run again")
    else:
        fix = ("correct the keyword arguments (or start what the class needs: its job system, its Kubernetes "
               "operator and credentials)")
    return ClusterFileError(f"cannot start {config.type}: {type(cause).__name__}: {cause}", file=config.path,
                            path="kwargs", fix=fix)


def _accepts(cls: Any, name: str) -> bool:
    try:
        return name in inspect.signature(cls).parameters
    except (TypeError, ValueError):
        return False


@contextmanager
def _quiet_dask_logs() -> Iterator[None]:
    """While a cluster starts, its failures are reported once by cosim, not as Dask's tracebacks on the terminal."""
    logging.disable(logging.ERROR)
    try:
        yield
    finally:
        logging.disable(logging.NOTSET)


def _root_cause(exc: BaseException) -> BaseException:
    seen = {id(exc)}
    while (inner := exc.__cause__ or exc.__context__) is not None and id(inner) not in seen:
        seen.add(id(inner))
        exc = inner
    return exc


def _close_quietly(cluster: Any) -> None:
    try:
        cluster.close()
    except Exception:
        pass  # the error that made us close it matters more

