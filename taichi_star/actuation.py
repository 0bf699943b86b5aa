"""Actuation: the curvature an SMA actuator takes over one cycle (paper Eq. 5), and the
`Schedule` of when each actuator fires.

A fired actuator's arc follows K̄(τ), τ the time since it fired: a logistic fall while the SMA
wire heats (τ < t0), then a logistic recovery while it cools. The fit does not close on itself
(K̄ just before the next cycle is not K̄(0)); `closure="ramp"` spreads the difference linearly
over the period so that a periodic gait has a continuous natural curvature.

What fires when, for every instance of a batch on the device, is one `Schedule`: a periodic
gait (`simulate`), commanded firings (`Simulator.fire`), or both. Both step controllers of the
engine ask its `fire_due` what fires in a step; `command` is the one way in for commands.
"""

import ast
import functools
from dataclasses import dataclass
from typing import Dict, Optional, Tuple

import numpy as np
import taichi as ti
from taichi.lang.field import Field

from .checks import check_finite, check_not_subnormal, is_finite_real
from .fields import FieldStore
from .gait import N_ACTUATORS

PROFILE_CLOSURES = ("jump", "ramp")
NEVER = -1.0
"""fire_time of an actuator that has not fired; the due time of no firing."""
SWITCH_SNAP = 1e-12
"""A time since firing τ within this share of max(|t|, 1 s) of the profile's switch t0 (t the
time, s) is t0, on the cooling branch (our convention: Eq. 5 is written for τ < t0 and τ > t0,
and leaves t0 open). Fixed steps end exactly on t0 after a
firing on the step grid, but τ, a difference of two step ends (or the time modulo the period),
rounds to either side of it, so the branch read there depended on the rounding: the engine
read heating at 8 of the paper robot's first 20 cycles and the NumPy reference at 6, not the
same ones (an audit, 2026-12; Eq. 5 jumps by 0.0064 1/m there, a custom profile by any
amount). 1e-12 of the time is thousands of f64 roundings and far less than any step; in f32
the rounding is larger, and τ is read as it comes."""
PENDING_CAPACITY = 16
"""Commanded firings an instance holds pending: distinct times, each firing any set of its
actuators."""


def snapped_to_switch(tau: float, switch_time: float, time_s: float) -> float:
    """τ (s), or the switch t0 (s) where τ lies within SWITCH_SNAP × max(|time_s|, 1 s) of it."""
    return switch_time if abs(tau - switch_time) <= SWITCH_SNAP * max(abs(time_s), 1.0) else tau


def _logistic(constants, tau):
    """c1/(1 + exp(−c2 (τ − c3))) + c4 for one branch's constants (c1..c4) at τ (s, scalar or
    array): one branch of Eq. 5, 1/m."""
    c1, c2, c3, c4 = constants
    return c1 / (1.0 + np.exp(-c2 * (np.asarray(tau, dtype=np.float64) - c3))) + c4


def _finite_numbers(values) -> bool:
    """Whether `values` is a sequence of real numbers (NumPy's included, none a bool) that
    floats hold as finite numbers (`is_finite_real`)."""
    return isinstance(values, (tuple, list, np.ndarray)) and all(is_finite_real(v)
                                                                 for v in values)


def _check_period(period) -> None:
    """ValueError naming period unless it is a finite number > 0 s (0 gave NaN)."""
    check_finite("period", period, 0.0, unit=" s")


