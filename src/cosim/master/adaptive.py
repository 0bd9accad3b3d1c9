"""Adaptive communication steps with error control: the master algorithm ``"adaptive"``.

Each communication step is taken by a fixed-step algorithm (Gauss-Seidel or Jacobi, ``base``); this
module chooses its length.  The error is measured on the *exchanged signals*: the outputs that feed
other units' inputs (Real ones; Integer and Boolean signals change only at events).  Two estimates,
chosen by what the units can do:

* **every unit can save and restore its state** (FMI ``canGetAndSetFMUstate``, a Python unit with
  ``get_state``/``set_state``): *step doubling*.  From the saved state the step is taken once with ``h``
  (result ``y1``), the state restored, then twice with ``h/2`` (``y2``).  Held inputs (zero-order hold)
  make the coupling first-order: a step's local error is ``c h^2``, so ``y2``'s is ``|y2 - y1|``.  The
  step is accepted when, for every signal,
  ``|y2 - y1| <= (atol + rtol * |y|) * h / (stop - start)``: each step may add only its share of the
  tolerance, so the error summed over the run stays within ``atol + rtol * |y|`` when the system does not
  amplify errors (a stable or an oscillating one).  A rejected step is restored and repeated with a
  smaller ``h``; an accepted one keeps ``y2`` (the two half steps).
* **some unit cannot restore**: the step cannot be repeated, so the controller only adapts the *next*
  step, as libcosim's ECCO does.  The estimate is the signals' change over the step, ``|y(t+h) - y(t)|``:
  how far a held input drifts from the value it stands for (the zero-order hold's error).  It should stay
  within ``atol + rtol * |y|``; a step that exceeds it is kept (counted in ``exceeded``) and the next one is
  shorter.

In both cases the next step is ``h * min(grow, max(shrink, safety / r))`` with ``r`` the largest ratio of
estimate to allowance (both estimates grow like ``h``), bounded by ``min_step`` and ``max_step`` and cut to
end exactly at the stop time.  A step that is still rejected at ``min_step`` is kept (``exceeded``).

A run ends: ``min_step`` defaults to ``1e-3 * rtol * step`` (rtol taken within [1e-6, 0.01]: the experiment's
step scaled by the relative tolerance, with room below it for steps that cross an event), and more than ``max_rejected`` tries in a row that miss the tolerance (steps rejected and
repeated, steps kept over it) end the run with :class:`~cosim.errors.StepControlError`, naming the counts, the
step reached and the signal farthest off.  Before, a unit whose outputs never met the tolerance (NaN, a
jump at every step) shrank the step to 1e-9 of the span and took ~10^9 steps: the run never ended.

Time: the fixed-step algorithms count whole steps (``t_k = start + k h``); here each step's end time
``t + h`` is computed once and is the next step's start, so every unit is stepped from exactly the time
it reached, and the last step ends exactly at ``stop``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence, TypeGuard

import numpy as np

from cosim.master.algorithms import GaussSeidel, Jacobi
from cosim.master.contract import MasterAlgorithm, SystemView
from cosim.master.transfers import Link
from cosim.units.protocol import Unit

SAFETY = 0.9  # aim below the allowance, so the next step is rarely rejected
GROW, SHRINK = 4.0, 0.2  # the most a step may grow or shrink at once
# How the estimates grow with the step h: held inputs make the coupling first-order, so a step's local error
# (step doubling) grows like h**2 and a signal's change over the step like h.
DOUBLING_ORDER, CHANGE_ORDER = 2, 1
BASES = {GaussSeidel.name: GaussSeidel, Jacobi.name: Jacobi}
RESTORE_MODES = ("auto", "never")
MAX_REJECTED = 100  # tries in a row that miss the tolerance before the run fails (experiment.adaptive.max_rejected)
# the default min_step is MIN_STEP_SCALE * rtol * step, rtol taken within RTOL_RANGE (an atol-only or a loose
# tolerance still gets one): three decades below the step a tolerance of rtol would ask for in step doubling
MIN_STEP_SCALE, RTOL_RANGE = 1e-3, (1e-6, 1e-2)


@dataclass(frozen=True)
class AdaptiveSettings:
    """The options of ``experiment.adaptive`` (all optional) and the run's span.

    ``rtol``/``atol``: relative and absolute tolerance on the exchanged signals; ``min_step`` and
    ``max_step`` bound the step (defaults: ``1e-3 * rtol * initial_step``, rtol within [1e-6, 0.01], at most
    ``max_step``, and ``stop - start``); ``max_rejected``: the most tries in a row that miss the tolerance
    before the run fails; ``initial_step``
    is the experiment's ``step``; ``base`` the fixed-step algorithm taking each step; ``restore``:
    ``"auto"`` rejects and repeats steps where every unit can restore its state, ``"never"`` only adapts.
    Raises ValueError for values that cannot work (the spec check reports them first, at their path).
    """

    start: float
    stop: float
    initial_step: float
    rtol: float = 1e-4
    atol: float = 1e-6
    min_step: float | None = None
    max_step: float | None = None
    max_rejected: int = MAX_REJECTED
    base: str = GaussSeidel.name
    restore: str = "auto"

    def __post_init__(self) -> None:
        for name in ("rtol", "atol"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, not {value!r}")
        if self.rtol == 0 and self.atol == 0:
            raise ValueError("rtol and atol cannot both be 0")
        if not self.min_step_or_default > 0 or not self.max_step_or_default >= self.min_step_or_default:
            raise ValueError(f"need 0 < min_step <= max_step, not {self.min_step!r} and {self.max_step!r}")
        if isinstance(self.max_rejected, bool) or not isinstance(self.max_rejected, int) or self.max_rejected < 1:
            raise ValueError(f"max_rejected must be a whole number >= 1, not {self.max_rejected!r}")
        if self.base not in BASES:
            raise ValueError(f"base must be one of {', '.join(BASES)}, not {self.base!r}")
        if self.restore not in RESTORE_MODES:
            raise ValueError(f"restore must be one of {', '.join(RESTORE_MODES)}, not {self.restore!r}")

    @property
    def span(self) -> float:
        return self.stop - self.start

    @property
    def min_step_or_default(self) -> float:
        if self.min_step is not None:
            return self.min_step
        low, high = RTOL_RANGE
        return min(MIN_STEP_SCALE * min(max(self.rtol, low), high) * self.initial_step, self.max_step_or_default)

    @property
    def max_step_or_default(self) -> float:
        return self.max_step if self.max_step is not None else self.span

    @classmethod
    def for_experiment(cls, experiment: Any) -> "AdaptiveSettings":
        """Settings from an experiment (``start``, ``stop``, ``step`` and the options ``adaptive``)."""
        options = dict(getattr(experiment, "adaptive", None) or ())
        return cls(start=experiment.start, stop=experiment.stop, initial_step=experiment.step, **options)


def option_problems(options: Mapping[str, Any]) -> list[tuple[str, str, str]]:
    """What the JSON Schema cannot say about ``experiment.adaptive``: (field or "", what is wrong, the fix)."""
    problems = []
    rtol, atol = options.get("rtol", AdaptiveSettings.rtol), options.get("atol", AdaptiveSettings.atol)
    if _number(rtol) and _number(atol) and rtol == 0 and atol == 0:
        problems.append(("", "rtol and atol are both 0: no error would be small enough",
                         "give a positive rtol or atol"))
    low, high = options.get("min_step"), options.get("max_step")
    if _number(low) and _number(high) and low > high:
        problems.append(("min_step", f"min_step ({low}) is larger than max_step ({high})",
                         "make min_step at most max_step"))
    return problems


def _number(value: Any) -> TypeGuard[int | float]:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


@dataclass
class StepStatistics:
    """What the controller did: steps ``accepted`` (recorded), ``rejected`` (restored and repeated),
    ``exceeded`` (kept over the tolerance: no restore, or already at ``min_step``), the ``smallest`` and
    ``largest`` accepted step, and the ``estimate`` used (``"step doubling"`` or ``"signal change"``)."""

    estimate: str
    base: str = GaussSeidel.name
    accepted: int = 0
    rejected: int = 0
    exceeded: int = 0
    smallest: float = math.inf
    largest: float = 0.0
    base_steps: int = 0  # steps of the base algorithm, repeated ones and half steps included (the work done)
    missed: int = 0  # tries in a row that missed the tolerance (rejected or exceeded), up to now

    def as_dict(self) -> dict[str, Any]:
        return {"estimate": self.estimate, "base": self.base, "accepted": self.accepted, "rejected": self.rejected,
                "exceeded": self.exceeded, "smallest": self.smallest if self.accepted else math.nan,
                "largest": self.largest if self.accepted else math.nan, "base_steps": self.base_steps}


def describe_statistics(stats: Mapping[str, Any]) -> str:
    """One line on what the controller did (``RunResult.step_stats``), for ``cosim run``."""
    if not stats.get("accepted"):
        return f"adaptive steps ({stats.get('estimate')}): none accepted"
    return (f"adaptive steps ({stats['estimate']}): {stats['accepted']} accepted, {stats['rejected']} rejected "
            f"and repeated, {stats['exceeded']} kept over the tolerance; step {stats['smallest']:.3g} .. "
            f"{stats['largest']:.3g} s; {stats['base_steps']} steps of {stats['base']} in all")


class ExchangedSignals:
    """The Real outputs that feed inputs, read into one float vector (each distinct element once)."""

    def __init__(self, units: Mapping[str, Unit], links: Sequence[Link]):
        per_unit: dict[str, dict[Any, None]] = {}
        for link in links:
            unit = units[link.source.unit]
            types = {v.name: v.type for v in unit.description.variables}
            for ref in link.source.refs:
                if types.get(ref.variable) == "Real":
                    per_unit.setdefault(link.source.unit, {})[ref] = None
        self._reads = []
        self.names: list[str] = []  # "unit.variable" (with "[i]", 1-based, for an array's element) per element
        n = 0
        for name, refs in per_unit.items():
            unit = units[name]
            self._reads.append((unit.reader(unit.select(list(refs))), slice(n, n + len(refs))))
            self.names += [f"{name}.{ref.variable}" + (f"[{ref.offset + 1}]" if ref.offset else "") for ref in refs]
            n += len(refs)
        self.size = n

    def read(self) -> np.ndarray:
        """A fresh vector (a copy: readers may hand out buffers the next call overwrites)."""
        values = np.empty(self.size)
        for read, where in self._reads:
            values[where] = read()
        return values


class Adaptive(MasterAlgorithm):
    """The adaptive master algorithm (module docstring), made for an experiment (``start``, ``stop``, ``step``
    and the options ``adaptive``; raises ValueError for options that cannot work).  Each :meth:`advance` takes
    one accepted step; :meth:`statistics` says what happened."""

    name = "adaptive"
    solves_loops = True  # as its base algorithms: the coupling is handed on to them

    def __init__(self, experiment: Any):
        self.settings = AdaptiveSettings.for_experiment(experiment)
        self.stats = StepStatistics("step doubling")

    def bind(self, view: SystemView) -> None:
        self.view = view
        s = self.settings
        self._base = BASES[s.base]()
        self._base.bind(view)
        self._units = list(view.units.values())
        self._signals = ExchangedSignals(view.units, view.links)
        self.restores = s.restore == "auto" and all(u.can_save_state for u in self._units)
        if self.restores:
            for unit in self._units:
                unit.allow_restore()
        self.stats = StepStatistics("step doubling" if self.restores else "signal change", s.base)
        self._saved: list[Any] = [None] * len(self._units)
        self._h = min(max(s.initial_step, s.min_step_or_default), s.max_step_or_default)
        self._y: np.ndarray | None = None  # the signals at the current time

    def start(self, t: float) -> None:
        self._base.start(t)  # its loops solved and the view's groups settled

    def advance(self, t: float) -> float:
        """Take one accepted step from ``t`` (repeating rejected tries where units can restore); returns
        the time reached, exactly ``stop`` for the last step."""
        if self._y is None:
            self._y = self._signals.read()
            self._size = np.abs(self._y)  # each signal's largest magnitude so far: what rtol is relative to
        return self._advance_restoring(t) if self.restores else self._advance_adapting(t)

    def statistics(self) -> dict[str, Any]:
        return self.stats.as_dict()

    def free(self) -> None:
        """Release the saved states (call before the units are terminated)."""
        for unit, state in zip(self._units, self._saved):
            if state is not None:
                unit.free_state(state)
        self._saved = [None] * len(self._units)

    # -- the two controllers ------------------------------------------------------------------------

    def _advance_restoring(self, t: float) -> float:
        s, stats, base = self.settings, self.stats, self._base
        for i, unit in enumerate(self._units):
            self._saved[i] = unit.save_state(self._saved[i])
        while True:
            h, t_next = self._step_to(t)
            base.step(t, t_next - t)
            y1 = self._signals.read()
            for unit, state in zip(self._units, self._saved):
                unit.restore_state(state)
            t_mid = t + 0.5 * (t_next - t)
            base.step(t, t_mid - t)
            base.step(t_mid, t_next - t_mid)
            stats.base_steps += 3
            y2 = self._signals.read()
            allowance = s.atol + s.rtol * np.maximum(self._size, np.abs(y2))
            ratio = _largest_ratio(np.abs(y2 - y1), allowance)
            at_floor = h <= s.min_step_or_default * (1 + 1e-12)
            if ratio <= 1.0 or at_floor:
                if ratio > 1.0:
                    stats.exceeded += 1
                    self._missed(t, h, np.abs(y2 - y1), allowance, y2)
                else:
                    stats.missed = 0
                self._accept(t_next - t, ratio, DOUBLING_ORDER)
                self._y = y2
                np.maximum(self._size, np.abs(y2), out=self._size)
                return t_next
            stats.rejected += 1
            self._missed(t, h, np.abs(y2 - y1), allowance, y2)
            for unit, state in zip(self._units, self._saved):
                unit.restore_state(state)
            self._h = max(h * _factor(ratio, DOUBLING_ORDER), s.min_step_or_default)

    def _advance_adapting(self, t: float) -> float:
        s, stats = self.settings, self.stats
        h, t_next = self._step_to(t)
        self._base.step(t, t_next - t)
        stats.base_steps += 1
        y = self._signals.read()
        allowance = s.atol + s.rtol * np.maximum(self._size, np.abs(y))
        ratio = _largest_ratio(np.abs(y - self._y), allowance)
        if ratio > 1.0:
            stats.exceeded += 1  # cannot be repeated: the next step is shorter instead
            self._missed(t, h, np.abs(y - self._y), allowance, y)
        else:
            stats.missed = 0
        self._accept(t_next - t, ratio, CHANGE_ORDER)
        self._y = y
        np.maximum(self._size, np.abs(y), out=self._size)
        return t_next

    def _missed(self, t: float, h: float, estimate: np.ndarray, allowance: np.ndarray, y: np.ndarray) -> None:
        """Count a try that missed the tolerance; past ``max_rejected`` in a row, end the run (StepControlError)."""
        stats, s = self.stats, self.settings
        stats.missed += 1
        if stats.missed <= s.max_rejected:
            return
        from cosim.errors import StepControlError

        with np.errstate(divide="ignore", invalid="ignore"):
            ratios = np.where(np.isnan(estimate), np.inf, estimate / np.where(allowance > 0, allowance, np.nan))
        worst = int(np.argmax(np.nan_to_num(ratios, nan=np.inf))) if estimate.size else 0
        name = self._signals.names[worst] if estimate.size else "?"
        if not math.isfinite(float(y[worst])):
            off = f"the exchanged signal {name} is {float(y[worst])}"
        else:
            off = (f"the exchanged signal farthest off is {name}: its error estimate {float(estimate[worst]):.3g} "
                   f"where {float(allowance[worst]):.3g} is allowed")
        raise StepControlError(name.split(".")[0], f"{stats.missed} tries in a row missed the tolerance (rtol "
                               f"{s.rtol:g}, atol {s.atol:g}; max_rejected {s.max_rejected}), the last with a step of "
                               f"{h:.3g} s (min_step {s.min_step_or_default:.3g} s); {off}. Loosen rtol or atol, "
                               "lower min_step or raise max_rejected in experiment.adaptive, or check that unit's "
                               "outputs", t)

    def _step_to(self, t: float) -> tuple[float, float]:
        """(the step the controller wants, the end time of this step): cut to end exactly at ``stop``, and
        stretched to it when the rest would be a sliver shorter than ``min_step``."""
        s = self.settings
        h = self._h
        rest = s.stop - t
        if h >= rest or rest - h < s.min_step_or_default:
            return h, s.stop
        return h, t + h

    def _accept(self, taken: float, ratio: float, order: int) -> None:
        stats, s = self.stats, self.settings
        stats.accepted += 1
        stats.smallest = min(stats.smallest, taken)
        stats.largest = max(stats.largest, taken)
        self._h = min(max(taken * _factor(ratio, order), s.min_step_or_default), s.max_step_or_default)


def _factor(ratio: float, order: int) -> float:
    """How much to change a step whose estimate is ``ratio`` times its allowance, for an estimate that grows
    like ``h**order``: toward ``SAFETY`` times the allowance, at most by GROW or SHRINK at once."""
    if ratio == 0:
        return GROW
    scale: float = ratio ** (-1.0 / order)  # float ** float is typed Any (it may be complex)
    return min(GROW, max(SHRINK, SAFETY * scale))


def _largest_ratio(estimate: np.ndarray, allowance: np.ndarray) -> float:
    """max(estimate / allowance), 0 for no signals; a NaN estimate counts as infinitely too large."""
    if not estimate.size:
        return 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        ratios = np.where(allowance > 0, estimate / allowance, np.where(estimate > 0, np.inf, 0.0))
    # a NaN signal makes its allowance NaN too (rtol * |y|), which the comparisons above read as "no error"
    ratios = np.where(np.isnan(estimate), np.inf, ratios)
    ratio = float(np.max(ratios))
    return math.inf if math.isnan(ratio) else ratio
