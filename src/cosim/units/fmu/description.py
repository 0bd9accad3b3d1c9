"""FMU units: reading, checking and extracting an FMU, for FMI 2.0 and 3.0.

:class:`FmuUnitType` is the picklable blueprint.  It reads the
modelDescription.xml once (through fmpy), reports *every* reason the FMU cannot
be used at once (:class:`FmuProblems`), describes its variables in the common
:mod:`cosim.units.protocol` terms and extracts the archive once per process.  The
live instances are in :mod:`.fmi2` and :mod:`.fmi3`, one module per FMI version,
and in :mod:`.model_exchange` for Model Exchange FMUs (integrated by CVode).

FMI 2.0 has no arrays; tools export an array ``x`` as scalars ``x[1]`` ..
``x[n]``.  Such a contiguous run of indexed scalars (same causality and type)
is *also* offered as an array variable ``x`` so that an FMI 2.0 FMU and an
FMI 3.0 FMU (or a Python unit) with an array port ``x`` are interchangeable.
"""

from __future__ import annotations

import math
import os
import platform
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

from cosim.errors import FmuProblems, Problem
from cosim.units.protocol import Unit, UnitDescription, UnitType, Variable, indexed_runs, parse_port
from cosim.util.archive import ArchiveError, ExtractionCache, check_archive, extract_to_new_folder
from cosim.util.digest import file_digest
from cosim.util.quantities import fmi_unit_definitions

_FMI3_TYPE = {
    "Float64": "Real", "Float32": "Real",
    "Int8": "Integer", "UInt8": "Integer", "Int16": "Integer", "UInt16": "Integer",
    "Int32": "Integer", "UInt32": "Integer", "Int64": "Integer", "UInt64": "Integer",
    "Enumeration": "Integer", "Boolean": "Boolean", "String": "String", "Binary": "Binary", "Clock": "Clock",
    "Real": "Real", "Integer": "Integer",
}


_REEXPORT = "re-export the FMU from its tool"


@dataclass(frozen=True)
class FmiElement:
    """Where one scalar element lives in the FMU: FMI type and value reference.

    For FMI 3.0 arrays, ``index`` is the element's offset in the array
    (the array is read whole); for scalars it is 0 and ``size`` is 1.
    """

    fmi_type: str
    value_reference: int
    index: int = 0
    size: int = 1


def platform_folders() -> tuple[str, str]:
    """The FMI 2.0 and FMI 3.0 binaries folder names of this machine."""
    system = {"Linux": "linux", "Darwin": "darwin", "Windows": "win"}.get(platform.system(), "linux")
    machine = platform.machine().lower()
    bits = "64" if machine in ("x86_64", "amd64", "aarch64", "arm64") else "32"
    arch = {"amd64": "x86_64", "arm64": "aarch64"}.get(machine, machine)
    return f"{system}{bits}", f"{arch}-{system}"


def shared_library_suffix() -> str:
    return {"Linux": ".so", "Darwin": ".dylib", "Windows": ".dll"}.get(platform.system(), ".so")


def safe_extract(archive: str | Path, target: str | Path) -> None:
    """Extract an FMU within the archive rules and limits (see :mod:`cosim.util.archive`).

    Raises FmuProblems (a user error) naming the FMU, the member and the rule
    or limit it breaks; the target folder is then removed.
    """
    try:
        extract_to_new_folder(archive, target)
    except ArchiveError as exc:
        raise FmuProblems(str(archive), exc.problems) from None


def model_identifier_problem(archive: str, identifier: Any) -> Problem | None:
    """Why ``identifier`` cannot name the FMU's library, or None.

    The library is looked up as ``binaries/<platform>/<modelIdentifier>.so``
    inside the extracted FMU; an identifier with a path in it (absolute, with
    ``/``, ``\\`` or ``..``) would make the FMU load a library from anywhere
    on the machine.
    """
    text = str(identifier or "")
    if re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.+-]*", text) and ".." not in text:
        return None
    return Problem(archive, "modelDescription.xml", f"modelIdentifier '{text[:80]}' is not a plain file name "
                   "(letters, digits, '_', '.', '-', no path); it names the library inside binaries/<platform>/ "
                   "of the FMU, and cosim loads nothing from outside the FMU",
                   "re-export the FMU with a plain modelIdentifier")