@dataclass(frozen=True)
class CurvatureProfile:
    """Logistic fit of one actuator's natural curvature over a cycle (paper Eq. 5).

    K̄(τ) = c1/(1 + exp(−c2 (τ − c3))) + c4, with the heating constants for τ < t0 and the
    cooling constants for τ ≥ t0; τ in s, K̄ in 1/m. The defaults are the paper's fit.
    """

    heating: Tuple[float, float, float, float] = (-89.827, 62.724, 0.061, 104.040)
    """(c1a 1/m, c2a 1/s, c3a s, c4a 1/m) while the wire heats."""
    cooling: Tuple[float, float, float, float] = (94.777, 2.507, 1.019, 4.445)
    """(c1d 1/m, c2d 1/s, c3d s, c4d 1/m) while it cools."""
    switch_time: float = 0.163
    """t0, s: the end of the heating phase, where the curvature is smallest; > 0."""

    def __post_init__(self):
        for name in ("heating", "cooling"):
            given = getattr(self, name)
            # + 0.0: a zero as +0.0, as StarParams' numbers (equal profiles are the same bits)
            # checked before float(): 10**400 raised an OverflowError (an audit, 2026-12)
            values = tuple(float(v) + 0.0 for v in given) if _finite_numbers(given) else ()
            if len(values) != 4:
                raise ValueError(f"CurvatureProfile.{name} must be 4 finite numbers, got "
                                 f"{given!r}")
            # as StarParams' fields: one number before Taichi's start and 0 after otherwise;
            # read from the values given (the + 0.0 above flushes them once Taichi has started)
            for index, value in enumerate(given):
                check_not_subnormal(f"CurvatureProfile.{name}[{index}]", value)
            object.__setattr__(self, name, values)
        check_finite("CurvatureProfile.switch_time", self.switch_time, 0.0, unit=" s")
        check_not_subnormal("CurvatureProfile.switch_time", self.switch_time)
        object.__setattr__(self, "switch_time", float(self.switch_time))
        if not self.rest_curvature > 0:
            raise ValueError(f"CurvatureProfile: K̄(0) must be > 0 1/m (the rest arc), got "
                             f"{self.rest_curvature!r}")

    def to_text(self) -> str:
        """The profile as one line of text, its repr (every constant to the last bit), which
        `from_text` reads back; how result tables store it."""
        return repr(self)

    @classmethod
    def from_text(cls, text: str) -> "CurvatureProfile":
        """The profile written by `to_text` ("CurvatureProfile(heating=(...), cooling=(...),
        switch_time=...)"); ValueError naming actuator_profile for any other text."""
        try:
            call = ast.parse(str(text).strip(), mode="eval").body
            if not (isinstance(call, ast.Call) and isinstance(call.func, ast.Name)
                    and call.func.id == cls.__name__ and not call.args):
                raise ValueError
            values = {keyword.arg: ast.literal_eval(keyword.value) for keyword in call.keywords}
            return cls(**values)
        except (SyntaxError, ValueError, TypeError):
            raise ValueError(f"actuator_profile: {str(text)[:80]!r} is not a profile's text "
                             f"(CurvatureProfile(heating=(4 numbers), cooling=(4 numbers), "
                             f"switch_time=number))") from None

    def as_array(self) -> np.ndarray:
        """(9,) float64: the nine constants in the order the kernels read them, the heating
        branch's c1a..c4a, the cooling branch's c1d..c4d (c1 and c4 in 1/m, c2 in 1/s, c3 in s:
        `_logistic`), then the switch time t0 (s)."""
        return np.array([*self.heating, *self.cooling, self.switch_time], dtype=np.float64)

    def curvature(self, tau):
        """K̄(τ) in 1/m for τ (s) since firing; scalar or array (Eq. 5 as fitted, no closure)."""
        tau = np.asarray(tau, dtype=np.float64)
        out = np.where(tau < self.switch_time, _logistic(self.heating, tau),
                       _logistic(self.cooling, tau))
        return float(out) if out.ndim == 0 else out

    @property
    def switch_jump(self) -> float:
        """K̄ just after t0 minus just before, 1/m: the two fitted branches do not quite meet
        (the paper's fit: 0.0064 1/m, 0.004 % of the stroke)."""
        return float(_logistic(self.cooling, self.switch_time)
                     - _logistic(self.heating, self.switch_time))

    def closure_gap(self, period: float) -> float:
        """K̄(0) − K̄(T), 1/m: the step of the natural curvature where a new cycle starts.
        ValueError naming period unless it is a finite number > 0 s."""
        _check_period(period)
        return self.rest_curvature - self.curvature(period)

    def cycle_curvature(self, tau, period: float, closure: str = "jump"):
        """K̄ over a cycle of `period` s with the given closure: "jump" = Eq. 5 as fitted,
        "ramp" = K̄(τ) + (K̄(0) − K̄(T))·τ/T (continuous from one cycle to the next).
        ValueError naming period unless it is a finite number > 0 s (0 gave NaN), or
        closure."""
        _check_period(period)
        if closure not in PROFILE_CLOSURES:
            raise ValueError(f"closure must be one of {list(PROFILE_CLOSURES)}, got {closure!r}")
        value = self.curvature(tau)
        if closure == "ramp":
            value = value + self.closure_gap(period) * np.asarray(tau, dtype=np.float64) / period
        return value

    @functools.cached_property
    def rest_curvature(self) -> float:
        """K̄(0), 1/m: the curvature of an actuator at rest (the arcs of the rest shape); kept
        once computed (the profile is immutable, and a batch asks each instance's)."""
        return self.curvature(0.0)


