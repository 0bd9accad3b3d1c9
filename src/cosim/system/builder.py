"""The system: units, their ports and connections, checked to fit together.

:func:`build_system` turns a :class:`~cosim.spec.loader.Spec` into a
:class:`System`: it creates every unit type, resolves every port of every
connection, parameter, recorded signal and objective to scalar elements, and
checks causality, types, sizes, ranges and algebraic loops.  It reports every
problem at once (:class:`~cosim.errors.SpecError`).

A System is picklable: it holds unit *types* (blueprints), never live units.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

from cosim.errors import FmuProblems, Problem, SpecError, UserError, did_you_mean, json_path
from cosim.master.loops import Coupling
from cosim.spec.loader import Spec
from cosim.system.connection_checks import check_connections
from cosim.system.coupled_me import ModelExchangeCoupling, model_exchange_coupling
from cosim.system.kernel_choice import KernelChoice, kernel_choice, why_not_native
from cosim.system.parts import Assignment, Connection, LoadedUnits, Signal, SystemUnit
from cosim.system.signals import add_recorded, resolve_signal, split_unit_name
from cosim.system.stepping import check_algebraic_loops, feedthrough_coupling, stepping_order
from cosim.system.study_checks import check_design, check_objective_expressions, fed_values
from cosim.system.value_checks import assignment
from cosim.system.warm_start_checks import check_warm_start_design
from cosim.units.kind import UnitSpec
from cosim.units.protocol import NUMERIC_TYPES, UnitDescription, UnitType
from cosim.units.python.data_files import attach as attach_data_files
from cosim.units.registry import replaying_units, unit_kind


@dataclass(frozen=True)
class System:
    """A validated system, ready to run (see :class:`cosim.execution.run.Execution`)."""

    spec: Spec
    units: Mapping[str, SystemUnit]
    connections: tuple[Connection, ...]
    order: tuple[str, ...]
    init_order: tuple[Connection, ...]
    assignments: tuple[Assignment, ...]
    probes: tuple[Signal, ...]
    recorded: tuple[str, ...]
    # direct feed-through in dependency order and the algebraic loops, as indices into ``connections``
    coupling: Coupling = Coupling()
    # connected model-exchange units integrated together, and the master's order with them (system/coupled_me.py)
    model_exchange: ModelExchangeCoupling = ModelExchangeCoupling()
    # design parameter -> (factor, offset) from its design `unit` to its port's unit (identities left out)
    design_conversions: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    # the saved warm-up of a spec with experiment.warm_start (cosim.execution.warm_start.WarmState), once made
    warm_start: Any = None
    # which master steps it: the native kernel or the Python master, and why not native (system/kernel_choice.py)
    kernel: KernelChoice = KernelChoice()

    def signal(self, text: str) -> Signal:
        """Resolve a 'unit.port' text against this system; raises SpecError if it does not fit."""
        problems: list[Problem] = []
        signal = resolve_signal(text, self.units, problems, self.spec.path, "$")
        if signal is None:
            raise SpecError(problems)
        return signal

    def assignment_for(self, target: str, value: Any) -> Assignment:
        """An Assignment setting ``target`` ('unit.port') to ``value``, checked like a spec parameter.

        Raises SpecError when the target does not exist or the value does not fit.
        """
        problems: list[Problem] = []
        unit_name, _, port = split_unit_name(target, self.units)
        if unit_name not in self.units:
            raise SpecError([Problem(self.spec.path, "$", f"unknown unit '{unit_name}' in '{target}'."
                                     f"{did_you_mean(unit_name, self.units)}", "use 'unit.parameter'")])
        result = assignment(self.units[unit_name], port, value, None, problems, self.spec.path, f"'{target}'")
        if result is None:
            raise SpecError(problems)
        return result

    def fed_by(self, target: str, value: Any) -> list[tuple[str, Any]]:
        """The unit parameters a value set on ``target`` sets too, as ``(target, value)``: an SSP system's
        parameter connector (a ``connectors`` unit's parameter with ``feeds``) sets the FMU parameters its
        parameter connections reach, each through its factor and offset; empty for other targets."""
        return fed_values(self.units, target, value)

    def recording(self, texts: Sequence[str]) -> "System":
        """This system, also recording ``texts`` ('unit.port' or 'unit.*' for every output of a unit).

        The units are not loaded or described again.  Raises SpecError when a
        text does not name a signal of the system.
        """
        problems: list[Problem] = []
        probes = {s.text: s for s in self.probes}
        recorded = list(self.recorded)
        add_recorded([(text, "$.record") for text in texts], self.units, problems, self.spec.path, probes, recorded)
        if problems:
            raise SpecError(problems)
        return replace(self, probes=tuple(probes.values()), recorded=tuple(recorded))

    def recording_all_outputs(self) -> "System":
        """This system recording every output of every unit besides its own record list (for re-runs)."""
        return self.recording([f"{name}.*" for name in self.units])


def make_unit_type(spec: UnitSpec, folder: str) -> UnitType:
    """The blueprint for one unit of a spec, made by its kind (see :mod:`cosim.units.registry`).

    No file is opened yet except builtin FMU builds.
    """
    return unit_kind(spec.kind).create(spec, folder)


def build_system(spec: Spec, broken_units: frozenset[str] = frozenset()) -> System:
    """Check that the spec's units, ports and connections fit, and build the System.

    ``broken_units`` names units already reported as broken elsewhere (by the
    schema check); references to them are not reported a second time.
    Raises SpecError listing every problem found.
    """
    file = spec.path
    problems: list[Problem] = []
    units = LoadedUnits()
    units.failed.update(broken_units)
    for u in spec.units:
        system_unit = _load_unit(u, spec.folder, file, problems)
        if system_unit is not None:
            units[u.name] = system_unit
        else:
            units.failed.add(u.name)

    _check_record_events(spec, units, problems)
    assignments = []
    replaying = replaying_units(spec.units)
    for u in spec.units:
        if u.name not in units or u.name in replaying:  # a player replaying a unit plays what that unit's values gave
            continue
        for field_name, values in (("parameters", u.parameters), ("start", u.start)):
            for port, value in values.items():
                a = assignment(units[u.name], port, value, field_name, problems, file,
                                json_path(["units", u.name, field_name, port]))
                if a is not None:
                    assignments.append(a)

    connections = check_connections(spec, units, problems)
    order = stepping_order([u.name for u in spec.units], connections)
    coupling = feedthrough_coupling([u.name for u in spec.units], units, connections, spec.experiment.loop_solver)
    init_order = check_algebraic_loops(units, connections, problems, file, coupling, spec.experiment.algorithm)
    model_exchange = model_exchange_coupling(spec, units, connections, order, coupling, problems)

    probes: dict[str, Signal] = {}
    recorded: list[str] = []
    add_recorded([(text, json_path(["record", i])) for i, text in enumerate(spec.record)], units, problems, file,
                  probes, recorded)
    for o in spec.objectives:
        if o.signal:
            s = resolve_signal(o.signal, units, problems, file, json_path(["objectives", o.name, "signal"]))
            if s is not None and s.variable.type not in NUMERIC_TYPES:
                problems.append(Problem(file, json_path(["objectives", o.name, "signal"]),
                                        f"'{o.signal}' is {s.variable.type}: only numeric signals (Real, Integer, "
                                        "Boolean) reduce to an objective", "choose a numeric signal; String and "
                                        "Binary signals can be recorded under 'record'"))
            elif s is not None:
                probes.setdefault(s.text, s)
    if spec.experiment.stop_when:
        s = resolve_signal(spec.experiment.stop_when, units, problems, file, "$.experiment.stop_when")
        if s is not None:
            if s.variable.type != "Boolean" or len(s.refs) != 1:
                problems.append(Problem(file, "$.experiment.stop_when", f"'{s.text}' is not a Boolean scalar",
                                        "name a Boolean output such as 'trajectory.finished'"))
            probes.setdefault(s.text, s)
    check_objective_expressions(spec, problems)
    design_conversions = check_design(spec, units, problems)
    check_warm_start_design(spec, units, problems)
    kernel = KernelChoice()
    if not problems:
        why_not = why_not_native(spec, units, connections, coupling, model_exchange, tuple(probes.values()))
        kernel = kernel_choice(spec, why_not)
        if spec.experiment.kernel == "native" and kernel.kernel != "native":
            problems.append(Problem(file, "$.experiment.kernel", f"the native kernel cannot step this system: "
                                    f"{kernel.reason}", "set \"kernel\": \"auto\" (the Python master steps what "
                                    "the kernel cannot) or change what the reason names"))
    if problems:
        raise SpecError(problems)
    system = System(spec=spec, units=dict(units), connections=tuple(connections), order=tuple(order),
                    init_order=tuple(init_order), assignments=tuple(assignments), probes=tuple(probes.values()),
                    recorded=tuple(recorded), coupling=coupling, model_exchange=model_exchange,
                    design_conversions=design_conversions, kernel=kernel)
    attach_data_files(system)  # files named by a unit's data-file parameters: read from the spec's folder, shipped
    return system


def _check_record_events(spec: Spec, units: Mapping[str, SystemUnit], problems: list[Problem]) -> None:
    """``record_events`` asks a model-exchange unit for event rows: refused for a unit that steps itself (its
    events are its own), under the adaptive algorithm (which repeats steps it rejects) and with a warm start
    (whose replayed samples hold no event rows)."""
    for u in spec.units:
        if not u.options.get("record_events") or u.name not in units:
            continue
        where = json_path(["units", u.name, "record_events"])
        if not units[u.name].unit_type.offers_equations():
            problems.append(Problem(spec.path, where, f"'{u.name}' runs as co-simulation: its events happen inside "
                                    "the FMU, where cosim does not see them",
                                    "add \"interface\": \"model-exchange\" (if the FMU offers it), or remove "
                                    "\"record_events\""))
        elif spec.experiment.algorithm == "adaptive":
            problems.append(Problem(spec.path, where, "the adaptive algorithm repeats the steps it rejects, so "
                                    "events would be recorded more than once",
                                    "use a fixed-step algorithm (gauss-seidel, jacobi) with \"record_events\""))
        elif spec.experiment.warm_start is not None:
            problems.append(Problem(spec.path, where, "under experiment.warm_start the warm-up's samples are "
                                    "replayed from the communication points only, so events before the warm-start "
                                    "time would be missing from the traces",
                                    "remove \"warm_start\" from the experiment, or \"record_events\" from the unit"))


def _load_unit(u: UnitSpec, folder: str, file: str, problems: list[Problem]) -> SystemUnit | None:
    path = json_path(["units", u.name, u.kind])
    try:
        unit_type = make_unit_type(u, folder)
        description = unit_type.describe()
    except FmuProblems as exc:
        for p in exc.problems:
            where = f" ({p.path})" if p.path else ""
            problems.append(Problem(file, path, f"FMU '{u.source}'{where}: {p.message}",
                                    p.fix or "re-export the FMU from its tool"))
        return None
    except UserError as exc:  # e.g. a plug-in kind's own check of its source
        for p in exc.problems:
            problems.append(Problem(file, path, f"{u.kind} '{u.source}': {p.message}", p.fix))
        return None
    except FileNotFoundError as exc:
        problems.append(Problem(file, path, str(exc), "check the path; relative paths start at the spec's folder"))
        return None
    except (ImportError, TypeError, ValueError) as exc:
        problems.append(Problem(file, path, f"cannot load '{u.source}': {exc}",
                                "check the module path and class name, and that the module imports cleanly"))
        return None
    except MemoryError:  # not an error in the source: loading it asked for more memory than there is
        problems.append(Problem(file, path, f"cannot load '{u.source}': it ran out of memory while loading",
                                "check what the unit allocates when it is loaded (array sizes, data files), or run "
                                "where there is more memory"))
        return None
    except Exception as exc:  # a user's module may raise anything while importing
        problems.append(Problem(file, path, f"cannot load '{u.source}': {type(exc).__name__}: {exc}",
                                "fix the error in the unit's source"))
        return None
    names = {v.name for v in description.variables}
    if u.options.get("feedthrough"):
        description = _declared_feedthrough(u, description, file, problems)
    for port, actual in u.ports.items():
        if actual not in names:
            problems.append(Problem(file, json_path(["units", u.name, "ports", port]),
                                    f"unit '{u.name}' has no variable '{actual}'.{did_you_mean(actual, names)}",
                                    "map the spec's port name to one of the unit's variables"))
    return SystemUnit(u, unit_type, description)


def _declared_feedthrough(u: UnitSpec, description: UnitDescription, file: str,
                          problems: list[Problem]) -> UnitDescription:
    """The description with the spec's ``feedthrough`` (output -> inputs it depends on directly) applied."""
    declared: dict[str, tuple[str, ...]] = {}
    outputs = {v.name for v in description.outputs()}
    inputs = {v.name for v in description.inputs()}
    for output, depends in u.options["feedthrough"].items():
        path = json_path(["units", u.name, "feedthrough", output])
        name = u.ports.get(output, output)
        if name not in outputs:
            problems.append(Problem(file, path, f"'{output}' is not an output of unit '{u.name}'."
                                                f"{did_you_mean(name, outputs)}", "name an output of the unit"))
            continue
        wrong = [d for d in depends if u.ports.get(d, d) not in inputs]
        if wrong:
            problems.append(Problem(file, path, f"not inputs of unit '{u.name}': {', '.join(wrong)}",
                                    "list the inputs this output depends on directly ([] for none)"))
            continue
        declared[name] = tuple(u.ports.get(d, d) for d in depends)
    return replace(description, feedthrough={**description.feedthrough, **declared})
