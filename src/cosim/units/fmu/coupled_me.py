"""Connected Model Exchange FMUs integrated together: one solver over all their states.

Model Exchange units wired to each other form one continuous system.  Integrated
one by one (each with its own CVode inside the communication step, inputs held),
the values they exchange are frozen over each step: a first-order coupling error,
percents for a stiffly coupled pair.  :class:`CoupledModelExchange` integrates
them as one system instead, as OMSimulator does:

* the right-hand side sets each member's time and continuous states, then carries
  the members' outputs to their inputs along the internal connections, in
  dependency order (an output with direct feed-through is read after the inputs
  it depends on are set), then reads every member's derivatives;
* the event indicators of all members are one vector for CVode's root finding
  (**state events**); the next **time event** is the earliest any member
  announces; ``completedIntegratorStep`` is called on every member after each
  return of the solver (**step events**);
* an event, whichever member has it, takes every member to Event Mode: each
  iterates its discrete states, the internal connections carry the new outputs,
  and this repeats until no member needs an update and no internal input
  changed; then every member returns to Continuous-Time Mode and the solver
  restarts.  An input set from outside (by the master, at a communication point)
  is handled as for a single unit (a restart, or an event when it flips an
  indicator's sign).

From the outside the group is one co-simulation unit: its ports are the members'
ports, named ``member.variable`` (:meth:`CoupledModelExchange.port_name`), so a
master algorithm steps it like any other unit.  The members stay live units of
their own for everything but stepping (parameters, initialization, reading
outputs, terminate): their owner drives their lifecycle, and a member joined to a
group refuses ``do_step``.  The solver's tolerance is the tightest of the members'
tolerances and its largest step the smallest ``max_step`` any member sets (else the
communication step, :func:`~cosim.units.fmu.model_exchange.internal_step_cap`).
"""

from __future__ import annotations

import ctypes
from functools import partial
from typing import Any, Callable, Mapping, Protocol, Sequence

from cosim.units.fmu.model_exchange import MAX_EVENT_ITERATIONS, EventLoop, SolverSettings
from cosim.units.protocol import ElementRef, Selection, Unit, UnitDescription, UnitError, Variable

_DOUBLE_POINTER = ctypes.POINTER(ctypes.c_double)
_DOUBLE_SIZE = ctypes.sizeof(ctypes.c_double)


class InternalLink(Protocol):
    """A connection between two members (the system's connections have this form):
    ``target = factor * source + offset``, element by element."""

    # read-only properties: the system's connections are frozen dataclasses
    @property
    def source(self) -> Any: ...  # .unit (member name), .refs (ElementRefs of the member)
    @property
    def target(self) -> Any: ...
    @property
    def factor(self) -> float: ...
    @property
    def offset(self) -> float: ...


class _Propagation:
    """One internal connection, resolved once: reads the source member's outputs, sets the target's inputs."""

    def __init__(self, members: Mapping[str, Any], link: InternalLink):
        source, target = members[link.source.unit], members[link.target.unit]
        self.read = source.reader(source.select(list(link.source.refs)))
        self.target_selection = target.select(list(link.target.refs))
        self.write = target.set_within_group
        self.scale = None if (link.factor, link.offset) == (1.0, 0.0) else (link.factor, link.offset)
        self.last: list[Any] | None = None

    def run(self) -> bool:
        """Carry the values over; True when they differ from the last ones carried."""
        values = self.read()
        values = list(values) if self.scale is None else [self.scale[0] * v + self.scale[1] for v in values]
        self.write(self.target_selection, values)
        changed = values != self.last
        self.last = values
        return changed


Propagation = _Propagation  # public: the master's plans for loops among members carry plain links with it


class _GroupSelection(Selection):
    """Elements of the group's ports: per member, its own selection and where its values go in the flat list."""

    def __init__(self, refs: Sequence[ElementRef], parts: list[tuple[Any, Selection, list[int]]]):
        self.refs = tuple(refs)
        self.parts = parts


