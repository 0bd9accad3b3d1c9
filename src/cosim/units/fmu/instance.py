"""What FMI 2.0 and FMI 3.0 instances share: buffers, logging, error reports.

A :class:`FmiSelection` groups the requested scalar elements by FMI type and
pre-builds the ctypes arrays of value references and values once, so that a
``get``/``set`` in the stepping loop is one FMI call per type and no allocation.
"""

from __future__ import annotations

import abc
import ctypes
import operator
from collections import deque
from functools import partial
from typing import Any, Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from cosim.errors import FmuProblems, Problem
from cosim.units.protocol import ElementRef, Selection, Unit, UnitError

STATUS_LABELS = ["OK", "Warning", "Discard", "Error", "Fatal", "Pending"]


def load_library(unit_type: Any, make_slave: Callable[[], Any]) -> Any:
    """fmpy's slave object from ``make_slave()``, which loads the FMU's library and looks up its functions.

    A library that cannot be loaded, or that lacks an FMI function, is the FMU's fault, not cosim's:
    raises FmuProblems (a user error) naming the FMU, the library and the missing function.
    """
    try:
        return make_slave()
    except AttributeError as exc:  # ctypes: "<library>: undefined symbol: fmi2DoStep"
        library, _, missing = str(exc).rpartition(": undefined symbol: ")
        inside = library.rpartition("/binaries/")[2]  # the library's place inside the FMU
        problem = Problem(unit_type.path, f"binaries/{inside}" if inside else "binaries",
                          f"its library lacks the FMI function {missing}" if library
                          else f"its library is unusable: {exc}",
                          "re-export the FMU from its tool: its library must export every function of its FMI "
                          "version")
    except OSError as exc:  # dlopen: not a library for this machine, a missing dependency
        problem = Problem(unit_type.path, "binaries", f"its library cannot be loaded: {exc}",
                          "re-export the FMU with a binary for this platform, and install what the library needs")
    raise FmuProblems(unit_type.path, [problem]) from None


def absent_function(name: str) -> Callable[..., int]:
    """Stands in for an FMI function the FMU's library lacks (``fmi2DoStep`` of a Model-Exchange-only FMU,
    whose unit class never calls it): calling it raises AttributeError naming the function."""
    def absent(*args: Any) -> int:
        raise AttributeError(f"the FMU's library has no {name}")
    return absent


class TypeGroup:
    """All requested elements of one FMI type: one get/set call reads them all."""

    def __init__(self, fmi_type: str, c_type: Any, vr_c_type: Any, vrs: list[int], sizes: list[int]):
        self.fmi_type = fmi_type
        self.vrs = (vr_c_type * len(vrs))(*vrs)
        self.n_vrs = len(vrs)
        self.n_values = sum(sizes)
        self.values: ctypes.Array[Any] = (c_type * self.n_values)()
        # FMI 3.0 Binary: each value is a pointer and a size; the buffers set are kept alive here (an empty
        # array for the other types, which never read it)
        self.sizes = (ctypes.c_size_t * (self.n_values if fmi_type == "Binary" else 0))()
        self.keep: list[Any] = [None] * self.n_values if fmi_type == "Binary" else []
        # Zero-argument FMI calls bound by the instance (functools.partial over
        # the library function): the stepping loop's cheapest possible call.
        self.read: Callable[[], int] = lambda: 0
        self.write: Callable[[], int] = lambda: 0

    def view(self) -> NDArray[Any]:
        """A numpy array over the values buffer itself (no copy: it sees every call's values, and writing
        it fills the buffer the set call reads)."""
        # memoryview: numpy's stubs take a buffer by its Python type, and a ctypes array is none of those named
        return np.frombuffer(memoryview(self.values), dtype=self.values._type_)


