"""The signal player: plays a recorded table as outputs.

It reads what ``cosim run --out`` writes (Parquet or CSV, a ``time`` column
and one column per signal, e.g. ``robot.tau[3]``) and offers every column as a
Real output of the same name.  Columns ``x[1]`` .. ``x[n]`` are also offered
as one array output ``x``, so a recorded ``robot.tau`` feeds an FMU's array
input ``tau`` in one connection.  A column recorded as ``unit.port`` is also
offered as plain ``port`` when no other column ends the same way, so a player
named like the recorded unit replaces it by changing one line of a spec.  With it, any unit can be run alone against
signals recorded in the whole system.

A player named like the recorded unit (``"move": {"player": "rec.parquet"}``
over columns ``move.omega``) offers those columns by their port names only
(``omega``), so the spec's ``move.omega`` means the same as before and a
recording of the player again has the column ``move.omega``, not
``move.move.omega``.

Boolean and Integer columns (``cosim run --out`` writes them with their type)
are played as Boolean and Integer outputs, always holding the last sample, so a
recorded ``finished`` flag can end a replayed run (``stop_when``).  Columns that
are not numbers (String, Binary) are not played.

Interpolation between samples: ``linear`` (default), ``hold`` (the last
sample at or before t) or ``nearest``.  Beyond the recorded range:
``hold`` the end values (default) or ``error``.

Units of measure: a Parquet table written by ``cosim run --out`` carries
the recorded signals' units in its metadata; the spec may give or override
them per column, alias or array (``"units": {"speed": "rpm"}``; a CSV table
has none); an element ``x[2]`` has the unit of its array ``x`` unless given its own.  Connections then convert them
like an FMU's (see :mod:`cosim.util.quantities`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from cosim.units.kind import UnitKind, UnitSpec
from cosim.units.protocol import (
    ElementRef,
    Selection,
    Unit,
    UnitDescription,
    UnitError,
    UnitType,
    Variable,
    indexed_runs,
    parse_port,
)
from cosim.util.archive import MEMBER_SEPARATOR, member_file

INTERPOLATIONS = ("linear", "hold", "nearest")


def read_table(path: str | Path) -> Any:
    """A recorded table as a pandas DataFrame (Parquet or CSV by extension).

    Raises FileNotFoundError for a missing file and ValueError when the table
    has no numeric 'time' column or time does not increase.
    """
    import pandas as pd

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such file: {path}")
    if path.suffix.lower() == ".csv":
        separator = csv_separator_line(path)  # "sep=," first (Excel's hint; OMSimulator's result CSVs): skipped
        frame = pd.read_csv(path, skiprows=1, sep=separator) if separator else pd.read_csv(path)
    else:
        frame = pd.read_parquet(path)
    if "time" not in frame.columns:
        raise ValueError(f"{path} has no 'time' column; columns: {', '.join(map(str, frame.columns[:8]))}")
    time = frame["time"].to_numpy(dtype=float)
    if len(time) == 0 or np.any(np.diff(time) < 0):
        raise ValueError(f"{path}: 'time' must be non-empty and non-decreasing")
    return frame


def csv_separator_line(path: str | Path) -> str | None:
    """The separator a CSV's first line ``sep=X`` (or ``"sep=X"``) declares, None when it has no such line."""
    with open(path, encoding="utf-8", errors="replace") as stream:
        first = stream.readline().strip().strip('"')
    return first[4] if len(first) == 5 and first.lower().startswith("sep=") else None


def _is_numeric(column: Any) -> bool:
    import pandas as pd

    return bool(pd.api.types.is_numeric_dtype(column) or pd.api.types.is_bool_dtype(column))


def _is_bool(column: Any) -> bool:
    import pandas as pd

    return bool(pd.api.types.is_bool_dtype(column))


def _typed(value: float, kind: str) -> Any:
    """A played sample as its recorded type."""
    if kind == "Boolean":
        return bool(value)
    if kind == "Integer":
        return int(round(value))
    return float(value)