EXTRACTED = ExtractionCache("fmu", safe_extract)  # one unpacked copy of each FMU per process


CO_SIMULATION, MODEL_EXCHANGE = "co-simulation", "model-exchange"
INTERFACES = (CO_SIMULATION, MODEL_EXCHANGE)  # as a spec's "interface" names them


def offered_interfaces(md: Any) -> tuple[str, ...]:
    """The interfaces an FMU's model description offers, co-simulation first."""
    return tuple(i for i, part in ((CO_SIMULATION, md.coSimulation), (MODEL_EXCHANGE, md.modelExchange)) if part)


class FmuUnitType(UnitType):
    """Blueprint of an FMU unit (FMI 2.0 or 3.0, co-simulation or Model Exchange).

    ``interface`` (``"co-simulation"`` or ``"model-exchange"``) chooses how
    the FMU runs; ``None`` means co-simulation when the FMU offers it, else
    Model Exchange.  ``solver_settings`` (a
    :class:`~cosim.units.fmu.model_exchange.SolverSettings`) configure the
    integrator of a Model Exchange unit; they are refused for co-simulation.

    Pickles as its path, digest and (optionally) the FMU's bytes, so a Dask
    worker on another machine can use it without a shared filesystem.
    """

    def __init__(self, path: str | Path, reference: str | None = None, structural: dict[str, int] | None = None,
                 interface: str | None = None, solver_settings: Any = None):
        self.path = str(path)
        self.reference = reference or self.path
        # values of structural parameters set by the spec: they size arrays (FMI 3.0 <Dimension valueReference>)
        self.structural = dict(structural or {})
        self.requested_interface = interface
        self._solver_settings = solver_settings
        self._md: Any = None
        self._description: UnitDescription | None = None
        self._elements: dict[str, list[FmiElement]] = {}
        self._digest: str | None = None

    def __getstate__(self) -> dict[str, Any]:
        return {"path": self.path, "reference": self.reference, "structural": self.structural,
                "requested_interface": self.requested_interface, "_solver_settings": self._solver_settings,
                "_md": None, "_description": None, "_elements": {}, "_digest": self._digest}

    @property
    def interface(self) -> str:
        """How the FMU runs: the requested interface, or co-simulation when offered, else Model Exchange."""
        if self.requested_interface:
            return self.requested_interface
        return CO_SIMULATION if self.model_description().coSimulation is not None else MODEL_EXCHANGE

    def offers_equations(self) -> bool:
        return self.interface == MODEL_EXCHANGE

    @property
    def solver_settings(self) -> Any:
        """The Model Exchange solver settings (defaults when the spec gives none)."""
        from cosim.units.fmu.model_exchange import SolverSettings

        return self._solver_settings or SolverSettings()

    @property
    def digest(self) -> str:
        if self._digest is None:
            self._digest = file_digest(self.path)
        return self._digest

    def provides_directional_derivatives(self) -> bool:
        """Whether the FMU gives directional derivatives for the interface it runs as (FMI 2.0
        ``providesDirectionalDerivative``; FMI 3.0 ``providesDirectionalDerivatives``, which fmpy does not read:
        taken from modelDescription.xml here, once)."""
        if getattr(self, "_derivatives", None) is None:
            md = self.model_description()
            interface = md.coSimulation if self.interface == CO_SIMULATION else md.modelExchange
            if md.fmiVersion.startswith("2"):
                self._derivatives = bool(getattr(interface, "providesDirectionalDerivative", False))
            else:
                from lxml import etree

                with zipfile.ZipFile(self.path) as zf:
                    data = zf.read("modelDescription.xml")  # already parsed by fmpy: a checked, bounded file
                parser = etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=False)
                element = etree.fromstring(data, parser).find(
                    "CoSimulation" if self.interface == CO_SIMULATION else "ModelExchange")
                self._derivatives = element is not None and \
                    element.get("providesDirectionalDerivatives") in ("true", "1")
        return self._derivatives

    def model_description(self) -> Any:
        """fmpy's ModelDescription, after checking the FMU can run here.

        Raises FmuProblems listing every problem found (missing file, not a
        zip, the requested interface not offered, solver settings for a
        co-simulation FMU, no binary for this platform, unsupported version).
        """
        if self._md is not None:
            return self._md
        from fmpy import read_model_description

        if not os.path.isfile(self.path):
            raise FmuProblems(self.path, [Problem(self.path, "", f"file not found: {self.path}",
                                                  "check the path; relative paths start at the spec's folder")])
        if not zipfile.is_zipfile(self.path):
            raise FmuProblems(self.path, [Problem(self.path, "", "not a zip archive, so not an FMU",
                                                  "rebuild or re-export it")])
        try:  # found here, when the spec is checked, not first when a worker unpacks it
            check_archive(self.path)
        except ArchiveError as exc:
            raise FmuProblems(self.path, exc.problems) from None
        version = _declared_fmi_version(self.path)
        if version is not None and version not in ("2.0", "3.0"):  # fmpy's reader fails on FMI 1.0 with a TypeError
            raise FmuProblems(self.path, [Problem(self.path, "modelDescription.xml", f"FMI version {version[:20]} "
                                                  "is not supported", "export the FMU as FMI 2.0 or 3.0")])
        try:
            md = read_model_description(self.path, validate=False)
        except Exception as exc:  # fmpy raises many kinds for a broken XML
            raise FmuProblems(self.path, [Problem(self.path, "modelDescription.xml", f"cannot read it: {exc}",
                                                  _REEXPORT)]) from None
        problems = []
        if md.fmiVersion not in ("2.0", "3.0"):
            problems.append(Problem(self.path, "modelDescription.xml", f"FMI version {md.fmiVersion} is not "
                                    "supported", "export the FMU as FMI 2.0 or 3.0"))
        offered = offered_interfaces(md)
        chosen = self.requested_interface or (offered[0] if offered else None)
        if not offered:
            others = "scheduled execution (FMI 3.0 clocks)" if getattr(md, "scheduledExecution", None) else "no interface"
            problems.append(Problem(self.path, "modelDescription.xml", f"the FMU does not support co-simulation "
                                    f"({others} only); cosim runs co-simulation and model-exchange FMUs",
                                    "export the FMU for co-simulation or model exchange (FMI 2.0 or 3.0)"))
        elif chosen not in offered:
            problems.append(Problem(self.path, "modelDescription.xml", f"the spec asks for \"interface\": "
                                    f"\"{chosen}\" but the FMU offers only {' and '.join(offered)}",
                                    f"remove \"interface\" (or set it to \"{offered[0]}\")"))
        elif chosen == CO_SIMULATION and self._solver_settings is not None:
            fix = ("add \"interface\": \"model-exchange\" to integrate the FMU with cosim's solver"
                   if MODEL_EXCHANGE in offered else "remove them: the FMU integrates itself")
            problems.append(Problem(self.path, "", "'tolerance' and 'max_step' configure the model-exchange solver, "
                                    "but this FMU runs as co-simulation", fix))
        if chosen == MODEL_EXCHANGE and chosen in offered:
            from cosim.units.fmu.model_exchange import solver_problem

            reason = solver_problem()
            if reason:
                problems.append(Problem(self.path, "", reason, "use the FMU's co-simulation interface if it has one, "
                                        "or run on a platform fmpy ships SUNDIALS for (x86_64 Linux or Windows, "
                                        "arm64 macOS)"))
        if chosen in offered:
            folder2, folder3 = platform_folders()
            folder = folder3 if md.fmiVersion == "3.0" else folder2
            part = md.coSimulation if chosen == CO_SIMULATION else md.modelExchange
            identifier_problem = model_identifier_problem(self.path, part.modelIdentifier)
            if identifier_problem:
                raise FmuProblems(self.path, problems + [identifier_problem])
            library = f"binaries/{folder}/{part.modelIdentifier}{shared_library_suffix()}"
            with zipfile.ZipFile(self.path) as zf:
                if library not in zf.namelist():
                    present = sorted({n.split("/")[1] for n in zf.namelist()
                                      if n.startswith("binaries/") and n.count("/") >= 2})
                    problems.append(Problem(self.path, library, "no binary for this platform; the FMU has "
                                            f"binaries for {', '.join(present) or 'no platform'}",
                                            "re-export the FMU with a binary for this platform, or run it "
                                            "where it has one"))
        if problems:
            raise FmuProblems(self.path, problems)
        self._md = md
        return md

    def describe(self) -> UnitDescription:
        if self._description is None:
            self._description, self._elements = _describe(self.model_description(), self.reference, self.structural)
        return self._description

    def elements(self) -> dict[str, list[FmiElement]]:
        """Per variable name, where each of its scalar elements lives."""
        self.describe()
        return self._elements

    def extracted_folder(self) -> str:
        """The folder this process extracted the FMU into (extracting once)."""
        return EXTRACTED.folder(self.path, f"{self.path}:{self.digest}")

    def files(self) -> list[Path]:
        self.digest  # hashed here, from the original, so a worker need not hash its copy
        return [Path(self.path)]

    def relocate(self, copies: Sequence[Path]) -> None:
        self.path = str(copies[0])

    def instantiate(self, name: str) -> Unit:
        md = self.model_description()
        if self.interface == MODEL_EXCHANGE:
            from cosim.units.fmu.model_exchange import Fmi2ModelExchangeUnit, Fmi3ModelExchangeUnit

            return (Fmi2ModelExchangeUnit if md.fmiVersion == "2.0" else Fmi3ModelExchangeUnit)(name, self)
        if md.fmiVersion == "2.0":
            from cosim.units.fmu.fmi2 import Fmi2Unit

            return Fmi2Unit(name, self)
        from cosim.units.fmu.fmi3 import Fmi3Unit

        return Fmi3Unit(name, self)


