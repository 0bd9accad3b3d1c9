"""An FMU run by itself (``cosim run|validate|inspect model.fmu``): the spec of one unit, as FMPy runs it.

The unit is named by the FMU's model name (renamed as :mod:`cosim.ssp.names` renames SSP names); the experiment
is the FMU's default experiment, completed as FMPy's ``simulate_fmu`` completes it (start 0, stop start + 1 s,
step 10^(round(log10(stop - start)) - 3) s); every output is recorded.  Command-line fields override it.
"""

from __future__ import annotations

import math
import zipfile
from pathlib import Path
from typing import Any, Mapping

from cosim.errors import Problem, SpecError
from cosim.ssp.names import cosim_part


def is_fmu(path: Path) -> bool:
    """True for an ``.fmu`` file (an archive) or a folder holding an extracted FMU's modelDescription.xml."""
    return (path.suffix.lower() == ".fmu" and path.is_file()) or (path / "modelDescription.xml").is_file()


def fmu_raw_spec(path: Path, experiment: Mapping[str, Any] | None = None, inputs: Path | None = None) -> dict[str, Any]:
    """The spec content of the FMU at ``path`` run alone, with ``experiment`` fields (command line) on top;
    ``inputs``, a table in the player's format (a ``time`` column, one column per input: ``u``, ``model.u`` or
    ``u[i]``), is played into the FMU's inputs of those names by a player unit named ``input``.

    Raises SpecError (at the FMU) when its modelDescription.xml cannot be read, and (at the table) when no column
    of ``inputs`` names an input of the FMU."""
    from fmpy import read_model_description

    try:
        md = read_model_description(str(path), validate=False)
    except (OSError, zipfile.BadZipFile, KeyError, ValueError, Exception) as exc:  # fmpy raises bare Exception
        raise SpecError([Problem(str(path), "modelDescription.xml", f"the FMU cannot be read: {exc}",
                                 "give an FMU (a zip archive with modelDescription.xml), e.g. as exported by "
                                 "your modelling tool")]) from None
    default = md.defaultExperiment
    start = float(default.startTime) if default is not None and default.startTime is not None else 0.0
    stop = float(default.stopTime) if default is not None and default.stopTime is not None else start + 1.0
    given = dict(experiment or {})
    start, stop = float(given.get("start", start)), float(given.get("stop", stop))
    if default is not None and default.stepSize is not None:
        step = float(default.stepSize)
    else:  # FMPy's choice for an FMU without one: a thousandth of the duration, rounded to a power of ten
        step = 10 ** (round(math.log10(stop - start)) - 3) if stop > start else 1e-3
    name = cosim_part(md.modelName or path.stem) or "model"
    raw: dict[str, Any] = {"name": md.modelName or path.stem, "units": {name: {"fmu": str(path.resolve())}},
                           "experiment": {"start": start, "stop": stop, "step": step, **given},
                           "record": [f"{name}.*"]}
    if inputs is not None:
        fmu_inputs = {v.name.split("[")[0] for v in md.modelVariables if v.causality == "input"}
        ports = _played_ports(inputs, name)
        played = [p for p in ports if p in fmu_inputs]
        if not played:
            raise SpecError([Problem(str(inputs), "columns", f"no column of the table names an input of "
                                     f"{path.name} (columns: {', '.join(ports[:8]) or 'none'}; inputs: "
                                     f"{', '.join(sorted(fmu_inputs)[:8]) or 'none'})",
                                     "name the columns after the FMU's inputs ('time' first), e.g. time,u")])
        raw["units"]["input"] = {"player": str(inputs.resolve())}
        raw["connections"] = [{"from": f"input.{p}", "to": f"{name}.{p}"} for p in played]
    return raw


def _played_ports(table: Path, unit: str) -> list[str]:
    """The ports a player of ``table`` offers for the unit ``unit``'s inputs: each column but ``time`` by its
    name without ``unit.`` in front, an element ``x[i]`` as its array ``x``, each once."""
    import pandas as pd

    try:
        columns = list(pd.read_parquet(table).columns) if table.suffix.lower() == ".parquet" \
            else list(pd.read_csv(table, nrows=0).columns)
    except (OSError, ValueError) as exc:
        raise SpecError([Problem(str(table), "", f"cannot read the input table: {exc}",
                                 "give a .csv or .parquet table with a 'time' column")]) from None
    ports = [c[len(unit) + 1:] if c.startswith(unit + ".") else c for c in map(str, columns) if c != "time"]
    return list(dict.fromkeys(p.split("[")[0] for p in ports))