class _IndexSelection(Selection):
    def __init__(self, refs: Sequence[ElementRef], columns: np.ndarray, kinds: Sequence[str]):
        self.refs = tuple(refs)
        self.columns = columns
        self.kinds = list(kinds) if any(k != "Real" for k in kinds) else None  # None: all Real, no conversion


class PlayerUnitType(UnitType):
    """Blueprint of a signal player over the table at ``path``."""

    def __init__(self, path: str | Path, columns: Sequence[str] | None = None, interpolation: str = "linear",
                 extrapolation: str = "hold", units: dict[str, str] | None = None, unit_name: str | None = None,
                 all_real: bool = False):
        if interpolation not in INTERPOLATIONS:
            raise ValueError(f"interpolation '{interpolation}' is not one of {', '.join(INTERPOLATIONS)}")
        self.path = str(path)
        self.columns = list(columns) if columns else None
        self.interpolation = interpolation
        self.extrapolation = extrapolation
        self.units = dict(units or {})
        self._recorded_units: dict[str, str] = {}
        self.unit_name = unit_name  # the spec's name of this player: its own columns 'name.port' are offered as 'port'
        self.all_real = all_real  # every column Real (interpolated), whatever its recorded type: SSP table components
        self._table: tuple[np.ndarray, np.ndarray, list[str]] | None = None
        self._kinds: list[str] = []
        self._aliases: dict[str, str] | None = None

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_table"] = state["_aliases"] = None
        return state

    def files(self) -> list[Path]:
        return [Path(self.path)]

    def relocate(self, copies: Sequence[Path]) -> None:
        self.path = str(copies[0])

    def table(self) -> tuple[np.ndarray, np.ndarray, list[str]]:
        """(time, values[samples, columns], column names); raises as :func:`read_table`."""
        if self._table is None:
            frame = read_table(self.path)
            # A player plays numbers: String and Binary (hex) columns of a recorded table are left out
            # unless named in 'columns', where they are refused.
            numeric = [str(c) for c in frame.columns if c != "time" and _is_numeric(frame[c])]
            names = self.columns or numeric
            missing = [c for c in names if c not in frame.columns]
            if missing:
                raise ValueError(f"{self.path} has no column(s) {', '.join(missing)}")
            not_numbers = [c for c in names if c not in numeric]
            if not_numbers:
                raise ValueError(f"{self.path}: column(s) {', '.join(not_numbers)} are not numbers (a player plays "
                                 "numeric and Boolean columns only); leave them out of 'columns'")
            self._kinds = ["Real" if self.all_real else "Boolean" if _is_bool(frame[c]) else
                           "Integer" if np.issubdtype(frame[c].dtype, np.integer) else "Real" for c in names]
            self._table = (frame["time"].to_numpy(dtype=float), frame[names].to_numpy(dtype=float), names)
            # units written by 'cosim run --out' into a Parquet table's metadata (CSV has none)
            self._recorded_units = dict(frame.attrs.get("units") or {})
        return self._table

    def kinds(self) -> list[str]:
        """The type of each played column as recorded: Real, Integer or Boolean."""
        self.table()
        return self._kinds

    def aliases(self) -> dict[str, str]:
        """Port name -> recorded column, for the ports not named like their column (computed once).

        The player's own columns ``<unit_name>.port`` are offered as ``port`` (only); of the other columns
        ``unit.port``, those whose ``port`` is unique are offered as ``port`` too.
        """
        if self._aliases is None:
            _, _, names = self.table()
            own = f"{self.unit_name}." if self.unit_name else None
            aliases = {n[len(own):]: n for n in names if own and n.startswith(own)}
            short: dict[str, list[str]] = {}
            for n in names:
                if "." in n and not (own and n.startswith(own)):
                    short.setdefault(n.split(".", 1)[1], []).append(n)
            aliases |= {k: v[0] for k, v in short.items() if len(v) == 1 and k not in names and k not in aliases}
            self._aliases = aliases
        return self._aliases

    def port_names(self) -> list[str]:
        """Every scalar port the player offers (arrays x of x[1]..x[n] come on top)."""
        _, _, columns = self.table()
        own = f"{self.unit_name}." if self.unit_name else None
        return [c for c in columns if not (own and c.startswith(own))] + list(self.aliases())

    def describe(self) -> UnitDescription:
        _, values, columns = self.table()
        aliases = self.aliases()
        names = self.port_names()
        index = {n: i for i, n in enumerate(columns)} | {a: columns.index(c) for a, c in aliases.items()}
        kinds = self.kinds()
        runs = indexed_runs(names)
        unknown = sorted(set(self.units) - set(names) - set(runs))
        if unknown:
            raise ValueError(f"'units' names {', '.join(unknown)}, not played by {self.path}; "
                             f"played: {', '.join(names[:8])}{' ...' if len(names) > 8 else ''}")
        variables = [Variable(n, "output", kinds[index[n]], unit=self._unit_of(n),
                              start=_typed(values[0, index[n]], kinds[index[n]]),
                              description=f"played from {self.path}") for n in names]
        for base, members in runs.items():
            member_kinds = {kinds[index[m]] for m in members}
            variables.append(Variable(base, "output", member_kinds.pop() if len(member_kinds) == 1 else "Real",
                                      unit=self._unit_of(base), shape=(len(members),),
                                      description=f"array of {base}[1..{len(members)}] played from {self.path}"))
        return UnitDescription(name=Path(self.path).name, variables=tuple(variables), kind="player",
                               feedthrough={v.name: () for v in variables}, source=self.path)

    def _unit_of(self, name: str) -> str | None:
        """The spec's unit for a column, alias or array (an element has its array's), else the recorded one."""
        if name in self.units:
            return self.units[name]
        base, index = parse_port(name)
        if index is not None and base in self.units:
            return self.units[base]
        column = self.aliases().get(name, name)
        recorded = self._recorded_units.get(column)
        if recorded is None and column not in self.table()[2]:  # an array: its first element's recorded unit
            recorded = self._recorded_units.get(f"{self.aliases().get(f'{name}[1]', f'{name}[1]')}")
        return recorded

    def column_index(self, ref: ElementRef) -> int:
        """The table column of one element (scalar column, alias, or array element)."""
        _, _, names = self.table()
        aliases = self.aliases()
        name = ref.variable
        if name not in names and name not in aliases:
            name = f"{ref.variable}[{ref.offset + 1}]"
        return names.index(aliases.get(name, name))

    def instantiate(self, name: str) -> Unit:
        return PlayerUnit(name, self)


