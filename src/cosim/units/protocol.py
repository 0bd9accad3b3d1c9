"""The one protocol every co-simulation unit obeys, FMU or Python.

A *unit type* is a picklable blueprint: it describes the unit's variables and
creates live *unit instances*.  Both FMUs (:mod:`cosim.units.fmu.description`) and
Python classes (:mod:`cosim.units.python.unit`) implement the same two
abstract classes here, so a spec can swap one for the other by changing the
line that names it.

Variables are addressed by name.  An array variable ``tau`` of shape ``(7,)``
has the elements ``tau[1]`` .. ``tau[7]``: element indices are **1-based**, as
in Modelica and in the scalar names FMI 2.0 tools export, so ``tau[3]`` means
the same element whether ``tau`` is an FMI 3.0 array or seven FMI 2.0 scalars.

Values cross the protocol as flat sequences of scalars.  A caller first turns
names into a :class:`Selection` once (``unit.select([...])``) and then calls
``get``/``set`` with it every step, so the per-step path does no name lookup.
"""

from __future__ import annotations

import abc
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Callable, Iterable, Mapping, Sequence

from cosim.errors import UnitError as UnitError  # re-exported: units raise it from here

if TYPE_CHECKING:  # numpy only names a type here: importing the protocol stays cheap
    from numpy.typing import NDArray

_ELEMENT_RE = re.compile(r"^(?P<base>.+?)\[(?P<index>\d+)\]$")

# Variable types.  Only numbers are reduced to objectives (Boolean counts as 0/1);
# String and Binary (FMI 3.0 bytes) values are recorded as they are, a Clock is never transferred.
NUMERIC_TYPES = ("Real", "Integer", "Boolean")
VALUE_TYPES = NUMERIC_TYPES + ("String", "Binary")


class SimulationEnded(Exception):
    """Raised by ``do_step`` when a unit ends the whole simulation (not an error).

    ``time`` is the last time the unit reached (at most ``t + h``); FMI 2.0
    FMUs say so with fmi2Discard + fmi2Terminated, FMI 3.0 FMUs with
    ``terminateSimulation`` (and ``earlyReturn``/``lastSuccessfulTime``).
    The run ends there, cleanly, with the traces up to ``time``.
    """

    def __init__(self, unit: str, time: float, reason: str = "asked to end the simulation"):
        self.unit = unit
        self.time = time
        self.reason = reason
        super().__init__(f"unit '{unit}' {reason} at t={time:g}")


@dataclass(frozen=True)
class Variable:
    """One variable of a unit: what the spec and the master need to know.

    ``shape`` is ``()`` for a scalar and ``(n,)`` (or more dimensions) for an
    array.  ``start`` is a scalar, or a tuple in row-major order for arrays.
    """

    name: str
    causality: str
    type: str = "Real"
    unit: str | None = None
    start: Any = None
    description: str = ""
    shape: tuple[int, ...] = ()
    min: float | None = None
    max: float | None = None
    variability: str = "continuous"
    fmi_type: str | None = None  # an FMU variable's own FMI type (Float32, UInt64, Enumeration, Binary ...)
    # FMI relativeQuantity: the value is a difference (e.g. of temperatures), so unit offsets do not apply
    relative_quantity: bool = False
    # FMI initial ("exact", "approx", "calculated"; None when the unit says none): an output or local whose start
    # is "exact" or "approx" (a state's start value, as the Reference FMUs declare them) may be set before a run
    initial: str | None = None

    @property
    def size(self) -> int:
        """Number of scalar elements (1 for a scalar)."""
        return math.prod(self.shape) if self.shape else 1

    @property
    def is_array(self) -> bool:
        """Whether the variable is an array (it has a shape), addressed by elements ``name[i]``."""
        return bool(self.shape)

    def element_names(self) -> list[str]:
        """Names of the scalar elements, ``x`` or ``x[1]`` .. ``x[n]`` (flattened)."""
        if not self.shape:
            return [self.name]
        return [f"{self.name}[{i}]" for i in range(1, self.size + 1)]


