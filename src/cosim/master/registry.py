"""The one list of master algorithm names: each maps to a class implementing
:class:`~cosim.master.contract.MasterAlgorithm`, made for an experiment."""

from __future__ import annotations

from typing import Any

from cosim.master.adaptive import Adaptive
from cosim.master.algorithms import GaussSeidel, Jacobi, JacobiDelayed
from cosim.master.contract import MasterAlgorithm

ALGORITHMS: dict[str, type[MasterAlgorithm]] = {
    cls.name: cls for cls in (GaussSeidel, Jacobi, JacobiDelayed, Adaptive)}
DEFAULT_ALGORITHM = GaussSeidel.name


def make_algorithm(name: str, experiment: Any) -> MasterAlgorithm:
    """The algorithm called ``name``, made for ``experiment`` (``start``, ``stop``, ``step`` and, for the
    adaptive algorithm, its options); raises ValueError for an unknown name or options that cannot work."""
    try:
        factory = ALGORITHMS[name]
    except KeyError:
        raise ValueError(f"unknown master algorithm '{name}'; use one of {', '.join(ALGORITHMS)}") from None
    return factory(experiment)