@ti.data_oriented
class Schedule:
    """When the actuators of `capacity` instances fire, on the device: a periodic gait, pending
    commanded firings (at most `PENDING_CAPACITY` distinct times per instance, each any set of
    actuators), and each actuator's last two firings, which the bending term reads. Shapes
    (capacity, 8) per actuator, (capacity,) per instance, (capacity, PENDING_CAPACITY) per
    pending firing.

    A command is due at a reading of the stepping's clock: with fixed steps the step number
    (a firing due at step k happens at that step's end, k·dt, exactly as the periodic gait's),
    with adaptive steps the time in s (the controller ends a step on it). `time`: the state's
    field of each instance's current time, s (what firing now reads)."""

    FIELD_NAMES = ("fire_time", "previous_fire_time", "gait_mask", "gait_period",
                   "gait_cycle_steps", "gait_cycles", "pending_due", "pending_actuators",
                   "pending_count")
    """The fields a state saves and restores (`fields`)."""

    def __init__(self, capacity: int, arena, time: Field):
        self.time = time
        self.fire_time = arena.batch_field(float, (capacity, N_ACTUATORS))
        """Time (s) each actuator last fired; NEVER when it has not."""
        self.previous_fire_time = arena.batch_field(float, (capacity, N_ACTUATORS))
        """The firing before that (it still applies to times before `fire_time`)."""
        self.gait_mask = arena.batch_field(ti.i32, (capacity, N_ACTUATORS))
        """Actuators the periodic gait fires at the start of every cycle (none: commands only)."""
        self.gait_period = arena.batch_field(float, capacity)
        """Period of the gait, s; 0: no periodic gait."""
        self.gait_cycle_steps = arena.batch_field(ti.i32, capacity)
        """Fixed steps per period when the period is a whole number of steps, else 0."""
        self.gait_cycles = arena.batch_field(ti.i32, capacity)
        """The last cycle of the gait begun (0 at t = 0) as counted so far: the steps count
        only the cycles begun by their start, so that a rejected adaptive step leaves the count
        as it was."""
        self.pending_due = arena.batch_field(float, (capacity, PENDING_CAPACITY))
        """Clock readings of the commanded firings, increasing (the first `pending_count`):
        those after the instance's clock are pending, those at or before it have fired (they
        leave when the next command is queued)."""
        self.pending_actuators = arena.batch_field(ti.i32, (capacity, PENDING_CAPACITY))
        """The actuators each pending firing fires: bit m for actuator A(m+1)."""
        self.pending_count = arena.batch_field(ti.i32, capacity)
        """Entries of the pending firings in use."""
        self._pending_store: Optional[FieldStore] = None

    def fields(self) -> Dict[str, Field]:
        """The schedule's fields by name (`FIELD_NAMES`)."""
        return {name: getattr(self, name) for name in self.FIELD_NAMES}

    @property
    def pending_store(self) -> FieldStore:
        """The pending firings' fields in one copy each way (made at the first scheduled
        command: three kernels each way to compile otherwise)."""
        if self._pending_store is None:
            self._pending_store = FieldStore({name: getattr(self, name) for name in
                                              ("pending_due", "pending_actuators", "pending_count")})
        return self._pending_store

    # ---------------------------------------------------------------- device side
    @ti.func
    def fire(self, b, m, time):
        """Actuator m of instance b fires at `time` (s); the firing it held becomes the previous
        one, which still applies before `time`. The rule "previous ← current, current ← now",
        written once. Firing at the time it last fired changes nothing: a rejected adaptive step
        and its retry both fire what they end on."""
        if self.fire_time[b, m] != time:
            self.previous_fire_time[b, m] = self.fire_time[b, m]
            self.fire_time[b, m] = time

    @ti.func
    def next_firing(self, b, time):
        """The time (s) of instance b's first firing after its current time `time` (s), with
        adaptive steps: the next cycle start of its periodic gait or its next pending command,
        whichever comes first; NEVER when there is none. Counts the cycles begun by `time`."""
        due = NEVER
        period = self.gait_period[b]
        if period > 0.0:
            cycle = self.gait_cycles[b]
            while period * (cycle + 1) <= time:
                cycle += 1
            self.gait_cycles[b] = cycle
            due = period * (cycle + 1)
        entry = 0
        while entry < self.pending_count[b] and self.pending_due[b, entry] <= time:
            entry += 1
        if entry < self.pending_count[b]:
            command = self.pending_due[b, entry]
            if due < 0.0 or command < due:
                due = command
        return due

    @ti.func
    def fire_due(self, b, start, end, step):
        """Fire what instance b has due in its step from `start` to `end` (s): `step` is the
        step's number with fixed steps (the clock counts steps: the step is (step − 1, step]),
        0 with adaptive steps (the clock reads s: the step is (start, end], and the controller
        ends it on the first firing due, `next_firing`). Eq. 5 is right-continuous (a firing at
        t sets K̄(0) at t), so the step that ends on a firing already sees it.

        Pending commands due in the step fire at its end. The periodic gait fires where a cycle
        begins in the step: at its end when the period is a whole number of fixed steps (so
        that a command for the same step gives the same bits), else at the exact time k·T (with
        adaptive steps, the step's end). An actuator due twice in a step fires once, at the
        later time. Nothing is counted past the step's start (a rejected adaptive step is
        retried from there)."""
        clock_start, clock_end = start, end
        if step > 0:
            clock_start, clock_end = ti.cast(step - 1, float), ti.cast(step, float)
        commanded = 0
        entry = 0
        while entry < self.pending_count[b] and self.pending_due[b, entry] <= clock_end:
            if self.pending_due[b, entry] > clock_start:
                commanded |= self.pending_actuators[b, entry]
            entry += 1
        periodic_at = NEVER
        period = self.gait_period[b]
        if step > 0 and self.gait_cycle_steps[b] > 0:
            if step % self.gait_cycle_steps[b] == 0:
                periodic_at = end
        elif period > 0.0:
            cycle = self.gait_cycles[b]
            while period * (cycle + 1) <= end:
                cycle += 1
                if period * cycle > start:
                    periodic_at = period * cycle
                else:
                    self.gait_cycles[b] = cycle
        for m in range(N_ACTUATORS):
            at = NEVER
            if self.gait_mask[b, m] != 0:
                at = periodic_at
            if (commanded >> m) & 1:
                at = end
            if at >= 0.0:
                self.fire(b, m, at)

    @ti.kernel
    def fire_now(self, actuators: ti.types.ndarray()):
        """Fire the actuators of bits actuators[b] ((B,) int32) of the first B instances at
        each one's current time."""
        for b in range(actuators.shape[0]):
            for m in range(N_ACTUATORS):
                if (actuators[b] >> m) & 1:
                    self.fire(b, m, self.time[b])

    # ---------------------------------------------------------------- host side
    def periodic_values(self, values: Dict[str, np.ndarray], masks: np.ndarray,
                        periods: np.ndarray, cycle_steps: np.ndarray):
        """Set, in a state's `values` (`state.BatchState.initial_values`), every instance to
        fire its gait (`masks`: (capacity, 8) 0/1) at t = 0 and at the start of every cycle
        (`periods`: (capacity,) s; `cycle_steps`: (capacity,) fixed steps per period, 0 where
        the period is not a whole number of steps)."""
        values["gait_mask"] = masks
        values["gait_period"] = periods
        values["gait_cycle_steps"] = cycle_steps
        values["fire_time"] = np.where(masks != 0, 0.0, NEVER)

    def command(self, actuators: np.ndarray, due: Optional[float] = None,
                clock: Optional[np.ndarray] = None, step_s: Optional[float] = None):
        """Fire actuators of the first B instances (`actuators`: (B, 8) bool, column m for
        actuator A(m+1)): with `due` None now, each instance at its current time (acting on the
        steps after it); else at the clock reading `due` (a step number with fixed steps, a time
        in s with adaptive ones), added to the firings pending (the same reading again adds the
        actuators to that firing). `clock`: (B,) each instance's clock reading now; `step_s`:
        the fixed step (s) when the clock counts steps, None when it reads seconds.

        Raises ValueError, nothing changed, where `due` is not after the clock of an instance
        with actuators to fire, is a step number past those the clock's float type counts
        exactly (f32: beyond 2²⁴ steps), or would be a firing beyond the `PENDING_CAPACITY` an
        instance holds pending."""
        actuators = np.asarray(actuators, dtype=bool)
        bits = (actuators.astype(np.int32) << np.arange(N_ACTUATORS, dtype=np.int32)).sum(
            axis=1, dtype=np.int32)
        if due is None:
            self.fire_now(bits)
            return
        pending_now = self.pending_store.read()
        dues, entries, counts = (pending_now[name] for name in
                                 ("pending_due", "pending_actuators", "pending_count"))
        at = dues.dtype.type(due)
        seconds = float(due) * (step_s if step_s is not None else 1.0)
        # every step up to 2^(mantissa + 1) is a whole float; past it `fire_due` compares the
        # step numbers as that float, rounded to even neighbours, and an even due step past
        # 2^24 in f32 (held exactly, accepted: an audit, 2026-12) could fire a step early
        exact_steps = 2 ** (np.finfo(dues.dtype).nmant + 1)
        if step_s is not None and (float(at) != due or due > exact_steps):
            raise ValueError(f"at_s = {seconds:.6g} s is step {due}, past the steps the "
                             f"clock's {dues.dtype} counts exactly (at most step "
                             f"{exact_steps}); use precision 'f64'")
        rows = np.flatnonzero(bits)
        late = rows[~(clock[rows] < at)]
        if len(late):
            now = float(clock[late[0]]) * (step_s if step_s is not None else 1.0)
            raise ValueError(f"at_s = {seconds:.6g} s is not after the current time of instance "
                             f"{int(late[0])} ({now:.6g} s); fire without at_s to fire now")
        for b in rows:
            # the firings at or before the clock have happened: they leave the queue here
            pending = dues[b, :counts[b]] > clock[b]
            times, fired = dues[b, :counts[b]][pending], entries[b, :counts[b]][pending]
            place = int(np.searchsorted(times, at))
            if place < len(times) and times[place] == at:
                fired[place] |= bits[b]
            elif len(times) == PENDING_CAPACITY:
                raise ValueError(f"at_s = {seconds:.6g} s: instance {int(b)} already has "
                                 f"{PENDING_CAPACITY} firings pending, the most it holds "
                                 f"(PENDING_CAPACITY); advance past one, then schedule this one")
            else:
                times, fired = np.insert(times, place, at), np.insert(fired, place, bits[b])
            counts[b] = len(times)
            dues[b, :len(times)], entries[b, :len(times)] = times, fired
        self.pending_store.write({"pending_due": dues, "pending_actuators": entries,
                                  "pending_count": counts})
