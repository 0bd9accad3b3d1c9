"""The points of one system run one after the other in this process (the child's side), reusing unit instances."""

from __future__ import annotations

import logging
import struct
import time
from typing import Any

from cosim.execution.point_row import PointRow


class PointRunner:
    """Runs points of one system in this process, reusing unit instances between points.

    Units are reset (``fmi2Reset``/``fmi3Reset`` for an FMU) after each point that ended cleanly and reused
    for the next; after a failed point, and for a unit whose spec says ``"reuse": false``, they are made anew.
    A reset is trusted only once checked: the first clean point is run a second time on the reset units, and
    when its objectives differ in any bit from the fresh run's, no unit is reused in this runner again
    (``reset_broken``; logged once).
    """

    def __init__(self, system: Any):
        self.system = system
        self.units: dict[str, Any] | None = None
        self.reset_checked = False
        self.reset_broken = False
        self._fresh_only = {n for n, su in system.units.items() if su.spec.options.get("reuse") is False}
        # checked for FMUs only: a Python unit's reset is its own code, and running a point twice would show
        # in what it counts or writes
        self.reset_checked = any(su.description.kind != "fmu" for su in system.units.values())

    def run(self, point_id: str, values: dict[str, Any], prune: Any = None) -> PointRow:
        """One row for one point: status ok, failed or (with ``prune``, a
        :class:`~cosim.execution.prune.PruneOrder`) pruned, its message, run_time and objectives."""
        from cosim.errors import CosimError, SpecError
        from cosim.execution.point import run_point
        from cosim.execution.prune import PruneBound

        started = time.perf_counter()
        try:
            self._instantiate_missing()
        except Exception as exc:
            self.close()
            cause = str(exc) if isinstance(exc, CosimError) else f"{type(exc).__name__}: {exc}"
            return row_without_result(point_id, "failed", f"cannot instantiate the units: {cause}", started)
        try:
            observers = [PruneBound(self.system, prune.settings, prune.front())] if prune is not None else []
            result = run_point(self.system, values, units=self.units, observers=observers)
        except SpecError as exc:  # raised before the units are touched: they stay fresh for the next point
            return row_without_result(point_id, "failed", "; ".join(p.message for p in exc.problems), started)
        if (result.ok or result.status == "pruned") and not self.reset_broken:  # a clean stop at a point
            self._reset()
            if result.ok and not self.reset_checked and prune is None and self.units is not None:
                self._check_reset(values, result)
        else:
            self.close()  # after a failure, trust no instance's state
        return PointRow.of(point_id, result, time.perf_counter() - started)

    def _instantiate_missing(self) -> None:
        units = self.units if self.units is not None else {}
        for name, su in self.system.units.items():
            if name not in units:
                units[name] = su.unit_type.instantiate(name)
        self.units = dict((n, units[n]) for n in self.system.units)  # the system's order

    def _reset(self) -> None:
        """Reset every unit for the next point; units that opt out are terminated (made anew next time)."""
        assert self.units is not None
        try:
            for name in list(self.units):
                if name in self._fresh_only:
                    self.units.pop(name).terminate()
                else:
                    self.units[name].reset()
        except Exception:
            self.close()  # a unit that cannot reset is instantiated afresh for the next point

    def _check_reset(self, values: dict[str, Any], fresh: Any) -> None:
        """Run the point again on the reset units; a difference in any bit of an objective marks the reset
        broken (every point from now on gets fresh instances)."""
        from cosim.execution.point import run_point

        self.reset_checked = True
        self._instantiate_missing()
        again = run_point(self.system, values, units=self.units)
        same = again.status == fresh.status and list(again.objectives) == list(fresh.objectives) and all(
            struct.pack("<d", float(again.objectives[k])) == struct.pack("<d", float(v))
            for k, v in fresh.objectives.items())
        if same and again.ok:
            self._reset()
            return
        self.reset_broken = True
        logging.getLogger(__name__).warning(
            "note: a point run again on reset units gave other objectives than on fresh units: the units' "
            "reset is not trusted, every point gets fresh instances (set \"reuse\": false on the unit whose "
            "reset is broken to say so in the spec)")
        self.close()

    def close(self) -> None:
        for unit in (self.units or {}).values():
            try:
                unit.terminate()
            except Exception:
                pass  # terminating the others matters more
        self.units = None


def row_without_result(point_id: str, status: str, message: str, started: float) -> PointRow:
    """The row of a point that gave no result (it failed before running, hung or crashed)."""
    return PointRow(point_id, status, message, time.perf_counter() - started)
