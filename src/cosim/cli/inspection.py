"""``cosim inspect``: the ports of a unit, whatever it is, or of every unit of a spec.

A target is an FMU (``model.fmu``, ``builtin:NAME_fmi3``), a Python unit (``file.py:Class``,
``package.module:Class``), a recorded table a player would play (``.parquet``/``.csv``) or a spec.json. Every
port is listed with its causality, type, shape, unit, start value and range, so that the names the error
messages mention ("no variable 'x'; run cosim inspect") can be looked up.  An SSP (``.ssp``, ``.ssd`` or a
folder with SystemStructure.ssd) is inspected like a spec, without needing a stop time or step size; the start
column shows the values the SSP (or spec) binds, marked ``*``, instead of the unit's own.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

from cosim.cli.exit_codes import EXIT_OK
from cosim.errors import SpecError, UsageError
from cosim.units.protocol import UnitDescription, UnitType

HEADER = ("name", "causality", "type", "shape", "unit", "start", "range", "description")


def unit_type_of(target: str) -> UnitType:
    """The blueprint of the unit ``target`` names (FMU, Python class or recorded table).

    Raises UsageError when the target names nothing cosim can load, with what it expected.
    """
    from cosim.units.fmu.description import FmuUnitType
    from cosim.units.fmu.kind import resolve_fmu_path
    from cosim.units.player import PlayerUnitType
    from cosim.units.python.unit import PythonUnitType

    suffix = Path(target).suffix.lower()
    try:
        if suffix == ".fmu" or target.startswith("builtin:"):
            return FmuUnitType(resolve_fmu_path(target), target)
        if suffix in (".parquet", ".csv"):
            unit_type: UnitType = PlayerUnitType(target)
        elif ":" in target:
            module = target.rpartition(":")[0]
            base = Path(module).parent if module.endswith(".py") else Path.cwd()
            unit_type = PythonUnitType(target, base_dir=str(base.resolve()))
        else:
            raise UsageError(f"'{target}' is not something cosim inspect knows: give a spec.json, a model.fmu or "
                             "builtin:NAME_fmi3, a Python unit file.py:Class or package.module:Class, or a "
                             "recorded .parquet/.csv table")
        unit_type.describe()  # load it now, so that a missing file or class is reported here
        return unit_type
    except (FileNotFoundError, ImportError, ValueError, TypeError) as exc:
        raise UsageError(f"cannot inspect '{target}': {exc}") from None


def listed_variables(description: UnitDescription) -> list:
    """The ports to show: scalars x[1]..x[n] that are also offered as the array x (an FMI 2.0 FMU's, a
    player's columns) are left out, and so are local variables."""
    arrays = {v.name for v in description.variables if v.is_array}
    return [v for v in description.variables
            if v.causality != "local" and not (not v.is_array and v.name.split("[")[0] in arrays)]


def port_rows(description: UnitDescription, bound: dict[str, Any] | None = None) -> list[tuple[str, ...]]:
    """One row per port (HEADER's columns); a port in ``bound`` (the value a spec or SSP sets) shows that
    value, marked ``*``, in the start column instead of the unit's own start."""
    rows: list[tuple[str, ...]] = []
    bound = bound or {}
    for v in listed_variables(description):
        shape = "x".join(map(str, v.shape)) if v.shape else "scalar"
        rng = "" if v.min is None and v.max is None else f"[{_fmt(v.min) or '-inf'}, {_fmt(v.max) or 'inf'}]"
        start = f"{_fmt(bound[v.name])} *" if v.name in bound else _fmt(v.start)
        rows.append((v.name, v.causality, v.fmi_type or v.type, shape, v.unit or "",
                     start, rng, shorten(v.description, DESCRIPTION_WIDTH)))
    return rows


DESCRIPTION_WIDTH = 60  # the description column's width: a table row stays on one line of a wide terminal


def shorten(text: str, width: int) -> str:
    """``text`` on one line, at most ``width`` characters; a longer text is cut at the last word boundary that
    fits and ends with "...", never in the middle of a word (issue 39: "the joint's torq" read as a typo).
    A first word longer than ``width`` is the only one cut, since nothing shorter would say anything."""
    text = " ".join(text.split())
    if len(text) <= width:
        return text
    room = width - len("...")
    cut = text.rfind(" ", 0, room + 1)
    head = text[:cut] if cut > 0 else text[:room]
    return head.rstrip(" ,;:.-") + "..."


def print_table(rows: list[tuple[str, ...]], indent: str = "  ", out: Callable[[str], Any] = print) -> None:
    table = [HEADER, *rows]
    widths = [max(len(r[i]) for r in table) for i in range(len(HEADER))]
    for row in table:
        out(indent + "  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip())


def inspect_unit(target: str) -> int:
    """Print the ports of one unit; returns the exit code."""
    from cosim.units.fmu.description import FmuUnitType, offered_interfaces  # imported when used: fmpy is heavy

    unit_type = unit_type_of(target)
    d = unit_type.describe()
    offered: tuple[str, ...] = ()
    fmu_type = unit_type if isinstance(unit_type, FmuUnitType) else None  # an FMU's (d.kind == "fmu")
    if fmu_type is not None:
        offered = offered_interfaces(fmu_type.model_description())
    kind = {"fmu": f"FMI {d.fmi_version} {' and '.join(offered)} FMU", "python": "Python unit",
            "player": "player of a recorded table"}.get(d.kind, d.kind)
    print(f"{target}: {d.name}, {kind}" + (f", default step {d.default_step:g} s" if d.default_step else ""))
    if fmu_type is not None and len(offered) > 1:
        print(f"  runs as {fmu_type.interface} unless the spec's unit sets \"interface\": \"model-exchange\"")
    if d.description:
        print(f"  {d.description}")
    if fmu_type is not None and getattr(fmu_type.model_description().coSimulation, "needsExecutionTool", False):
        print("  needsExecutionTool: the FMU drives its exporting tool, which must be installed and licensed "
              "on every machine that runs it (also every Dask worker)")
    print_table(port_rows(d))
    return EXIT_OK


def inspect_spec(path: str, experiment: dict[str, Any] | None = None, variant: str | None = None) -> int:
    """Print a spec's (or an SSP's) units with their ports, its connections and stepping order; returns the exit
    code. ``experiment`` overrides the experiment's fields (what an SSP often lacks)."""
    from cosim.ssp.reading import held_notes

    with held_notes() as notes:  # printed below as note: lines, each once (logged, they would show twice)
        return _inspect_spec(path, experiment, variant, notes)


def _inspect_spec(path: str, experiment: dict[str, Any] | None, variant: str | None, notes: list[str]) -> int:
    from cosim.spec.loader import read_raw
    from cosim.ssp import is_ssp, read_ssp
    from cosim.system.validate import check_spec

    experiment = dict(experiment or {})
    ssp = read_ssp(path, variant) if is_ssp(path) else None
    # inspecting needs neither stop time nor step size (an SSP, or a spec on one, often lacks them): stand-ins,
    # said as such below
    raw = ssp.raw if ssp is not None else read_raw(path, None, variant)
    known = raw.get("experiment") if isinstance(raw, dict) else None
    missing: list[str] = []
    if isinstance(known, dict) and ssp is None:  # an SSP alone runs with OMSimulator's defaults (cosim.ssp)
        given = {**known, **experiment}
        missing = [k for k in ("stop", "step") if k not in given]
        start = given.get("start", 0.0)
        start = float(start) if isinstance(start, (int, float)) else 0.0
        stop = given.get("stop")
        if "stop" in missing:
            experiment["stop"] = stop = start + 1.0
        if "step" in missing:
            experiment["step"] = float(stop) - start if isinstance(stop, (int, float)) and stop > start else 1.0
    try:
        system = check_spec(path, experiment or None, variant)
    except SpecError:
        if ssp is None:
            print_units_that_load(path, raw)  # what can be listed is listed; the problems follow (exit 2)
        raise
    print(f"spec {path}: {system.spec.name}")
    if ssp is not None and len(ssp.files.variants) > 1:
        print("variants: " + ", ".join(f"{name} ({Path(p).name}{', shown' if name == ssp.files.variant else ''})"
                                       for name, p in ssp.files.variants.items()))
    for note in dict.fromkeys([*(ssp.notes if ssp is not None else []), *notes]):
        print(f"note: {note}")
    marked = False
    for name, unit in system.units.items():
        d = unit.description
        kind = f"FMI {d.fmi_version}" if d.kind == "fmu" else d.kind
        if d.kind == "fmu" and getattr(unit.unit_type, "interface", None) == "model-exchange":  # an FMU type's
            kind += " model-exchange"  # co-simulation, the usual case, goes without saying
        ports = listed_variables(d)  # FMI 2.0 scalars x[1]..x[n] count once, as their array x
        inputs = sum(v.causality == "input" for v in ports)
        outputs = sum(v.causality == "output" for v in ports)
        print(f"unit {name}: {kind} {unit.spec.source} ({inputs} inputs, {outputs} outputs)")
        own = {v.name: v for v in d.variables}
        bound = {unit.variable_name(k): v for k, v in {**unit.spec.parameters, **unit.spec.start}.items()}
        bound = {k: v for k, v in bound.items() if k in own}
        marked = marked or bool(bound)
        print_table(port_rows(d, bound))
    print("connections:")
    for c in system.connections:
        scaled = f" (x {c.factor:.17g} + {c.offset:.17g})" if c.transforms else ""
        print(f"  {c.source.text} -> {c.target.text}{scaled}")
    if marked:
        print("* the value the spec or SSP sets (the unit's own start value is replaced)")
    exp = system.spec.experiment
    stop = "(no stop time: give --stop to run)" if "stop" in missing else f"{exp.stop:g} s"
    step = "(none: give --step to run)" if "step" in missing else f"{exp.step:g} s"
    print(f"experiment: {exp.start:g} .. {stop}, step {step}, {exp.algorithm}")
    print(f"kernel: {system.kernel.describe()}")  # native (compiled loop) or python, and why not native
    groups = system.model_exchange.groups
    print(f"stepping order: {' -> '.join(system.model_exchange.order if groups else system.order)}")
    for group in groups:  # connected model-exchange units: one solver, one unit to the master
        print(f"integrated together (one solver): {group.name} = {', '.join(group.members)}")
    print_coupling(system)
    print_bounds(system)
    return EXIT_OK


def print_bounds(system: Any) -> None:
    """Per objective, which way its value can move while a design runs (what --prune may rely on), and why."""
    from cosim.spec.bounds import system_bounds

    bounds = system_bounds(system)
    if not bounds:
        return
    print("objective bounds while a design runs (--prune):")
    width = max(len(name) for name in bounds)
    for name, b in bounds.items():
        print(f"  {name:<{width}}  {b.direction or 'unbounded':<15}  {b.why}")


def print_units_that_load(path: str, raw: Any) -> None:
    """For a spec with problems: the ports of each unit that loads on its own, and which units do not.

    ``cosim validate``'s advice to inspect the spec is then no dead end: the variables a misspelt parameter
    or connection should name are listed, while the problems (printed after this) say what to fix."""
    from cosim.errors import CosimError
    from cosim.spec.loader import build_spec
    from cosim.system.builder import make_unit_type

    units = raw.get("units") if isinstance(raw, dict) else None
    if not isinstance(units, dict) or not units:
        print(f"spec {path}: no units to list (the problems follow)")
        return
    print(f"spec {path} has problems (listed after its units); the units that load on their own:")
    for name, entry in units.items():
        try:
            alone = build_spec({"units": {name: entry}, "experiment": {"stop": 1.0, "step": 1.0}}, Path(path))
            unit_spec = alone.units[0]
            d = make_unit_type(unit_spec, alone.folder).describe()
        except (CosimError, OSError, ValueError, TypeError, KeyError, IndexError, AttributeError) as exc:
            reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            print(f"unit {name}: does not load ({reason[:200]})")
            continue
        kind = f"FMI {d.fmi_version}" if d.kind == "fmu" else d.kind
        print(f"unit {name}: {kind} {unit_spec.source}")
        print_table(port_rows(d))
    print("connections, stepping order and loops: not shown until the problems below are fixed")


def print_coupling(system: Any) -> None:
    """The system's direct feed-through inputs in dependency order, and its algebraic loops with their tearing
    variables (what the master sets and solves at each communication point)."""
    from cosim.master.loops import Loop
    from cosim.system.stepping import assumed_feedthrough

    coupling = system.coupling
    feeds = [system.connections[block[0]].target for block in coupling.blocks if not isinstance(block, Loop)]
    if feeds:
        names = dict.fromkeys(f"{s.unit}.{s.variable.name}" for s in feeds)
        print(f"direct feed-through inputs, in dependency order: {', '.join(names)}")
    settings = coupling.settings
    if not coupling.loops:
        print("algebraic loops: none")
        return
    print(f"algebraic loops: {len(coupling.loops)} (solved by {settings.method}, tolerance {settings.tolerance:g}, "
          f"at most {settings.max_iterations} iterations)")
    for loop in coupling.loops:
        values = sum(len(system.connections[i].target.refs) for i in loop.torn)
        print(f"  loop through units {', '.join(loop.units)}: tearing {', '.join(loop.tearing)} "
              f"({values} value{'' if values == 1 else 's'}); ports {', '.join(loop.ports)}")
        group = next((g.name for g in system.model_exchange.groups if set(loop.units) <= set(g.members)), None)
        if group is not None:
            from cosim.master.coupled_me import GROUP_LOOP_TOLERANCE

            print(f"    solved inside {group} at every evaluation of its equations (tolerance "
                  f"{min(settings.tolerance, GROUP_LOOP_TOLERANCE):g}), not only at communication points")
        assumed = assumed_feedthrough(system.units, loop)
        if assumed:
            print(f"    note: unit(s) {', '.join(assumed)} declare no dependencies for their outputs, so every "
                  "output is assumed to depend directly on every input; if one does not, declare it in the spec "
                  '("feedthrough": {"<output>": []})')


def inspect_target(target: str, experiment: dict[str, Any] | None = None, variant: str | None = None) -> int:
    """``cosim inspect TARGET``: a spec (``.json``) or SSP (``.ssp``, ``.ssd``, a folder with SystemStructure.ssd),
    or any one unit."""
    from cosim.ssp import is_ssp

    if Path(target).suffix.lower() == ".json" or is_ssp(target):
        return inspect_spec(target, experiment, variant)
    if variant is not None:
        raise UsageError(f"--variant {variant}: only an SSP has variants, and '{target}' is none")
    return inspect_unit(target)


def _fmt(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bytes):
        return value.hex() or '""'  # FMI 3.0 Binary: the bytes in hex, as the trace columns hold them
    if isinstance(value, (tuple, list)):
        return "(" + ", ".join(_fmt(v) for v in value[:4]) + (", ..." if len(value) > 4 else "") + ")"
    return f"{value:g}" if isinstance(value, float) else str(value)