class PlayerUnit(Unit):
    """A live player: outputs follow the table at the current time."""

    def __init__(self, name: str, unit_type: PlayerUnitType):
        self.name = name
        self.unit_type = unit_type
        self.description = unit_type.describe()
        self.time_points, self.values, _ = unit_type.table()
        self.discrete = np.array([k != "Real" for k in unit_type.kinds()], dtype=bool)  # always held, never blended
        self.current = self.values[0].copy()
        self.t = float(self.time_points[0])

    def select(self, refs: Sequence[ElementRef]) -> Selection:
        columns = np.array([self.unit_type.column_index(r) for r in refs], dtype=int)
        kinds = self.unit_type.kinds()
        return _IndexSelection(refs, columns, [kinds[c] for c in columns])

    def get(self, selection: Selection) -> list[Any]:
        # attr-defined: the protocol hands back the Selection this unit's select() made, an _IndexSelection
        values: list[Any] = self.current[selection.columns].tolist()  # type: ignore[attr-defined]
        if selection.kinds is None:  # type: ignore[attr-defined]  # (as above)
            return values
        return [_typed(v, k) for v, k in zip(values, selection.kinds)]  # type: ignore[attr-defined]  # (as above)

    def set(self, selection: Selection, values: Sequence[Any]) -> None:
        raise UnitError(self.name, "a signal player has only outputs; nothing can be set", self.t)

    def setup(self, start_time: float, stop_time: float | None) -> None:
        self.t = start_time
        first, last = self.time_points[0], self.time_points[-1]
        if self.unit_type.extrapolation == "error" and (start_time < first or (stop_time or first) > last):
            raise UnitError(self.name, f"the run [{start_time:g}, {stop_time}] leaves the recorded time range "
                                       f"[{first:g}, {last:g}] of {self.unit_type.path}", start_time)
        self.current = self._at(start_time)

    def enter_initialization(self) -> None:
        pass

    def exit_initialization(self) -> None:
        pass

    def do_step(self, t: float, h: float) -> None:
        self.t = t + h
        self.current = self._at(self.t)

    def reset(self) -> None:
        self.current = self.values[0].copy()

    def terminate(self) -> None:
        pass

    def _at(self, t: float) -> np.ndarray:
        times, values = self.time_points, self.values
        mode = self.unit_type.interpolation
        # rows are taken as values[i, :]: numpy's stubs type values[i] as Any, values[i, :] as the array it is
        if len(times) == 1 or t <= times[0]:
            return values[0, :].copy()
        if t >= times[-1]:
            return values[-1, :].copy()
        # searchsorted 'right' so that at a sample time with repeated times
        # (an event) we take the value after the event.
        i = int(np.searchsorted(times, t, side="right")) - 1
        if mode == "hold":
            return values[i, :].copy()
        t0, t1 = times[i], times[i + 1]
        if mode == "nearest":
            nearest = values[i if t - t0 <= t1 - t else i + 1, :].copy()
            nearest[self.discrete] = values[i][self.discrete]
            return nearest
        w = (t - t0) / (t1 - t0)
        blended: np.ndarray = (1.0 - w) * values[i, :] + w * values[i + 1, :]
        if self.discrete.any():
            blended[self.discrete] = values[i][self.discrete]
        return blended


