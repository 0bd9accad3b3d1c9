"""The observers a run of a system has by default: its objectives, its traces (with event rows) and its
``stop_when``; each learns the run's columns when attached (:class:`RunContext`).

Any other :class:`~cosim.master.observers.Observer` passed to :class:`~cosim.execution.run.Execution` runs beside
them, so a study, a test or a plug-in adds what it watches without editing the run.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

from cosim.execution.probe import Probe
from cosim.master.contract import SystemView
from cosim.master.observers import ExactColumns, ObjectiveReducer, TraceRecorder
from cosim.spec.loader import ObjectiveSpec
from cosim.system.builder import System
from cosim.units.protocol import Unit


@dataclass(frozen=True)
class RunContext:
    """What an observer learns of the run it watches (``attached``): the ``system``, the ``live`` units by name,
    the ``view`` the algorithm steps (model-exchange groups as one unit each), the ``probe`` and its exact
    columns (text, bytes and 64-bit integers read as Python objects), if any."""

    system: System
    live: Mapping[str, Unit]
    view: SystemView
    probe: Probe
    exact: ExactColumns | None

    @property
    def columns(self) -> list[str]:
        """The probed numeric columns: the order of the ``values`` every hook receives."""
        return self.probe.columns

    @property
    def types(self) -> dict[str, tuple[str, str | None]]:
        return self.probe.types

    @property
    def units(self) -> dict[str, str]:
        """Column -> unit of measure, where the variable declares one."""
        return self.probe.units


def columns_of(system: System, signal: str | None) -> list[str]:
    """The probe columns of ``signal`` (a probed signal's text, e.g. ``robot.tau``); raises KeyError."""
    for s in system.probes:
        if s.text == signal:
            return list(s.columns)
    raise KeyError(signal)


def reduction_of(objective: ObjectiveSpec) -> str:
    """The reduction of an objective that reduces a signal (the spec's schema requires one with every signal);
    raises KeyError without one, as looking the reduction up would."""
    if objective.reduce is None:
        raise KeyError(objective.reduce)
    return objective.reduce


class Objectives(ObjectiveReducer):
    """The spec's objectives with a signal, reduced at the end of the run (:class:`ObjectiveReducer`, its columns
    taken from the run's probe when attached)."""

    def __init__(self, system: System):  # the reducer itself is made in attached(), once the columns are known
        self.system = system

    def attached(self, context: Any) -> None:
        super().__init__(context.columns, [(o.name, reduction_of(o), columns_of(self.system, o.signal))
                                           for o in self.system.spec.objectives if o.signal])


class Recording(TraceRecorder):
    """The full traces of the spec's recorded signals (:class:`TraceRecorder`), with two rows at every event
    inside a step of the model-exchange units whose spec says ``record_events``."""

    def __init__(self, system: System, capacity: int):
        self.system, self.capacity = system, capacity
        self._hooked: list[Any] = []

    def attached(self, context: Any) -> None:
        probe = context.probe
        super().__init__(probe.columns, self.system.recorded, self.capacity, context.exact, probe.types,
                         probe.units)
        self._hooked = self._hook_events(context.view.units, probe)

    def detached(self) -> None:
        for stepping in self._hooked:
            stepping.on_event = None  # units given by the caller outlive this run
        self._hooked = []

    def _hook_events(self, stepped: Mapping[str, Any], probe: Probe) -> list[Any]:
        """Hook the model-exchange units whose spec says ``record_events`` (or the group integrating them) so
        that every event they handle inside a step adds two rows: their recorded columns just before the event
        and just after it, the other columns as at the last row.  Returns what was hooked."""
        wanted = [name for name, unit in self.system.units.items() if unit.spec.options.get("record_events")]
        by_stepping: dict[int, tuple[Any, list[str]]] = {}
        for name in wanted:
            stepping = stepped.get(name) or next((g for g in stepped.values() if name in getattr(g, "members", {})),
                                                 None)
            if stepping is not None and hasattr(stepping, "on_event"):  # checked by the system: model exchange
                by_stepping.setdefault(id(stepping), (stepping, []))[1].append(name)
        for stepping, names in by_stepping.values():
            def on_event(t: float, phase: str, names: tuple[str, ...] = tuple(names)) -> None:
                self.event(t, probe.read_units(names))
            stepping.on_event = on_event
        return [stepping for stepping, _ in by_stepping.values()]