def _declared_fmi_version(path: str) -> str | None:
    """The ``fmiVersion`` the FMU's modelDescription.xml declares (read from its first 4 kB), or None."""
    try:
        with zipfile.ZipFile(path) as zf, zf.open("modelDescription.xml") as f:
            head = f.read(4096).decode("utf-8", "replace")
    except (KeyError, OSError, zipfile.BadZipFile, RuntimeError):
        return None  # fmpy's reader says what is wrong
    found = re.search(r"<fmiModelDescription\b[^>]*?\bfmiVersion\s*=\s*[\"']([^\"']*)[\"']", head)
    return found.group(1) if found else None


def _number(text: Any, kind: str) -> Any:
    if text is None:
        return None
    if isinstance(text, (int, float, bool)):
        return text
    text = str(text).strip()
    values: list[Any]
    if kind == "Real":
        values = [float(t) for t in text.split()]
    elif kind == "Integer":
        values = [int(t) if t.lstrip("+-").isdigit() else int(float(t)) for t in text.split()]  # exact for 64 bits
    elif kind == "Boolean":
        values = [t in ("true", "1") for t in text.split()]
    elif kind == "Binary":
        values = [bytes.fromhex(t[2:] if t[:2] in ("0x", "0X") else t) for t in text.split()]
    else:
        return text
    return values[0] if len(values) == 1 else tuple(values)


