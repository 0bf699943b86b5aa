"""Sensitivities of a run's outputs with respect to per-instance parameters.

`simulate(params, T, sensitivities=("alpha", "drag_perpendicular"))` gives, for every instance,
the derivative of each output with respect to each named StarParams field: the derivative of the
discrete scheme by the implicit function theorem at every step, with the partial derivatives of
the residual taken as central differences of a residual made linear in the replicas' offsets
(measured against extrapolated differences of whole runs: within 1e-5 over three cycles,
mostly ~1e-6; docs/numerics.md).

How: for each direction (a field, or one number of a per-actuator field) every instance b gets
a pair of replicas in the same engine, at its parameters moved by ±ε, whose tables (rest
shape, masses, coefficients) lie on b's tangent (`replica_model`).
The replicas are never solved. After each accepted step of b, the engine moves them to b's new
state ± ε times the state's exact derivative, from the implicit function theorem on b's step
(`engine.BatchEngine.tangent_step`): the step's Jacobian at the converged state, factored once,
times the derivative equals minus the derivative of the residual with respect to the parameter
and to the step's start state. The replicas' own residuals, assembled at b's converged state
from their own start states and coefficients, give that right-hand side as a central
difference, and every term and extension is covered without derivative code of its own; a
term whose force is not linear in the velocity expands a replica's force about b's velocity
with the velocity derivative it computes for Newton anyway (`physics.assembly.Assembly.
primal_instance`), so that the pair's difference has no truncation from it. An output of the
run is a smooth function of the states, so its derivative is the central difference of the
replicas' outputs, which lie on the tangent line.

The step sequence is that of b: with adaptive steps the accepted steps are frozen, as are the
firing times (events, not functions of the parameters: `period` is not differentiable).
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import math
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import pandas as pd

from .checks import warn_user
from .driver import Clock
from .params import (COMPONENT_HEIGHTS, DIFFERENTIABLE_FIELDS, PER_ACTUATOR_FIELDS, STAR_RANGES,
                     SolverConfig, StarParams)
from .gait import N_ACTUATORS, Gait
from .metrics import wrap_degrees
from .model import MASS_FIELDS, build_model
from .physics import TERMS
from .timegrid import on_grid

# the public names (docs/api.md), those the studies use among them (tests/test_layering.py)
__all__ = ["SUMMARY_OUTPUTS", "TRAJECTORY_OUTPUTS", "RELATIVE_STEP", "FIELD_RELATIVE_STEPS",
           "delay_on_step_grid", "delay_event", "REPLICAS_PER_DIRECTION", "instances_per_instance",
           "parse_directions", "check_defined"]

RELATIVE_STEP = 1e-4
"""ε of a direction relative to the parameter's value. Each direction has one replica pair, at
±ε; its derivative is the pair's central difference, D(ε). Where the replicas' residual is
linear in their offsets from the instance, D(ε) is exact whatever ε, and a larger ε only
lifts the pair's offsets above the rounding of the positions. So the forces that are not
linear in the velocity (the drags |v|·v, the jet's Ṡ²) are, for a replica, expanded about its
instance's velocity to first order (`physics.assembly.Assembly.primal_instance`), the
actuation profile in a delay about its instance's time since the firing, and a replica's
tables lie on its instance's tangent (`replica_model`); what is left is the
forces' own curvature in their coefficients (~ε² relative) and in the states' offsets through
quadratic maps (the jet's areas). Measured over three cycles of the paper preset's five
Fig. 4c gaits against extrapolated differences of whole runs, at 1e-4 all eleven parameters
checked are within 1.0e-5 (the joint radius; the others within 4.4e-6; docs: numerics,
sensitivities); at 1e-5 the weakly moving ones lose to rounding (the cylinder's drag 3.6e-5,
the limbs' stiffness ratio 3.2e-5), at 1e-3 the radii to truncation (joint 1.6e-4, tip
1.0e-5). Before the expansion (the replicas used their own |v|·v, taking only their
instance's side of the kinks) the error was O(ε²) with a constant that grows as the velocity
nears zero, and no single ε served every parameter over long runs."""
FIELD_RELATIVE_STEPS = {field: step for term in TERMS
                        for field, step in term.sensitivity_steps.items()}
"""Fields whose ε departs from RELATIVE_STEP, gathered from the terms that own them
(`physics.base.Term.sensitivity_steps`, where each says why): three that barely move the
robot, whose replicas' offsets at RELATIVE_STEP are too few roundings of a position (C∥ and the
cylinder's drag C_c 1e-2, the damping time τ 1e-3). Each multiplies its own force, so the
residual is linear in it and a larger ε adds no truncation from the parameter itself (docs:
numerics, sensitivities)."""
FIELD_LEAST_STEPS = {field: step for term in TERMS
                     for field, step in term.sensitivity_least_steps.items()}
"""Fields whose ε has a least value, in the field's unit, gathered from the terms that own them
(`physics.base.Term.sensitivity_least_steps`): the wake's exchange time τ_w, at least 1e-6 s
(1e-4 of a short τ_w moved the replicas by a few roundings of their positions)."""
LINEAR_FIELDS = frozenset(MASS_FIELDS).union(*(term.linear_fields for term in TERMS))
"""Fields the residual is linear or quadratic in, as coefficients scaling its forces and masses
(`physics.base.Term.linear_fields`, `model.MASS_FIELDS`): a replica pair differences them
exactly at any ε, so a value far below the field's usual scale takes the ε of that scale
(`Direction.usual_scale`): ε = 1e-4 of a small value moved the replicas by less than the
positions' rounding (α at 8e-4: 4–6 % off, C∥ at 1e-5 and the hub's linear drag at 1e-4:
up to 1.8e-3, the differences' Taylor ratios 2: an audit, 2026-12)."""
REPLICAS_PER_DIRECTION = 2
"""Replica instances each direction adds per instance: the pair at ±ε."""


def instances_per_instance(directions: int) -> int:
    """How many instances a batch simulates for each one asked for with `directions`
    directions: itself and REPLICAS_PER_DIRECTION replicas per direction."""
    return 1 + REPLICAS_PER_DIRECTION * directions
ZERO_VALUE_SCALE = 0.01
"""For a parameter at 0, ε is RELATIVE_STEP times this share of the top of its range (for a
per-actuator delay: of the period, and for a delay above 0 at least that: `Direction.step`)."""
SUMMARY_OUTPUTS = ("displacement_x_mm", "displacement_y_mm", "speed_mm_s", "signed_speed_mm_s",
                   "travel_direction_deg", "heading_deg", "steady_speed_mm_s",
                   "steady_signed_speed_mm_s")
"""The summary columns whose derivatives a run with sensitivities reports."""
TRAJECTORY_OUTPUTS = ("x_mm", "y_mm", "heading_deg")
"""The trajectory columns whose derivatives it reports, at every record."""


def sensitivity_column(output: str, direction: str) -> str:
    """Column name of d(output)/d(direction), e.g. "d(displacement_x_mm)/d(alpha)"."""
    return f"d({output})/d({direction})"


DEFAULT_PARAMS = StarParams()
"""The defaults, built once (`Direction.usual_scale`, called per instance and direction)."""


@dataclass(frozen=True)
class Direction:
    """One parameter to differentiate by: a field, and for a per-actuator field the actuator's
    index (A_k at k − 1)."""

    field: str
    index: int = -1

    @property
    def label(self) -> str:
        return self.field if self.index < 0 else f"{self.field}[{self.index}]"

    def value(self, params: StarParams) -> float:
        value = getattr(params, self.field)
        return float(value if self.index < 0 else value[self.index])

    def moved(self, params: StarParams, value: float) -> StarParams:
        """A copy of params with this parameter set to `value`. Not validated: a replica of an
        instance at an included end of a range lies ε beyond it, where the model's formulas
        continue smoothly (ε keeps clear of an excluded end, where the model is singular:
        EXCLUDED_END_SHARE)."""
        replica = copy.copy(params)
        if self.index < 0:
            object.__setattr__(replica, self.field, float(value))
        else:
            values = list(getattr(params, self.field))
            values[self.index] = float(value)
            object.__setattr__(replica, self.field, tuple(values))
        return replica

    def allowed(self, params: StarParams, value: float) -> bool:
        """Whether StarParams takes `params` with this parameter at `value` (its range as the
        other fields narrow it, a per-actuator field's too)."""
        values = list(getattr(params, self.field)) if self.index >= 0 else None
        if values is not None:
            values[self.index] = value
        try:
            params.replace(**{self.field: value if values is None else tuple(values)})
        except ValueError:
            return False
        return True

    @property
    def relative_step(self) -> float:
        """ε relative to the parameter's value (RELATIVE_STEP or FIELD_RELATIVE_STEPS)."""
        return FIELD_RELATIVE_STEPS.get(self.field, RELATIVE_STEP)

    def step(self, params: StarParams) -> float:
        """ε for this instance (see `relative_step` and ZERO_VALUE_SCALE). A delay's is at
        least its ε at 0: the replicas are linear in a delay's offset (the profile expanded
        about the instance's delay), so a larger ε costs nothing, where ε = RELATIVE_STEP ×
        a tiny delay (1e-13 s at 1e-9 s) left the pair's offsets below the positions' rounding
        (11 % off the differences at 1e-9 s, 1.2 % at 1e-8: an audit, 2026-12). A field of
        FIELD_LEAST_STEPS takes at least its least ε; and every ε keeps to EXCLUDED_END_SHARE
        of the distance to an excluded end of the range."""
        value = abs(self.value(params)) or self.zero_scale(params)
        step = max(self.relative_step * value, self.least_step(params))
        return min(step, EXCLUDED_END_SHARE * self.excluded_end_gap(params))

    def zero_scale(self, params: StarParams = DEFAULT_PARAMS) -> float:
        """The value whose ε a parameter at 0 takes: ZERO_VALUE_SCALE of the top of its range
        (of 1 for a per-actuator gain, of the period for a delay)."""
        if self.field == "actuator_delays":
            return ZERO_VALUE_SCALE * params.period
        return ZERO_VALUE_SCALE * (STAR_RANGES[self.field][1] if self.field in STAR_RANGES
                                   else 1.0)

    def usual_scale(self) -> float:
        """The smallest value whose own ε a field of LINEAR_FIELDS takes: its `zero_scale`, or
        its default where that is less (and not 0), so that no preset's ε changes (C∥'s default,
        0.01, lies below its zero scale, 1)."""
        default = abs(self.value(DEFAULT_PARAMS))
        return min(self.zero_scale(), default) if default else self.zero_scale()

    def least_step(self, params: StarParams) -> float:
        """The least ε of this field at `params`, 0 where none (`step` takes at least it; so
        does the Taylor test's step, `sensitivity_check.taylor_step`): a delay's ε at 0, a
        field of LINEAR_FIELDS that of its `usual_scale`, a field of FIELD_LEAST_STEPS its
        own."""
        if self.field == "actuator_delays":
            return self.relative_step * self.zero_scale(params)
        usual = self.relative_step * self.usual_scale() if self.field in LINEAR_FIELDS else 0.0
        return max(usual, FIELD_LEAST_STEPS.get(self.field, 0.0))

    def excluded_end_gap(self, params: StarParams) -> float:
        """How far the parameter lies from the nearest excluded end of a range it bounds: its
        own, as the other fields narrow it (`StarParams.allowed_range`), and another field's
        whose excluded end it is (the joint radius is the tip radius's lower end: a joint
        radius 1e-7 m inside its tip radius took ε = 2.4e-6 m, and its replicas limbs of
        negative length: a review, 2026-12); inf where there is none (a per-actuator field:
        none of their ends is singular in the model)."""
        if self.field not in STAR_RANGES:
            return math.inf
        value = self.value(params)
        gap = math.inf
        for name in {self.field, *NARROWED_FIELDS}:
            lowest, highest, lowest_included, highest_included = params.allowed_range(name)
            if name == self.field:
                gap = min(gap, math.inf if lowest_included else value - lowest,
                          math.inf if highest_included else highest - value)
            elif not lowest_included and lowest == value:
                gap = min(gap, getattr(params, name) - value)
            elif not highest_included and highest == value:
                gap = min(gap, value - getattr(params, name))
        return gap


NARROWED_FIELDS = tuple(f.name for f in dataclasses.fields(StarParams)
                        if "narrowed_by" in f.metadata)
"""The fields whose range other fields narrow: the only ones whose excluded end another
parameter can be (`Direction.excluded_end_gap`)."""
EXCLUDED_END_SHARE = 0.01
"""ε is at most this share of the parameter's distance to an excluded end of its range
(`Direction.excluded_end_gap`): the model is singular there (the joint radius's actuator arcs
stop reaching from joint to joint, their geometry a square root of the gap; the tip radius's
limbs shrink to nothing), and the host's tables at ±2ε (`replica_model`) crossed it within 2ε
of it, silently (the joint radius's derivative 17 times its differences 1.5e-4 of the value
from the bound: an audit, 2026-12). The tables' fourth-order differences of a square root
then carry a truncation of ~(ε/gap)⁴ ≈ 1e-8, and the differences' runs at up to 4ε
(`sensitivity_check`) stay within 4 % of the gap."""


def parse_directions(names, what: str = "sensitivities") -> Tuple[Direction, ...]:
    """The directions of `simulate`'s `sensitivities` argument: field names, a per-actuator
    field standing for its eight numbers ("actuator_gains") or one of them by its Python index
    ("actuator_gains[3]": A4's, as `StarParams.actuator_gains[3]`; the studies' parameter boxes,
    NAME[INDEX] on their command lines, count from 1 instead: actuator_gains[4] there is A4).
    ValueError naming an unknown, repeated or non-differentiable one, and the argument `what`
    (a result's `sensitivity` names its `parameter`)."""
    # a set or a mapping would be taken in no defined order, or by its keys alone
    if isinstance(names, (str, bytes, set, frozenset, dict)) or not hasattr(names, "__iter__"):
        raise ValueError(f"{what} must be a sequence of StarParams field names (a list "
                         f"or tuple; not a set or a mapping), got {names!r}")
    directions: List[Direction] = []
    for name in names:
        if not isinstance(name, str):
            raise ValueError(f"{what} must hold field names, got {name!r}")
        field, _, rest = name.partition("[")
        indices = [-1]
        if field in PER_ACTUATOR_FIELDS:
            indices = list(range(N_ACTUATORS))
            if rest:
                index = rest[:-1]
                # isdigit() also takes digits such as "²" that int() refuses; "01" is not a
                # label this field is written with (it was read as 1: an audit, 2026-12)
                if not (rest.endswith("]") and index.isascii() and index.isdigit()
                        and str(int(index)) == index and int(index) < N_ACTUATORS):
                    raise ValueError(f"{what}: {name!r} must name an actuator index in "
                                     f"[0, {N_ACTUATORS - 1}] (Python's: {field}[0] is A1's, "
                                     f"{field}[{N_ACTUATORS - 1}] A{N_ACTUATORS}'s)")
                indices = [int(index)]
        elif rest or field not in DIFFERENTIABLE_FIELDS:
            if field in StarParams.__dataclass_fields__:
                raise ValueError(f"{what}: {name!r} is not differentiable (a word, a "
                                 f"count, the profile, or the period, which moves the firings); "
                                 f"differentiable fields: {', '.join(DIFFERENTIABLE_FIELDS)}")
            close = difflib.get_close_matches(field, DIFFERENTIABLE_FIELDS, n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise ValueError(f"{what}: {name!r} is not a StarParams field{hint} "
                             f"(differentiable fields: {', '.join(DIFFERENTIABLE_FIELDS)})")
        for index in indices:
            direction = Direction(field, index)
            if direction in directions:
                raise ValueError(f"{what}: {direction.label!r} is named twice")
            directions.append(direction)
    return tuple(directions)


def parse_parameter(name) -> Tuple[Direction, ...]:
    """The directions of the `parameter` of a result's or a Simulator's `sensitivity`: one
    name as `parse_directions` reads it, ValueError naming `parameter` otherwise."""
    if not isinstance(name, str):
        raise ValueError(f"parameter must be a StarParams field name, got {name!r}")
    return parse_directions([name], "parameter")


def check_directions(directions: Sequence[Direction], params: Sequence[StarParams],
                     solver: SolverConfig, commanded: bool = False,
                     duration_s: Optional[float] = None,
                     positions: Optional[Sequence[int]] = None):
    """ValueError, before any compute, where the sensitivities are not defined: in f32 (a
    central difference needs f64's digits) and for a component height at 0 (0 turns the 2.5-D
    model off: no derivative across that switch). A warning (`delay_event`, kind
    "delay_event") for a delay at which the run has a jump or a kink, not a slope, within
    `duration_s` (None: a `Simulator`, whose runs go on as long as it is told), with steps of
    one length (fixed, or adaptive ones held at dt_min = dt_max); with `commanded` (a
    `Simulator`, which fires what it is told, whatever the `gait` field says) for any
    actuator's delay. `positions`: the instances'
    numbers in the caller's batch, which the messages give (None: 0, 1, ...)."""
    check_defined(directions, params, solver, positions)
    for direction in directions:
        held = not solver.adaptive or solver.dt_min == solver.dt_max
        if direction.field == "actuator_delays" and held:
            # steps of one length (adaptive ones held at dt_min = dt_max too: an audit,
            # 2026-12): the events of a delay fall on the step grid or not
            dt = solver.dt if not solver.adaptive else solver.dt_max
            # the run's last step end, as its clock has it: fixed steps round the duration to
            # whole steps, adaptive ones end on it (a review, 2026-12: rounded, a held
            # adaptive run was warned of a firing after its end)
            end_s = None if duration_s is None else Clock(solver, duration_s).simulated_s
            events = [(b, delay_event(p, direction.index, dt, commanded, end_s))
                      for b, p in enumerate(params)]
            jumping = [(b, event) for b, event in events if event is not None]
            if jumping:
                b, (time, what) = jumping[0]
                number = b if positions is None else positions[b]
                warn_user(
                    f"sensitivities: {direction.label} = {direction.value(params[b]):g} s "
                    f"(instance {number}, {len(jumping)} in all) puts {what} on a step end "
                    f"(t = {time:g} s): the run changes slope or jumps there as the delay "
                    f"passes, and its derivative by the delay is not defined; move the delay off "
                    f"the step grid (e.g. by dt/2)", UserWarning, kind="delay_event")


def check_defined(directions: Sequence[Direction], params: Sequence[StarParams],
                  solver: SolverConfig, positions: Optional[Sequence[int]] = None):
    """`check_directions`' refusals alone (ValueError: f32; a component height at 0, naming the
    first such instance by its number in `positions`, None: 0, 1, ...), for a caller that
    checks before it runs and leaves the warnings to the run."""
    if directions and solver.precision != "f64":
        raise ValueError(f"sensitivities need precision 'f64' (central differences lose f32's "
                         f"digits), got {solver.precision!r}")
    for direction in directions:
        if direction.field in COMPONENT_HEIGHTS:
            at_zero = [b for b, p in enumerate(params) if direction.value(p) == 0.0]
            if at_zero:
                first = at_zero[0] if positions is None else positions[at_zero[0]]
                raise ValueError(f"sensitivities: {direction.field} is 0 (the 2.5-D model off) "
                                 f"for instance {first}; its derivative is defined only with "
                                 f"the component heights set (> 0)")


def delay_event(params: StarParams, actuator: int, dt: float, commanded: bool = False,
                end_s: Optional[float] = None) -> Optional[Tuple[float, str]]:
    """(time, s; what) of the first step end, up to the run's last one at `end_s` (None: no
    end; `check_directions` gives the duration as the run makes it), at which a run
    of `params` at steps of dt s has no derivative by the delay d of `actuator` (index k − 1
    for A_k), None where it has none. The actuator must fire: the gait fires it, or with
    `commanded` (a Simulator's run, whose firings are commands at step ends, the gait unread)
    any actuator, from one firing at 0. A periodic run fires at k·period, also inside a step
    where the period is no whole number of steps. After each firing the profile starts d
    later, τ = max(t − d, 0), a kink where d > 0 (at d = 0 the derivative is one-sided, as
    the delay's range starts there), and its branches switch t0 after that, a jump of
    `CurvatureProfile.switch_jump` where they do not meet, but only before the next firing
    restarts it (d + t0 < period). Either on a step end: moving the delay by any ε moves it
    across that step end. Until 2026-12 only the first firing's switch was looked at (an
    audit: the onset, later firings off the step grid, held adaptive steps and a switch past
    the next firing were missed or warned of wrongly)."""
    if not (commanded or Gait.parse(params.gait).mask[actuator] == 1):
        return None
    delay = params.actuator_delays[actuator]
    profile = params.actuator_profile
    offsets = []
    if delay > 0.0:
        offsets.append((delay, "the profile's onset, the delay after a firing,"))
    if profile.switch_jump != 0.0 and (commanded or delay + profile.switch_time
                                       < params.period):
        offsets.append((delay + profile.switch_time,
                        f"the actuation profile's switch, {profile.switch_time:g} s after the "
                        f"onset, where the fitted curvature jumps by "
                        f"{profile.switch_jump:.2g} 1/m,"))
    # the run fires up to its last step end: a firing past the duration asked for but inside
    # the last fixed step happens, and its events were left out (a mutation audit, 2026-12)
    if commanded or end_s is None:
        firings = np.zeros(1)
    else:
        firings = params.period * np.arange(int(np.ceil(end_s / params.period)) + 1)
        firings = firings[firings < end_s]
    found = []
    for offset, what in offsets:
        times = firings + offset
        if end_s is not None:
            times = times[times <= end_s * (1 + 1e-12)]
        hits = times[on_grid(times, dt)]
        if hits.size:
            found.append((float(hits[0]), what))
    return min(found) if found else None


def delay_on_step_grid(params: StarParams, actuator: int, dt: float,
                       commanded: bool = False) -> bool:
    """Whether a run of `params` at steps of dt s that goes on past its first firing's events
    has no derivative by the delay of `actuator` (`delay_event` with no end)."""
    return delay_event(params, actuator, dt, commanded) is not None


def replica_batch(params: Sequence[StarParams], directions: Sequence[Direction],
                  scale: float = 1.0):
    """(the batch to simulate, steps (n_directions, B)). The batch: the instances, then for
    each direction its pair of replicas at ±ε (±scale·ε), the pair
    as +ε replicas then −ε replicas: the order of `engine.BatchEngine.replica`, whose
    direction j is pair j here (so the engine carries 2·n_directions tangents). Equal
    instances share their replicas (ε is a function of the instance's parameters)."""
    steps = np.array([[direction.step(p) for p in params] for direction in directions])
    batch = list(params)
    for direction, row in zip(directions, steps):
        for sign in (1.0, -1.0):
            replicas: Dict[StarParams, StarParams] = {}
            for p, eps in zip(params, row):
                if p not in replicas:
                    replicas[p] = direction.moved(p, direction.value(p) + sign * scale * eps)
                batch.append(replicas[p])
    return batch, steps


def pair_slices(direction: int, count: int) -> Tuple[slice, slice]:
    """Where the +ε and the −ε replicas of direction number `direction` lie in a
    `replica_batch` batch of `count` instances."""
    first = (1 + REPLICAS_PER_DIRECTION * direction) * count
    return slice(first, first + count), slice(first + count, first + 2 * count)


def replica_model(params: Sequence[StarParams], directions: Sequence[Direction],
                  commanded: bool = False):
    """(the `model.BatchModel` of `replica_batch`'s batch, steps (n_directions, B)), its
    replicas' rest shapes, masses and coefficients moved from their instance's by exactly ±ε
    times their derivatives: c ± (8·(c(ε) − c(−ε)) − (c(2ε) − c(−2ε)))/12, the fourth-order
    central difference of the host's tables (a second batch at ±2ε is built for it). A pair
    built at p ± ε itself is off that line by the tables' curvature, ε²·c″/2, the same for both
    replicas: where a parameter moves the rest geometry, the elastic forces of that small misfit
    between a replica's rest shape and its tables are large, and they dominated the joint
    radius's derivatives (docs: numerics, sensitivities)."""
    batch, steps = replica_batch(params, directions)
    model = build_model(batch, commanded)
    if not directions:
        return model, steps
    wide = build_model(replica_batch(params, directions, scale=2.0)[0], commanded)
    count = len(params)

    def linear(near: np.ndarray, far: np.ndarray) -> np.ndarray:
        if not np.issubdtype(near.dtype, np.floating):
            return near
        moved = near.copy()
        for j in range(len(directions)):
            plus, minus = pair_slices(j, count)
            offset = (8.0 * (near[plus] - near[minus]) - (far[plus] - far[minus])) / 12.0
            moved[plus] = near[:count] + offset
            moved[minus] = near[:count] - offset
        return moved

    return dataclasses.replace(
        model, rest_positions=linear(model.rest_positions, wide.rest_positions),
        mass=linear(model.mass, wide.mass), inertia=linear(model.inertia, wide.inertia),
        coefficients={name: {key: linear(values, wide.coefficients[name][key])
                             for key, values in table.items()}
                      for name, table in model.coefficients.items()}), steps


def _difference(plus: np.ndarray, minus: np.ndarray, output: str) -> np.ndarray:
    """plus − minus, an angle's difference (output in degrees) taken the short way round."""
    difference = plus - minus
    return wrap_degrees(difference) if output.endswith("_deg") else difference


def derivatives(values: np.ndarray, directions: Sequence[Direction], steps: np.ndarray,
                output: str) -> dict:
    """d(output)/d(direction) for every direction, label -> (B, ...) array, from `values`
    (B_all, ...): the output of every instance of a `replica_batch` batch in its order (an
    angle's differences, output in degrees, taken the short way round)."""
    count = len(values) // instances_per_instance(len(directions))
    result = {}
    for j, direction in enumerate(directions):
        plus, minus = (values[side] for side in pair_slices(j, count))
        width = (2.0 * steps[j]).reshape((count,) + (1,) * (values.ndim - 1))
        result[direction.label] = _difference(plus, minus, output) / width
    return result


def split_result(summary: pd.DataFrame, trajectory: pd.DataFrame,
                 directions: Sequence[Direction], steps: np.ndarray):
    """From the tables of a run of `replica_batch`: (summary and trajectory of the instances
    alone, sensitivities: one row per instance with a column `sensitivity_column(output,
    direction)` per SUMMARY_OUTPUTS × direction, trajectory sensitivities: the trajectory's
    instance and t_s with one column per TRAJECTORY_OUTPUTS × direction)."""
    count = len(summary) // instances_per_instance(len(directions))
    sensitivities = {}
    by_instance = trajectory.sort_values(["instance", "t_s"], kind="stable")
    records = len(by_instance) // len(summary) if len(summary) else 0
    primal_trajectory = by_instance[by_instance["instance"] < count].reset_index(drop=True)
    trajectory_sensitivities = {"instance": primal_trajectory["instance"].to_numpy(),
                                "t_s": primal_trajectory["t_s"].to_numpy()}
    for output in SUMMARY_OUTPUTS:
        for label, values in derivatives(summary[output].to_numpy(dtype=float), directions,
                                         steps, output).items():
            sensitivities[sensitivity_column(output, label)] = values
    for output in TRAJECTORY_OUTPUTS:
        recorded = by_instance[output].to_numpy(dtype=float).reshape(len(summary), records)
        for label, values in derivatives(recorded, directions, steps, output).items():
            trajectory_sensitivities[sensitivity_column(output, label)] = values.ravel()
    return (summary.iloc[:count].reset_index(drop=True), primal_trajectory,
            pd.DataFrame(sensitivities), pd.DataFrame(trajectory_sensitivities))