class CoupledModelExchange(EventLoop, Unit):
    """Model Exchange units integrated together by one CVode (module docstring).

    ``members``: live Model Exchange units (:class:`~cosim.units.fmu.model_exchange.Fmi2ModelExchangeUnit`,
    :class:`~cosim.units.fmu.model_exchange.Fmi3ModelExchangeUnit`, FMI versions may mix) by their names;
    they join the group here, before their initialization (so they start no solver of their own).
    ``links``: the connections between members, in the order their values must be carried (an output with
    direct feed-through after the connections into the inputs it depends on). Raises UnitError when a member
    cannot be integrated by a group.
    """

    def __init__(self, name: str, members: Mapping[str, Any], links: Sequence[InternalLink],
                 carry: Callable[[Mapping[str, Any], Callable[[], float]], list[Any]] | None = None):
        """``carry``: when the links cannot be carried one after the other (an algebraic loop among the members),
        makes what carries them instead, from the initialized members and a function giving the time of the
        evaluation: objects whose ``run()`` carries values and says whether an input changed (the master's loop
        solver, :func:`cosim.master.coupled_me.integrate_together`)."""
        self.name = name
        self._carry = carry
        self._rhs_time = 0.0
        self.time: float | None = None
        self.members = dict(members)
        for member_name, member in self.members.items():
            if not hasattr(member, "join"):
                raise UnitError(member_name, f"is not a Model Exchange unit, so '{name}' cannot integrate it", None)
            member.join(self)
        self._links = list(links)
        self._propagations: list[_Propagation] | None = None  # resolved at the first step (after initialization)
        self._carry_pending = False  # inputs set from outside, not yet carried along the internal connections
        settings = [m._settings for m in self.members.values()]
        steps = [s.max_step for s in settings if s.max_step is not None]
        self._init_loop(SolverSettings(tolerance=min(s.tolerance for s in settings),
                                       max_step=min(steps) if steps else None),
                        sum(m._nz for m in self.members.values()))
        self._nx = sum(m._nx for m in self.members.values())
        self._ports: dict[str, tuple[str, str]] = {}  # the group's port name -> (member, variable)
        variables = []
        for member_name, member in self.members.items():
            for v in member.description.variables:
                port = self.port_name(member_name, v.name)
                self._ports[port] = (member_name, v.name)
                variables.append(Variable(port, v.causality, v.type, v.unit, v.start, v.description, v.shape,
                                          v.min, v.max, v.variability, v.fmi_type, v.relative_quantity))
        self.description = UnitDescription(name=name, variables=tuple(variables), kind="model-exchange group",
                                           description=f"{', '.join(self.members)} integrated together")

    def port_name(self, member: str, variable: str) -> str:
        """The group's name for a member's variable: ``member.variable``."""
        return f"{member}.{variable}"

    # -- values ----------------------------------------------------------------------

    def select(self, refs: Sequence[ElementRef]) -> _GroupSelection:
        by_member: dict[str, tuple[list[ElementRef], list[int]]] = {}
        for i, ref in enumerate(refs):
            try:
                member, variable = self._ports[ref.variable]
            except KeyError:
                raise UnitError(self.name, f"has no port '{ref.variable}' (its ports are 'member.variable')",
                                self.time) from None
            own, where = by_member.setdefault(member, ([], []))
            own.append(ElementRef(variable, ref.offset))
            where.append(i)
        parts = [(self.members[m], self.members[m].select(own), where) for m, (own, where) in by_member.items()]
        return _GroupSelection(refs, parts)

    def get(self, selection: Selection) -> list[Any]:
        sel: _GroupSelection = selection  # type: ignore[assignment]  # the one this unit's select() made
        if self._carry_pending:  # inputs set from outside since the last step: outputs fed through members follow
            self._carry_pending = False
            self._propagate()
        out: list[Any] = [None] * len(sel.refs)
        for member, own, where in sel.parts:
            for i, value in zip(where, member.get(own)):
                out[i] = value
        return out

    def set(self, selection: Selection, values: Sequence[Any]) -> None:
        """Set members' inputs from outside (the master): the members note the change, as single units do."""
        sel: _GroupSelection = selection  # type: ignore[assignment]  # the one this unit's select() made
        for member, own, where in sel.parts:
            member.set(own, [values[i] for i in where])
        self._carry_pending = self._propagations is not None

    # -- lifecycle: the members' owner drives them; these do it for a group used on its own --------------

    def setup(self, start_time: float, stop_time: float | None) -> None:
        for member in self.members.values():
            member.setup(start_time, stop_time)

    def enter_initialization(self) -> None:
        for member in self.members.values():
            member.enter_initialization()

    def exit_initialization(self) -> None:
        for member in self.members.values():
            member.exit_initialization()

    def reset(self) -> None:
        self._solver = None
        for member in self.members.values():
            member.reset()

    def terminate(self) -> None:
        self._solver = None
        for member in self.members.values():
            member.terminate()

    # -- stepping --------------------------------------------------------------------

    def do_step(self, t: float, h: float) -> None:
        if self._solver is None:  # the first step: every member is initialized now
            self._now = self._rhs_time = t
            self._propagations = self._carriers()
            self._set_time(t)
            self._start_solver()
        changed = [m for m in self.members.values() if m._inputs_changed]
        if changed:  # the master set inputs from outside: carry them through the internal connections too
            for member in changed:
                member._inputs_changed = False
            self._propagate()
            self._inputs_changed = True
        super().do_step(t, h)

    def _carriers(self) -> list[Any]:
        """What carries the internal connections' values, in order (module docstring)."""
        if self._carry is not None:
            return self._carry(self.members, lambda: self._rhs_time)
        return [_Propagation(self.members, link) for link in self._links]

    def settle(self, t: float) -> None:
        """Carry the internal connections' values at ``t`` (after initialization, before the first step): with a
        loop among the members, the loop solved, so the values read at the start time satisfy it."""
        if self._carry is None:
            return
        self._now = self._rhs_time = t
        if self._propagations is None:
            self._propagations = self._carriers()
        self._propagate()

    def _propagate(self) -> bool:
        """Carry outputs to inputs along every internal connection; True when an input changed."""
        changed = False
        for propagation in self._propagations or ():
            changed = propagation.run() or changed
        return changed

    # -- the model for the solver loop -----------------------------------------------------

    def _solver_model(self) -> dict[str, Any]:
        states = [(m, m._nx) for m in self.members.values() if m._nx]
        indicators = [(m, m._nz) for m in self.members.values() if m._nz]

        def each(pairs: list[tuple[Any, int]], label: str,
                 call: Callable[[Any], Callable[..., Any]]) -> Callable[..., None]:
            """A callback over one vector of all members' values: each member's call on its slice."""
            def over_members(pointer: Any, _n: int) -> None:
                address, offset = ctypes.cast(pointer, ctypes.c_void_p).value, 0
                if address is None:  # kept by _caught, as any callback failure: the run fails naming the call
                    raise ValueError(f"{label}: the solver passed a NULL vector")
                for member, n in pairs:
                    part = ctypes.cast(address + offset * _DOUBLE_SIZE, _DOUBLE_POINTER)
                    member._guard(label, partial(call(member), part, n))  # a failure names the member
                    offset += n
            return over_members

        get_x = each(states, "getContinuousStates", lambda m: m._slave.getContinuousStates)
        set_states = each(states, "setContinuousStates", lambda m: m._slave.setContinuousStates)

        def set_x(pointer: Any, n: int) -> None:
            set_states(pointer, n)
            self._propagate()  # outputs follow the states, so do the inputs they feed

        def set_time(t: float) -> None:
            self._rhs_time = t  # a loop among the members is solved at this time (its guess extrapolates to it)
            for member in self.members.values():
                member._guard("setTime", partial(member._slave.setTime, t))

        return dict(nx=self._nx, nz=self._nz, get_x=self._caught(get_x), set_x=self._caught(set_x),
                    get_dx=self._caught(each(states, "getDerivatives", lambda m: m._get_derivatives())),
                    get_z=self._caught(each(indicators, "getEventIndicators", lambda m: m._slave.getEventIndicators)),
                    get_nominals=self._caught(each(states, "getNominalsOfContinuousStates",
                                                   lambda m: m._slave.getNominalsOfContinuousStates)),
                    set_time=self._caught(set_time))

    def _set_time(self, time: float) -> None:
        self._now = self._rhs_time = time
        for member in self.members.values():
            member._set_time(time)
        self._propagate()  # outputs may depend on time

    def _completed_integrator_step(self) -> bool:
        asked = False
        for member in self.members.values():
            asked = member._completed_integrator_step() or asked  # every member hears of the step
        return asked

    def _enter_event_mode(self) -> None:
        for member in self.members.values():
            member._enter_event_mode()

    def _event_iteration(self) -> None:
        """Every member's event iteration, then the internal connections, until nothing changes any more."""
        for _ in range(MAX_EVENT_ITERATIONS):
            for member in self.members.values():
                member._now = self._now
                member._event_iteration()
            if not self._propagate():
                return
        raise UnitError(self.name, f"the event iteration of the members did not settle in {MAX_EVENT_ITERATIONS} "
                        "rounds (their outputs keep changing each other's inputs)", self._now)

    def _enter_continuous_time_mode(self) -> None:
        for member in self.members.values():
            member._enter_continuous_time_mode()

    def _next_event_time(self) -> float | None:
        times = [t for t in (m._next_event_time() for m in self.members.values()) if t is not None]
        return min(times) if times else None

    def _read_indicators_into(self, buffer: Any) -> None:
        address, offset = ctypes.addressof(buffer), 0
        for member in self.members.values():
            if member._nz:
                member._read_indicators_into(ctypes.cast(address + offset * _DOUBLE_SIZE, _DOUBLE_POINTER))
                offset += member._nz

    def _callback_failure(self, exc: BaseException) -> UnitError:
        if isinstance(exc, UnitError):  # a member's FMI call failed (its _guard names it)
            return exc
        return UnitError(self.name, f"a call during integration failed: {type(exc).__name__}: {exc}", self._now)