def _relative(v: Any) -> bool:
    """FMI relativeQuantity of a variable, or of its declared type when the variable does not say."""
    if getattr(v, "relativeQuantity", None) is not None:
        return bool(v.relativeQuantity)
    declared = getattr(v, "declaredType", None)
    return bool(getattr(declared, "relativeQuantity", False)) if declared is not None else False


def _unit_of(v: Any) -> str | None:
    if v.unit:
        return str(v.unit)
    declared = getattr(v, "declaredType", None)
    return getattr(declared, "unit", None) if declared is not None else None


def _whole(text: Any) -> int | None:
    """A dimension's size as written (``"3"``, ``3``, ``"1e9"``), or None when it is not a whole number."""
    try:
        value = float(text) if not isinstance(text, int) else text
    except (TypeError, ValueError):
        return None
    if isinstance(value, float) and (not value == value or value in (float("inf"), float("-inf"))
                                     or value != int(value)):
        return None
    return int(value)


def _dimension_size(reference: str, variable_name: str, dimension: Any, structural: dict[str, int]) -> int:
    """One FMI 3.0 <Dimension>: a fixed ``start``, or the value of a structural parameter
    (the spec's value when it sets one, else the parameter's start value).

    Raises FmuProblems naming the FMU, the variable and the fix when the size is not a
    whole number >= 0 (a negative size would make no array, not "-5 elements").
    """
    if dimension.start is not None:
        text, source = dimension.start, f"<Dimension start=\"{dimension.start}\">"
    elif dimension.variable is None:
        return 0
    elif dimension.variable.name in structural:
        text = structural[dimension.variable.name]
        source = f"the structural parameter '{dimension.variable.name}' (set by the spec to {text})"
    else:
        text = dimension.variable.start
        source = f"the structural parameter '{dimension.variable.name}' (start {text})"
        if text is None:
            return 0
    size = _whole(text)
    if size is None or size < 0:
        fix = (f"set '{dimension.variable.name}' to a whole number >= 0" if dimension.start is None
               else _REEXPORT + " with a whole-number size")
        raise FmuProblems(reference, [Problem(reference, f"modelDescription.xml: variable '{variable_name}'",
                                              f"array size {text} from {source} is not a whole number >= 0", fix)])
    return size


