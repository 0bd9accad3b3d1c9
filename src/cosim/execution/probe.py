"""The probe of a run: every probed signal of a system read into one float vector per communication point."""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from cosim.system.builder import System
from cosim.units.protocol import NUMERIC_TYPES, Unit


class Probe:
    """Reads every probed signal of the system into one float vector.

    Signals whose values are not floats (String, Binary) or do not fit one
    exactly (64-bit integers) are also read as Python objects by
    :meth:`read_exact`, for the trace recorder; only numbers enter the vector.
    """

    def __init__(self, system: System, units: Mapping[str, Unit]):
        self.columns: list[str] = []
        self.types: dict[str, tuple[str, str | None]] = {}
        self.units: dict[str, str] = {}  # column -> unit of measure, for the recorded table's metadata
        per_unit: dict[str, list[Any]] = {}
        positions: dict[str, list[int]] = {}
        exact: dict[str, list[Any]] = {}
        self.exact_columns: list[str] = []
        for signal in system.probes:
            for ref, column in zip(signal.refs, signal.columns):
                if column in self.types:
                    continue
                variable = signal.variable
                self.types[column] = (variable.type, variable.fmi_type)
                if variable.unit:
                    self.units[column] = variable.unit
                if variable.type not in NUMERIC_TYPES or variable.fmi_type in ("Int64", "UInt64"):
                    exact.setdefault(signal.unit, []).append(ref)
                    self.exact_columns.append(column)
                if variable.type not in NUMERIC_TYPES:
                    continue
                positions.setdefault(signal.unit, []).append(len(self.columns))
                per_unit.setdefault(signal.unit, []).append(ref)
                self.columns.append(column)
        # per unit: its probed elements and their columns (what the native kernel reads itself)
        self.layout = [(name, tuple(refs), list(positions[name])) for name, refs in per_unit.items()]
        self._exact_reads = [(units[name].select(refs), units[name]) for name, refs in exact.items()]
        self.values = np.zeros(len(self.columns))
        self._reads = []
        self._reads_of: dict[str, tuple[Any, ...]] = {}  # unit name -> its read, for read_units
        for name, refs in per_unit.items():
            where = np.array(positions[name], dtype=int)
            contiguous = bool(np.all(np.diff(where) == 1))
            # a contiguous run is written through a slice, cheaper than fancy indexing
            target = slice(int(where[0]), int(where[-1]) + 1) if contiguous else where
            self._reads.append((units[name].reader(units[name].select(refs)), target))
            self._reads_of[name] = self._reads[-1]

    def read(self) -> np.ndarray:
        values = self.values
        for read, where in self._reads:
            values[where] = read()
        return values

    def read_units(self, names: Sequence[str]) -> np.ndarray:
        """The vector with only the columns of the units ``names`` read anew; the others keep the values of the
        last read (an event row: one unit is inside its step, the others are not to be read there)."""
        values = self.values
        for name in names:
            if name in self._reads_of:
                read, where = self._reads_of[name]
                values[where] = read()
        return values

    def read_exact(self) -> list[Any]:
        """The values of ``exact_columns``, as the units give them (str, bytes, int)."""
        out: list[Any] = []
        for selection, unit in self._exact_reads:
            out.extend(unit.get(selection))
        return out
