"""Read an SSP's system and flatten it into the content of a spec.json.

:func:`read_ssp` walks the root ``ssd:System``: every ``ssd:Component`` (an
FMU) becomes a unit named by its path below the root system, e.g.
``SuT.edrive_mass``; nested systems only contribute their connectors.  The
steps, one module each, share one :class:`~cosim.ssp.reading.Reading`:

- :mod:`.elements`: systems, components (FMU or CSV table, a player), connectors, unit names; ``implementation``
  and OMSimulator's solvers give a component's interface and solver settings (see :mod:`.annotations`);
- :mod:`.connections`: a chain ``A.y -> system connector -> ... -> B.u`` becomes one connection ``A.y -> B.u``
  whose factor and offset compose unit conversions (:mod:`.measures`) and ``LinearTransformation``s;
- :mod:`.bindings`: parameter bindings (inline or .ssv, ``prefix``, .ssm mappings, parameter connections)
  become unit parameters and start values;
- :mod:`.experiment`: ``DefaultExperiment`` and the step size of OMSimulator's or OSP's annotations; what is
  missing is left to the spec or the command line;
- :mod:`.system_connectors`: what each system connector carries, for naming it in a spec.

Forms tools write against the schema are read with a note (:mod:`.tolerant`).  Every problem is collected
(file in the archive, element path, fix) and raised at the end as one SpecError; nothing else escapes for any
input file.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cosim.errors import SpecError, suggestions_bounded
from cosim.ssp.archive import SspFiles, open_ssp
from cosim.ssp.bindings import Bindings
from cosim.ssp.connections import Flow
from cosim.ssp.elements import components, read_system, unit_names
from cosim.ssp.experiment import note_unread, read_experiment
from cosim.ssp.measures import read_unit_definitions
from cosim.ssp.model import FMU_TYPES, TABLE_TYPES, Node
from cosim.ssp.names import cosim_name, cosim_part, cosim_path
from cosim.ssp.reading import Reading
from cosim.ssp.system_connectors import ConnectorSignal, connector_signals
from cosim.ssp.xml import element_path, forget_positions, tag

__all__ = ["FMU_TYPES", "TABLE_TYPES", "SspSystem", "read_ssp"]


@dataclass
class SspSystem:
    """An SSP read and flattened: ``raw`` is the content of an equivalent spec.json."""

    files: SspFiles
    raw: dict
    notes: list[str]
    system_connectors: list[str] = field(default_factory=list)  # 'Root.sub.connector', for messages
    # 'Root.sub.connector' (and 'sub.connector') -> what it carries (see system_connectors.connector_signals)
    connector_signals: dict[str, ConnectorSignal] = field(default_factory=dict)
    root_system: str = ""
    # 'Root.sub.connector' of every system connector of kind output, in document order (recorded by a run)
    output_connectors: list[str] = field(default_factory=list)
    # the SSP's own dotted names of renamed systems, components and system connectors -> their cosim names
    # (with and without the root system's name; see cosim.ssp.names)
    renamed: dict[str, str] = field(default_factory=dict)
    # unit name (a component's, a system's connectors unit's) -> (file label, element path) of its SSD element,
    # where a problem of the flattened spec is reported (see cosim.ssp.locate)
    elements: dict[str, tuple[str, str]] = field(default_factory=dict)


def read_ssp(path: str | Path, variant: str | None = None) -> SspSystem:
    """Read, check and flatten the SSP at ``path`` (.ssp, folder or .ssd), its SSD of ``variant`` if given (see
    :func:`~cosim.ssp.archive.open_ssp`); raises SpecError."""
    reading = Reading(open_ssp(path, variant))
    try:
        with suggestions_bounded():  # a problem per connection of 10^5 stays linear
            return _read(reading)
    finally:  # also when problems are raised: the notes say what was read as what
        reading.flush_alike()
        forget_positions()


def _read(reading: Reading) -> SspSystem:
    root = reading.parse(reading.files.ssd, reading.label, "ssd")
    if root is None:
        raise SpecError(reading.problems)
    reading.units.update(read_unit_definitions(root))
    system = root.find(tag("ssd", "System"))
    read_system(reading, system, ())
    bindings = Bindings(reading)
    bindings.read(system, ())
    experiment = read_experiment(reading, root)
    _raise_problems(reading)
    names = unit_names(reading)
    _raise_problems(reading)
    units = {names[n.path]: _raw_unit(reading, n) for n in components(reading)}
    note_unread(reading, root)
    flow = Flow(reading)
    connections = flow.connections(names)
    bindings.apply(units, names, flow)
    _raise_problems(reading)
    raw = {"name": root.get("name", reading.files.ssd.stem), "units": units, "connections": connections,
           "experiment": experiment, "record": [f"{name}.*" for name in units]}
    if root.get("description"):
        raw["description"] = root.get("description")
    root_name = cosim_name(system.get("name", ""))
    renamed = _renamed(reading, system.get("name", ""), root_name)
    connectors = [f"{cosim_path((root_name, *n.path))}.{cosim_part(c)}" for n in reading.nodes.values()
                  if n.kind == "system" for c in n.connectors]
    outputs = [f"{cosim_path((root_name, *n.path))}.{cosim_part(name)}" for n in reading.nodes.values()
               if n.kind == "system" for name, c in n.connectors.items() if c.kind == "output"]
    signals = connector_signals(reading, flow, bindings, names, root_name)
    elements = {names[n.path]: (reading.label, element_path(n.element)) for n in components(reading)}
    elements.update({cosim_path((root_name, *n.path)) if root_name else cosim_path(n.path):
                     (reading.label, element_path(n.element)) for n in reading.nodes.values() if n.kind == "system"})
    elements[""] = (reading.label, element_path(system))
    return SspSystem(reading.files, raw, reading.notes, connectors, signals, root_name, outputs, renamed, elements)


def _renamed(reading: Reading, root: str, root_name: str) -> dict[str, str]:
    """Every system, component and system connector whose SSP name is not its cosim name, by its dotted SSP
    name with and without the root system's -> its cosim name; a note per renamed system or connector (the
    components' notes are :func:`~cosim.ssp.elements.unit_names`')."""
    renamed: dict[str, str] = {}
    if root != root_name:
        renamed[root] = root_name
        reading.alike.add("renamed system", f"system '{root}' is called '{root_name}' (names keep ASCII letters, "
                          "digits, _)", f"'{root_name}'", "more systems renamed likewise")
    for node in reading.nodes.values():
        names: list[tuple[tuple[str, ...], tuple[str, ...]]]
        if not node.path:
            names = [((c,), (cosim_part(c),)) for c in node.connectors] if node.kind == "system" else []
        else:
            names = [(node.path, tuple(cosim_name(p) for p in node.path))]
            if node.kind == "system":
                names += [((*node.path, c), (*names[0][1], cosim_part(c))) for c in node.connectors]
        for path, cosim in names:
            ssp, new = ".".join(path), ".".join(cosim)
            if ssp == new:
                continue
            renamed[ssp] = new
            if root:
                renamed[f"{root}.{ssp}"] = f"{root_name}.{new}"
            if node.kind == "system" and path[-1] != cosim[-1]:  # a connector of a renamed system keeps its name
                what = "system" if path == node.path else "connector"
                full, new_full = ".".join((root, *path)), ".".join((root_name, *cosim))
                reading.alike.add(f"renamed {what}", f"{what} '{full}' is called '{new_full}' (names keep ASCII "
                                  "letters, digits, _)", f"'{new_full}'", f"more {what}s renamed likewise")
    return renamed


def _raise_problems(reading: Reading) -> None:
    if reading.problems:
        raise SpecError(reading.problems)


def _raw_unit(reading: Reading, node: Node) -> dict:
    """The spec entry of one component: an FMU unit, or a player of a table component."""
    files = reading.files
    if node.table is not None:
        # every column Real and interpolated linearly, as OMSimulator plays a table
        unit: dict[str, Any] = {"player": files.reference(node.table), "interpolation": "linear", "all_real": True}
        if node.connectors:
            unit["columns"] = list(node.connectors)
        return unit
    assert node.fmu is not None  # a component is a table or an FMU
    return {"fmu": files.reference(node.fmu), **({"interface": node.interface} if node.interface else {}),
            **node.settings, **node.options}