def _check_array_sizes(reference: str, shapes: dict[str, tuple[tuple[int, ...], tuple[str | None, ...]]],
                       set_by_spec: Sequence[str] = ()) -> None:
    """Refuse an FMU whose arrays hold more elements in all than ``COSIM_ARRAY_ELEMENTS``.

    Checked before any per-element object is made: a ``<Dimension start="1000000000"/>`` (or a
    structural parameter set to 1e9) would otherwise take the machine's memory. ``shapes`` maps
    a variable name to its shape and, per dimension, the structural parameter sizing it (None for a
    fixed ``start``); ``set_by_spec`` are the structural parameters the spec sets. Raises FmuProblems naming the FMU, the largest arrays and how to raise the limit.
    """
    from cosim.util import limits

    most = int(limits.limit("array_elements"))
    sizes = {name: math.prod(shape) for name, (shape, _) in shapes.items()}
    total = sum(sizes.values())
    if total <= most:
        return

    def origin(name: str) -> str:
        shape, params = shapes[name]
        fixed = ["<Dimension start>"] if None in params else []
        named = dict.fromkeys(f"structural parameter '{p}' = {size}" + (" set by the spec" if p in set_by_spec else "")
                              for size, p in zip(shape, params) if p)
        return ", ".join(fixed + list(named))

    largest = sorted(sizes, key=lambda n: -sizes[n])[:3]
    listed = ", ".join(f"'{n}' has {' x '.join(map(str, shapes[n][0])) + ' = ' if len(shapes[n][0]) > 1 else ''}"
                       f"{sizes[n]:,} (from {origin(n)})" for n in largest)
    by_parameter = {p: size for n in largest for size, p in zip(*shapes[n]) if p}
    biggest = max(by_parameter.values(), default=0)
    culprits = sorted(p for p, size in by_parameter.items() if size == biggest)
    fix = (f"set the structural parameter{'s' if len(culprits) > 1 else ''} "
           f"{', '.join(repr(p) for p in culprits)} smaller, or use an FMU with smaller arrays" if culprits
           else "use an FMU with smaller arrays")
    raise FmuProblems(reference, [Problem(
        reference, f"modelDescription.xml: variable '{largest[0]}'",
        f"its arrays hold {total:,} elements in all, above the limit of {most:,}: {listed}",
        f"{fix}; {limits.raise_hint('array_elements')}")])