@dataclass(frozen=True)
class UnitDescription:
    """What a unit type offers: its variables and its capabilities.

    ``feedthrough`` maps an output name to the input names its value depends on
    *directly* (without a step in between).  An output missing from the map is
    assumed to depend on every input, as FMI prescribes when a model declares
    nothing; an empty list means no direct feed-through.
    """

    name: str
    variables: tuple[Variable, ...]
    kind: str = "python"
    fmi_version: str | None = None
    can_reset: bool = True
    feedthrough: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    default_step: float | None = None
    description: str = ""
    source: str = ""
    # The unit's own definitions of unit names (an FMU's <UnitDefinitions>), see cosim.util.quantities
    unit_definitions: Mapping[str, Any] = field(default_factory=dict)

    def variable(self, name: str) -> Variable:
        """The variable called ``name``; raises KeyError if there is none."""
        for v in self.variables:
            if v.name == name:
                return v
        raise KeyError(name)

    @property
    def by_name(self) -> Mapping[str, Variable]:
        """The variables by name, read-only; built once per description (resolving 10^5 ports of an FMU with
        10^5 variables rebuilt it 10^5 times)."""
        cached = self.__dict__.get("_by_name")
        if cached is None:
            cached = MappingProxyType({v.name: v for v in self.variables})
            object.__setattr__(self, "_by_name", cached)  # frozen: a cache, not a field (eq, replace ignore it)
        return cached

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state.pop("_by_name", None)  # rebuilt where it is needed; a mapping proxy does not pickle
        return state

    def inputs(self) -> list[Variable]:
        return [v for v in self.variables if v.causality == "input"]

    def outputs(self) -> list[Variable]:
        return [v for v in self.variables if v.causality == "output"]

    def depends_on(self, output: str) -> tuple[str, ...]:
        """Inputs that feed ``output`` directly (all inputs when undeclared)."""
        if output in self.feedthrough:
            return tuple(self.feedthrough[output])
        return tuple(v.name for v in self.inputs())


@dataclass(frozen=True)
class ElementRef:
    """One scalar element: a variable and a 0-based flat offset into it."""

    variable: str
    offset: int = 0


def parse_port(port: str) -> tuple[str, int | None]:
    """Split ``"tau[3]"`` into ``("tau", 3)``; ``"tau"`` into ``("tau", None)``."""
    m = _ELEMENT_RE.match(port)
    if m:
        return m.group("base"), int(m.group("index"))
    return port, None


def indexed_runs(names: Iterable[str]) -> dict[str, list[str]]:
    """Complete runs of scalar names ``base[1]`` .. ``base[n]``, by base, in first-seen order.

    Only runs numbered from 1 without gaps, whose base is not itself a name
    and has no brackets, count.  They are offered as one array ``base``, so
    FMI 2.0 scalars and recorded columns connect like FMI 3.0 arrays.
    """
    names = list(names)
    known = set(names)
    groups: dict[str, dict[int, str]] = {}
    for name in names:
        base, index = parse_port(name)
        if index is not None and "[" not in base:
            groups.setdefault(base, {})[index] = name
    return {base: [members[i] for i in range(1, len(members) + 1)] for base, members in groups.items()
            if base not in known and sorted(members) == list(range(1, len(members) + 1))}


def resolve_port(description: UnitDescription, port: str) -> tuple[Variable, list[ElementRef]]:
    """Turn a port name into its variable and scalar elements.

    ``port`` may name a whole variable (all its elements) or one element with
    a 1-based index.  A variable whose own name contains brackets (an FMI 2.0
    scalar ``x[1]`` that was not grouped) is found by its full name first.

    Raises KeyError when no variable fits and IndexError when the index is
    outside the array.
    """
    by_name = description.by_name
    if port in by_name:
        var = by_name[port]
        return var, [ElementRef(var.name, i) for i in range(var.size)]
    base, index = parse_port(port)
    if index is None or base not in by_name:
        raise KeyError(port)
    var = by_name[base]
    if not var.is_array or not 1 <= index <= var.size:
        raise IndexError(f"{port}: '{base}' has {var.size} element(s); indices run from 1")
    return var, [ElementRef(var.name, index - 1)]


def flatten_value(var: Variable, value: Any) -> list[Any]:
    """A user's value for ``var`` as a flat list of its scalar elements.

    Raises ValueError when an array value has the wrong number of elements.
    """
    if var.is_array:
        flat = list(_flatten(value)) if isinstance(value, (list, tuple)) or hasattr(value, "shape") else None
        if flat is None:
            flat = [value] * var.size  # one scalar fills the whole array
        if len(flat) != var.size:
            raise ValueError(f"'{var.name}' has {var.size} elements, got {len(flat)} values")
        return flat
    return [value]