# -- the player unit kind ------------------------------------------------------------------------------


def _relative(source: str, folder: str) -> Path:
    if MEMBER_SEPARATOR in source:  # a table inside an SSP archive (an SSP's CSV component), as resolve_fmu_path
        return member_file(source)
    path = Path(source)
    return path if path.is_absolute() else Path(folder) / path


def _create_player(spec: UnitSpec, folder: str) -> PlayerUnitType:
    o = spec.options
    return PlayerUnitType(_relative(spec.source, folder), o.get("columns"), o.get("interpolation", "linear"),
                          o.get("extrapolation", "hold"), o.get("units"), unit_name=spec.name,
                          all_real=o.get("all_real", False))


KIND = UnitKind("player", {
    "player": {"type": "string", "description": "A recorded table (.parquet or .csv, as written by 'cosim run "
                                                "--out') played back as outputs."},
    "columns": {"type": "array", "items": {"type": "string"},
                "description": "player only: the columns to play (default: all but 'time')."},
    "interpolation": {"enum": ["linear", "hold", "nearest"],
                      "description": "player only: how values between samples are found."},
    "extrapolation": {"enum": ["hold", "error"],
                      "description": "player only: beyond the recorded time range, hold the end values or fail."},
    "units": {"type": "object", "additionalProperties": {"type": "string"},
              "description": "player only: unit of measure of played columns or arrays, e.g. {\"speed\": \"rpm\"}."},
    "all_real": {"type": "boolean",
                 "description": "player only: play every column as Real (interpolated), whatever its recorded type "
                                "(a CSV column of whole numbers reads as Integer, held). An SSP's table component "
                                "is played so."},
}, _create_player, example='"player": "traces.parquet"', description="recorded signals played back", replays=True)