def _describe(md: Any, reference: str, structural: dict[str, int] | None = None
              ) -> tuple[UnitDescription, dict[str, list[FmiElement]]]:
    """Translate fmpy's model description into ours (grouping FMI 2.0 indexed scalars)."""
    fmi3 = md.fmiVersion == "3.0"
    variables: list[Variable] = []
    elements: dict[str, list[FmiElement]] = {}
    shapes: dict[str, tuple[tuple[int, ...], tuple[str | None, ...]]] = {}
    if fmi3:  # every array's size, checked against the limit before one object per element is made
        for v in md.modelVariables:
            if v.dimensions:
                shape = tuple(_dimension_size(reference, v.name, d, structural or {}) for d in v.dimensions)
                shapes[v.name] = (shape, tuple(d.variable.name if d.start is None and d.variable is not None
                                               else None for d in v.dimensions))
        _check_array_sizes(reference, shapes, tuple(structural or ()))
    for v in md.modelVariables:
        kind = _FMI3_TYPE.get(v.type, "Real")
        shape = shapes[v.name][0] if v.name in shapes else ()
        size = math.prod(shape)
        start = _number(v.start, kind)
        if shape and isinstance(start, tuple) and len(start) != size:
            start = None  # a structural parameter set in the spec resized the array: its listed start no longer fits
        variables.append(Variable(
            name=v.name, causality=v.causality or "local", type=kind, unit=_unit_of(v),
            start=start, description=v.description or "", shape=shape,
            min=_number(v.min, "Real") if v.min is not None else None,
            max=_number(v.max, "Real") if v.max is not None else None,
            variability=v.variability or "continuous", fmi_type=v.type, relative_quantity=_relative(v),
            initial=v.initial,
        ))
        elements[v.name] = [FmiElement(v.type, v.valueReference, i, size) for i in range(size)] if shape \
            else [FmiElement(v.type, v.valueReference)]
    if not fmi3:
        variables, elements = _group_indexed(variables, elements)
    feedthrough = {}
    for unknown in md.outputs:
        name = unknown.variable.name
        if unknown.dependencies is not None:
            feedthrough[name] = tuple(d.name for d in unknown.dependencies if d.causality == "input")
    if not fmi3:
        feedthrough = _group_feedthrough(feedthrough, variables)
    default_step = None
    if md.defaultExperiment is not None and md.defaultExperiment.stepSize:
        default_step = float(md.defaultExperiment.stepSize)
    description = UnitDescription(
        name=md.modelName, variables=tuple(variables), kind="fmu", fmi_version=md.fmiVersion,
        can_reset=True, feedthrough=feedthrough, default_step=default_step,
        description=md.description or "", source=reference, unit_definitions=fmi_unit_definitions(md),
    )
    return description, elements


def _group_indexed(variables: list[Variable], elements: dict[str, list[FmiElement]]
                   ) -> tuple[list[Variable], dict[str, list[FmiElement]]]:
    """Offer runs ``x[1]..x[n]`` of FMI 2.0 scalars (same causality and type) also as an array ``x``."""
    by_name = {v.name: v for v in variables}
    extra = []
    for base, member_names in indexed_runs(by_name).items():
        ordered = [by_name[n] for n in member_names]
        first = ordered[0]
        if any(m.causality != first.causality or m.type != first.type for m in ordered):
            continue
        starts = [m.start for m in ordered]
        extra.append(Variable(
            name=base, causality=first.causality, type=first.type, unit=first.unit,
            start=None if all(s is None for s in starts) else tuple(starts),
            description=first.description, shape=(len(ordered),), min=first.min, max=first.max,
            variability=first.variability, initial=first.initial if all(m.initial == first.initial for m in ordered)
            else None,
        ))
        elements[base] = [elements[m.name][0] for m in ordered]
    return variables + extra, elements


def _group_feedthrough(feedthrough: dict[str, tuple[str, ...]], variables: list[Variable]
                       ) -> dict[str, tuple[str, ...]]:
    """Add feed-through entries for grouped arrays (union over their elements)."""
    arrays = {v.name for v in variables if v.is_array}
    result = dict(feedthrough)
    for base in arrays:
        members = [k for k in feedthrough if parse_port(k)[1] is not None and parse_port(k)[0] == base]
        if members:
            deps: set[str] = set()
            for k in members:
                deps.update(feedthrough[k])
            for dependency in list(deps):  # an element input stands for its array too
                dep_base, dep_index = parse_port(dependency)
                if dep_index is not None and dep_base in arrays:
                    deps.add(dep_base)
            result[base] = tuple(sorted(deps))
    return result