def _flatten(value: Any) -> Iterable[Any]:
    if hasattr(value, "tolist"):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        for item in value:
            yield from _flatten(item)
    else:
        yield value


class Selection(abc.ABC):
    """Scalar elements of one unit, resolved once for fast repeated access."""

    refs: tuple[ElementRef, ...]

    def __len__(self) -> int:
        return len(self.refs)


class Unit(abc.ABC):
    """A live instance of a unit type.

    Lifecycle: ``setup`` -> (``set`` parameters and start values) ->
    ``initialize`` -> ``do_step`` ... -> ``terminate``; ``reset`` returns a
    unit to the state right after instantiation so that it can run again.
    Every method raises :class:`UnitError` naming the unit when it fails.
    """

    name: str
    description: UnitDescription

    @abc.abstractmethod
    def select(self, refs: Sequence[ElementRef]) -> Selection:
        """Resolve scalar elements once for ``get``/``set``."""

    @abc.abstractmethod
    def get(self, selection: Selection) -> list[Any]:
        """Current values of the selected elements, in selection order."""

    @abc.abstractmethod
    def set(self, selection: Selection, values: Sequence[Any]) -> None:
        """Set the selected elements to ``values`` (same order and length)."""

    def reader(self, selection: Selection) -> Callable[[], Sequence[Any] | NDArray[Any]]:
        """A function returning the selected values, for reading them every step.

        Units may return something faster than ``get`` (e.g. a numpy view of a
        buffer refreshed in place); the result is only valid until the next call.
        """
        return lambda: self.get(selection)

    def writer(self, selection: Selection) -> Callable[[Any], None]:
        """A function setting the selected elements from a 1-D numpy array (or a sequence), for setting them
        every step (the master's transfers, lock-step runs).  Units may return something faster than ``set``."""
        return lambda values: self.set(selection, values.tolist() if hasattr(values, "tolist") else values)

    @abc.abstractmethod
    def setup(self, start_time: float, stop_time: float | None) -> None:
        """Prepare a run from ``start_time`` (to ``stop_time`` if known)."""

    @abc.abstractmethod
    def enter_initialization(self) -> None:
        """Enter initialization mode: parameters and start values are set."""

    @abc.abstractmethod
    def exit_initialization(self) -> None:
        """Leave initialization mode; outputs are valid at the start time."""

    @abc.abstractmethod
    def do_step(self, t: float, h: float) -> None:
        """Advance from ``t`` to ``t + h`` with the inputs held constant."""

    @abc.abstractmethod
    def reset(self) -> None:
        """Return to the freshly instantiated state."""

    @abc.abstractmethod
    def terminate(self) -> None:
        """End the run and free every resource; safe to call more than once."""

    # Saved states: an optional capability ---------------------------------
    # A master that may take a step back (the adaptive algorithm rejecting a step, a study starting from a
    # warmed-up state) saves a unit's state and restores it later.  Units that cannot keep the defaults.

    @property
    def can_save_state(self) -> bool:
        """Whether :meth:`save_state` and :meth:`restore_state` work (FMI ``canGetAndSetFMUstate``, a
        :class:`~cosim.units.python.unit.PythonUnit` with ``get_state``/``set_state``)."""
        return False

    def save_state(self, reuse: Any = None) -> Any:
        """A snapshot of everything the unit changes while it runs (its time, states and values).

        ``reuse``: an earlier snapshot of this unit that is no longer needed; its storage may be
        overwritten and returned (FMI allows updating a state in place).  Raises UnitError when the unit
        cannot save its state (see :attr:`can_save_state`).
        """
        raise UnitError(self.name, "cannot save its state (it offers no get/set of its state)", None)

    def restore_state(self, state: Any) -> None:
        """Return to a snapshot :meth:`save_state` made; the snapshot stays valid (it may be restored again)."""
        raise UnitError(self.name, "cannot restore a saved state (it offers no get/set of its state)", None)

    def free_state(self, state: Any) -> None:
        """Release a snapshot's storage (an FMU's memory); the snapshot is not used afterwards."""

    def allow_restore(self) -> None:
        """Tell the unit a saved state may be restored after later steps (FMI: ``noSetFMUStatePriorToCurrentPoint``
        becomes false), so it keeps what a restore needs."""

    # Serialized states: a saved state as bytes, to restore in another instance (another process): a study's
    # warm start runs once to a time, saves every unit's state and starts each point there (cosim.execution.warm_start)

    @property
    def can_serialize_state(self) -> bool:
        """Whether :meth:`serialize_state` and :meth:`deserialize_state` work (FMI ``canSerializeFMUstate``, a
        :class:`~cosim.units.python.unit.PythonUnit` whose saved state pickles)."""
        return False

    def serialize_state(self, state: Any) -> bytes:
        """The bytes of a snapshot :meth:`save_state` made; raises UnitError when the unit cannot serialize it."""
        raise UnitError(self.name, "cannot serialize its state (FMI canSerializeFMUstate is not set)", None)

    def deserialize_state(self, data: bytes) -> Any:
        """A snapshot of this unit from the bytes :meth:`serialize_state` gave (in any instance of the same unit
        type, in any process), for :meth:`restore_state`; raises UnitError for bytes it cannot take."""
        raise UnitError(self.name, "cannot deserialize a state (FMI canSerializeFMUstate is not set)", None)

    # Directional derivatives: an optional capability (FMI getDirectionalDerivative); the loop solver's Newton uses
    # them for its Jacobian where every unit on a loop gives them, finite differences otherwise

    def differentiator(self, outputs: Sequence[ElementRef], inputs: Sequence[ElementRef]
                       ) -> Callable[[Sequence[float]], Any] | None:
        """A function of a seed on ``inputs`` (one float per element) giving the directional derivative of
        ``outputs`` (a float array, one per element) at the unit's current inputs and states; each call raises
        UnitError when the unit fails.  None (the default) when the unit cannot give it for these elements."""
        return None

    def can_tune(self, variable: str) -> bool:
        """Whether ``variable`` may be set after initialization, between steps: an input, or a parameter whose
        variability is ``tunable`` (FMI); a fixed parameter is part of what a saved state holds and stays."""
        var = self.description.variable(variable)
        return var.causality == "input" or (var.causality == "parameter" and var.variability == "tunable")

    # Conveniences built on the primitives -------------------------------

    def set_values(self, values: Mapping[str, Any]) -> None:
        """Set variables or elements by name (arrays accept sequences)."""
        refs: list[ElementRef] = []
        flat: list[Any] = []
        for port, value in values.items():
            var, elements = resolve_port(self.description, port)
            refs.extend(elements)
            flat.extend(flatten_value(var, value) if len(elements) > 1 else [value])
        if refs:
            self.set(self.select(refs), flat)

    def get_values(self, ports: Sequence[str]) -> dict[str, Any]:
        """Values by name: a scalar, or a list for a whole array variable."""
        out: dict[str, Any] = {}
        for port in ports:
            var, elements = resolve_port(self.description, port)
            values = self.get(self.select(elements))
            out[port] = values if var.is_array and len(elements) > 1 else values[0]
        return out


class UnitType(abc.ABC):
    """A picklable blueprint of a unit: describes it and creates instances."""

    @abc.abstractmethod
    def describe(self) -> UnitDescription:
        """The unit's variables and capabilities (cheap after the first call)."""

    @abc.abstractmethod
    def instantiate(self, name: str) -> Unit:
        """A new live instance called ``name``."""

    def offers_equations(self) -> bool:
        """True when its units give cosim their equations to integrate (continuous states, derivatives, event
        indicators: a Model Exchange FMU), so that such units connected to each other can be integrated
        together by one solver (:mod:`cosim.system.coupled_me`). Default False: a unit steps itself."""
        return False

    def files(self) -> list[Path]:
        """Local files this blueprint reads to describe or instantiate its units (default: none).

        A sweep ships their bytes to its workers, so no shared filesystem is
        needed, and calls :meth:`relocate` there with the copies.
        """
        return []

    def relocate(self, copies: Sequence[Path]) -> None:
        """Use ``copies`` (in the order of :meth:`files`) instead of the original files."""