class FmiSelection(Selection):
    """Elements resolved to (type group, position in that group's value buffer)."""

    def __init__(self, refs: Sequence[ElementRef], groups: list[TypeGroup], positions: list[tuple[int, int]],
                 partial_arrays: bool):
        self.refs = tuple(refs)
        self.groups = groups
        self.positions = positions
        # Setting one element of an FMI 3.0 array means writing the whole
        # array, so the others are read first (read-modify-write).
        self.partial_arrays = partial_arrays
        self.plain = False
        self.pick: Callable[[Any], tuple[Any, ...]] | None = None  # fast reader for one numeric group
        self.structural = False  # FMI 3.0: a structural parameter among the elements (Fmi3Unit.select decides)


class FmuState:
    """One saved FMU state: the FMU's pointer (``fmi2FMUstate`` / ``fmi3FMUState``) and the time it was at."""

    __slots__ = ("pointer", "time")

    def __init__(self) -> None:
        self.pointer = ctypes.c_void_p()
        self.time: float | None = None


class FmiInstance(Unit):
    """Common part of :class:`Fmi2Unit` and :class:`Fmi3Unit`.

    Subclasses provide ``_c_types`` (FMI type -> ctypes type), ``_vr_type``,
    ``_prefix``, ``_slave`` (fmpy's slave object), ``_bind(group)``
    ``_set_call(group)`` and the version-specific lifecycle calls.
    """

    _c_types: dict[str, Any] = {}
    _vr_type: Any = ctypes.c_uint
    _prefix = "fmi"  # "fmi2" or "fmi3": names the calls in error messages
    _slave: Any = None
    _component: Any  # the FMI instance handle (fmi2Component / fmi3Instance), set by Fmi2Unit / Fmi3Unit

    def __init__(self, name: str, unit_type: Any):
        self.name = name
        self.unit_type = unit_type
        self.description = unit_type.describe()
        self.elements = unit_type.elements()
        self.log: deque[str] = deque(maxlen=20)
        self.time: float | None = None
        self._alive = False
        # Bumped by every call that may change the FMU's values (do_step, set, lifecycle calls through _guard):
        # a reader whose last read is of the current generation hands out its buffer again without calling
        # the FMU, since FMI values change only through such calls.  So an output read by a transfer and
        # again by the probe after the same step costs one get call.
        self.generation = 0
        self._readers: dict[tuple[Any, ...], Callable[[], Sequence[Any] | NDArray[Any]]] = {}

    # Logging and errors ---------------------------------------------------

    def _record_log(self, status: int, category: bytes | None, message: bytes | None) -> None:
        label = STATUS_LABELS[status] if 0 <= status < len(STATUS_LABELS) else str(status)
        text = (message or b"").decode("utf-8", "replace")
        self.log.append(f"[{label}] {text}")

    def fail_status(self, call: str, status: int) -> UnitError:
        """A UnitError for an FMI call that returned ``status``, with the FMU's last log lines."""
        label = STATUS_LABELS[status] if 0 <= status < len(STATUS_LABELS) else f"illegal status {status}"
        return self._error(f"{call} returned {label}")

    def fail(self, call: str, exc: BaseException) -> UnitError:
        """A UnitError for a failed FMI call (an fmpy exception), with its status and the FMU's last log lines."""
        status = getattr(exc, "status", None)
        if isinstance(status, int) and 0 <= status < len(STATUS_LABELS):
            return self.fail_status(call, status)
        return self._error(f"{call} failed: {exc}")

    def _error(self, text: str) -> UnitError:
        if self.log:
            text += "; FMU log: " + " | ".join(self.log)
        return UnitError(self.name, text, self.time)

    # True while set() and do_step() are the plain FMI calls of this class and its FMI 2.0/3.0 subclasses, so
    # a writer may fill the set call's buffer itself and reads may be reused; False for Model Exchange units,
    # whose set() and do_step() do more (restart the solver, integrate, handle events).
    _plain_calls = True

    def _guard(self, call: str, fn: Callable[[], Any]) -> Any:
        self.generation += 1
        try:
            return fn()
        except UnitError:
            raise
        except Exception as exc:
            raise self.fail(call, exc) from None

    # FMI type -> the type in the name of its get/set call (an Enumeration is read as an Integer / Int64)
    _call_types: dict[str, str] = {}

    def call_name(self, verb: str, fmi_type: str) -> str:
        """The FMI function that gets/sets ``fmi_type``: ``fmi2GetInteger`` for an FMI 2.0 Enumeration."""
        return f"{self._prefix}{verb}{self._call_types.get(fmi_type, fmi_type)}"

    # Selections -------------------------------------------------------------

    def select(self, refs: Sequence[ElementRef]) -> FmiSelection:
        by_type: dict[str, dict[int, int]] = {}  # type -> vr -> size, in first-seen order
        for ref in refs:
            element = self.elements[ref.variable][ref.offset]
            by_type.setdefault(element.fmi_type, {})[element.value_reference] = element.size
        groups: list[TypeGroup] = []
        offsets: dict[tuple[str, int], tuple[int, int]] = {}
        for g, (fmi_type, sizes) in enumerate(by_type.items()):
            start = 0
            for vr, size in sizes.items():
                offsets[(fmi_type, vr)] = (g, start)
                start += size
            group = TypeGroup(fmi_type, self._c_types[fmi_type], self._vr_type, list(sizes), list(sizes.values()))
            group.read, group.write = self._bind(group)
            groups.append(group)
        positions = []
        covered: dict[tuple[str, int], set[int]] = {}
        for ref in refs:
            element = self.elements[ref.variable][ref.offset]
            g, start = offsets[(element.fmi_type, element.value_reference)]
            positions.append((g, start + element.index))
            covered.setdefault((element.fmi_type, element.value_reference), set()).add(element.index)
        partial = any(len(covered[(e.fmi_type, e.value_reference)]) < e.size
                      for ref in refs for e in [self.elements[ref.variable][ref.offset]])
        selection = FmiSelection(refs, groups, positions, partial)
        # The common case, one numeric type read in buffer order, skips the
        # per-element bookkeeping in get/set (it is the stepping loop's hot path).
        numeric = len(groups) == 1 and groups[0].fmi_type not in ("Boolean", "String", "Binary")
        selection.plain = numeric and not partial and positions == [(0, i) for i in range(groups[0].n_values)]
        if numeric and len(positions) > 1:
            selection.pick = operator.itemgetter(*[i for _, i in positions])
        return selection

    def get(self, selection: Selection) -> list[Any]:
        sel: FmiSelection = selection  # type: ignore[assignment]  # the one this unit's select() made
        for group in sel.groups:
            status = group.read()
            if status > 1:  # above fmiWarning
                raise self.fail_status(self.call_name("Get", group.fmi_type), status)
        if sel.plain:
            return sel.groups[0].values[:]
        if sel.pick is not None:
            return list(sel.pick(sel.groups[0].values))
        return [self._convert(sel.groups[g], sel.groups[g].values[i], i) for g, i in sel.positions]

    def reader(self, selection: Selection) -> Callable[[], Sequence[Any] | NDArray[Any]]:
        sel: FmiSelection = selection  # type: ignore[assignment]  # the one this unit's select() made
        if not sel.plain:
            return lambda: self.get(sel)
        shared = self._readers.get(sel.refs)
        if shared is not None:  # the same elements read elsewhere too (a transfer and the probe): one reader
            return shared
        group = sel.groups[0]
        read, view, fail = group.read, group.view(), self.fail_status
        read_at = [-1]  # the generation of the last read

        def read_into_view() -> np.ndarray:
            if read_at[0] == self.generation:
                return view  # nothing was called since the last read: the FMU's values are the same
            status = read()
            if status > 1:
                raise fail(self.call_name("Get", group.fmi_type), status)
            read_at[0] = self.generation if self._plain_calls else -1
            return view  # a numpy view of the buffer the FMU just filled: no copy

        self._readers[sel.refs] = read_into_view
        return read_into_view

    def writer(self, selection: Selection) -> Callable[[Any], None]:
        sel: FmiSelection = selection  # type: ignore[assignment]  # the one this unit's select() made
        if not sel.plain or getattr(sel, "structural", False) or not self._plain_calls:
            return super().writer(selection)
        group = sel.groups[0]
        write, view, fail = group.write, group.view(), self.fail_status

        def write_from_array(values: Any) -> None:
            view[:] = values  # into the buffer the set call reads: no list, no per-element conversion
            self.generation += 1
            status = write()
            if status > 1:
                raise fail(self.call_name("Set", group.fmi_type), status)

        return write_from_array

    def set(self, selection: Selection, values: Sequence[Any]) -> None:
        sel: FmiSelection = selection  # type: ignore[assignment]  # the one this unit's select() made
        self.generation += 1
        if sel.plain:
            # call-overload: ctypes takes any sequence of the right length here; typeshed's stub names only list
            sel.groups[0].values[:] = values  # type: ignore[call-overload]
        else:
            if sel.partial_arrays:
                for group in sel.groups:
                    status = group.read()
                    if status > 1:
                        raise self.fail_status(self.call_name("Get", group.fmi_type), status)
            for (g, i), value in zip(sel.positions, values):
                group = sel.groups[g]
                if group.fmi_type == "String":
                    group.values[i] = value.encode("utf-8")
                elif group.fmi_type == "Binary":
                    data = bytes(value)
                    group.keep[i] = ctypes.create_string_buffer(data, len(data) or 1)
                    group.values[i] = ctypes.cast(group.keep[i], group.values._type_)
                    group.sizes[i] = len(data)
                else:
                    group.values[i] = value
        for group in sel.groups:
            status = group.write()
            if status > 1:
                raise self.fail_status(self.call_name("Set", group.fmi_type), status)

    @staticmethod
    def _convert(group: TypeGroup, value: Any, index: int) -> Any:
        if group.fmi_type == "Boolean":
            return bool(value)
        if group.fmi_type == "String":
            return value.decode("utf-8") if value is not None else ""
        if group.fmi_type == "Binary":  # copied out: the FMU's buffer is only valid until its next call
            return ctypes.string_at(value, group.sizes[index]) if value else b""
        return value

    # Saved states (FMI get/set FMU state) -----------------------------------

    # Names of the version's state calls (get, set, free); set by Fmi2Unit / Fmi3Unit.
    _state_calls: tuple[str, str, str] = ("", "", "")
    # Names of the version's (serialize, deserialize) calls, and of fmpy's wrappers of them (they size the buffer)
    _serialize_calls: tuple[str, str] = ("", "")
    _fmpy_serialize: tuple[str, str] = ("", "")

    @property
    def can_save_state(self) -> bool:
        # A Model Exchange unit's integrator state (CVode's) is not in the FMU state: not restorable here.
        md = self.unit_type.model_description()
        interface = getattr(md, getattr(self, "_interface", "coSimulation"), None)
        return bool(self._plain_calls and interface is not None and getattr(interface, "canGetAndSetFMUstate", False))

    def save_state(self, reuse: Any = None) -> Any:
        if not self.can_save_state:
            return super().save_state(reuse)
        state = reuse if reuse is not None else FmuState()
        status = self._state_function(0)(self._component, ctypes.byref(state.pointer))
        if status > 1:
            raise self.fail_status(self._state_calls[0], status)
        state.time = self.time
        return state

    def restore_state(self, state: Any) -> None:
        if not self.can_save_state:
            return super().restore_state(state)
        self.generation += 1  # every value may differ now: no reader may hand out its old buffer
        status = self._state_function(1)(self._component, state.pointer)
        if status > 1:
            raise self.fail_status(self._state_calls[1], status)
        if state.time is not None:  # a deserialized state does not know it; the caller does
            self.time = state.time

    def free_state(self, state: Any) -> None:
        if state is None or not state.pointer or not self._alive:
            return  # a freed instance has freed its states with it
        status = self._state_function(2)(self._component, ctypes.byref(state.pointer))
        if status > 1:
            raise self.fail_status(self._state_calls[2], status)

    @property
    def can_serialize_state(self) -> bool:
        md = self.unit_type.model_description()
        interface = getattr(md, getattr(self, "_interface", "coSimulation"), None)
        return self.can_save_state and bool(getattr(interface, "canSerializeFMUstate", False))

    def serialize_state(self, state: Any) -> bytes:
        if not self.can_serialize_state:
            return super().serialize_state(state)
        call = self._serialize_calls[0]
        return bytes(self._guard(call, lambda: getattr(self._slave, self._fmpy_serialize[0])(state.pointer)))

    def deserialize_state(self, data: bytes) -> Any:
        if not self.can_serialize_state:
            return super().deserialize_state(data)
        state = FmuState()
        self._guard(self._serialize_calls[1],
                    lambda: getattr(self._slave, self._fmpy_serialize[1])(bytes(data), state.pointer))
        return state

    # Directional derivatives (FMI getDirectionalDerivative) -------------------

    _derivative_call_name = ""  # fmi2GetDirectionalDerivative / fmi3GetDirectionalDerivative

    def differentiator(self, outputs: Sequence[ElementRef], inputs: Sequence[ElementRef]
                       ) -> Callable[[Sequence[float]], np.ndarray] | None:
        # Co-simulation FMUs declaring them, on Real scalars (an FMI 3.0 array element would need the whole array)
        if not self._plain_calls or not self.unit_type.provides_directional_derivatives():
            return None
        elements = [self.elements[r.variable][r.offset] for r in (*outputs, *inputs)]
        if any(e.size != 1 or e.fmi_type not in ("Real", "Float64") for e in elements):
            return None
        unknowns = (self._vr_type * len(outputs))(*[e.value_reference for e in elements[:len(outputs)]])
        knowns = (self._vr_type * len(inputs))(*[e.value_reference for e in elements[len(outputs):]])
        seed, sensitivity = (ctypes.c_double * len(inputs))(), (ctypes.c_double * len(outputs))()
        call = self._derivative_call(unknowns, knowns, seed, sensitivity)
        view = np.frombuffer(memoryview(sensitivity), dtype=float)

        def derivative(values: Sequence[float]) -> np.ndarray:
            seed[:] = list(values)
            status = call()
            if status > 1:
                raise self.fail_status(self._derivative_call_name, status)
            return view.copy()

        return derivative

    def _derivative_call(self, unknowns: Any, knowns: Any, seed: Any, sensitivity: Any) -> Callable[[], int]:
        """The version's getDirectionalDerivative call on these buffers, returning the FMI status."""
        raise NotImplementedError

    def allow_restore(self) -> None:
        # doStep's noSetFMUStatePriorToCurrentPoint is true (do_step's default) until a master may restore:
        # then this instance's do_step passes false.  The fixed-step path keeps the plain method.
        # method-assign: an instance attribute shadows the method on purpose, for this instance only
        self.do_step = partial(type(self).do_step, self, no_set_prior=False)  # type: ignore[method-assign]

    def _state_function(self, which: int) -> Callable[..., int]:
        from cosim.units.fmu.fmpy_internals import library

        function: Callable[..., int] = getattr(library(self._slave), self._state_calls[which])
        return function

    # Lifecycle shared by both versions ------------------------------------

    def reset(self) -> None:
        self._guard(f"{self._prefix}Reset", self._slave.reset)

    def terminate(self) -> None:
        if not self._alive:
            return
        self._alive = False
        self.generation += 1
        try:
            self._slave.terminate()
        except Exception:
            pass  # an FMU in error state may refuse terminate; freeing it still matters
        finally:
            self._slave.freeInstance()  # also unloads the library (fmpy), so the slave is never reused

    # Implemented per FMI version -------------------------------------------

    @abc.abstractmethod
    def do_step(self, t: float, h: float, no_set_prior: bool = True) -> None:
        """Unit.do_step; ``no_set_prior`` is doStep's noSetFMUStatePriorToCurrentPoint (False once a master
        may restore a saved state: :meth:`allow_restore`)."""

    def _bind(self, group: TypeGroup) -> tuple[Callable[[], int], Callable[[], int]]:
        """Calls that read / write the group's values from / into the FMU, returning the FMI status."""
        raise NotImplementedError
