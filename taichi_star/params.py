"""Parameters: frozen, validated dataclasses (SI units; per unit out-of-plane height H = 1 m).

`StarParams` describes one robot instance (geometry, material, fluid, actuation); a batch is a
sequence of them and every field except the topology (`n_arc`, `n_limb`) may differ per instance.
`SolverConfig` is shared by the whole batch. Every numeric field has a documented range; values
outside it (orders of magnitude beyond any real robot) are refused with the range named. NumPy
scalars are accepted wherever Python numbers are.

Presets: `StarParams.preset("paper" | "accurate" | "identified", **overrides)` and
`SolverConfig.preset("paper" | "accurate" | "identified")`.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import math
from dataclasses import dataclass, field, fields
from typing import Dict, Optional, Tuple

import numpy as np

from .actuation import PROFILE_CLOSURES, CurvatureProfile
from .checks import check_choice, check_flag, check_not_subnormal, is_real, is_whole, shown
from .gait import N_ACTUATORS, Gait

JET_MODES = ("contract", "always")
JET_DIRECTIONS = ("hub", "normal", "bisector")
JET_APPLICATIONS = ("hub", "spread")
ACTUATION_ENDS = ("clamped", "shared")
ACTUATION_ORIGINS = ("profile", "rest")
"""What a fired actuator's natural curvature is measured from (`StarParams.actuation_origin`)."""
JOINT_STIFFNESSES = ("limb", "series")
PRECISIONS = ("f64", "f32")
INTEGRATORS = ("euler", "bdf2")
JACOBIANS = ("newton", "chord", "lagged")
"""The Newton Jacobian modes of `SolverConfig.jacobian` (docs: Numerics, Newton's method)."""
PRESETS = ("paper", "accurate", "identified")
"""The names `StarParams.preset` and `SolverConfig.preset` take."""

UNIT_SUFFIXES = {"Pa": "_pa", "s": "_s", "m": "_m", "kg/m^3": "_kg_m3", "kg/m": "_kg_m",
                 "Pa*s/m": "_pa_s_m", "Pa*s": "_pa_s"}
"""Column-name suffix of each parameter unit (none for "1")."""


def parameter_column(name: str) -> str:
    """The table column of StarParams field `name`: the name with its unit as a suffix
    (youngs_modulus_pa, period_s, joint_radius_m, fluid_density_kg_m3); dimensionless fields,
    counts and texts keep their name."""
    return name + UNIT_SUFFIXES.get(PARAMETER_UNITS.get(name, "1"), "")


def parameter(default, unit: str = "1", lowest=None, highest=None, lowest_included=True,
              choices=None, differentiable: bool = True, narrowed_by: str = "",
              default_means: str = ""):
    """A StarParams (or SolverConfig) field with its unit and allowed values declared once, in
    its metadata: "unit" ("1": dimensionless or a count), "range" (lowest, highest, lowest
    included) for a number (an integer if the default is one), "choices" for a word.
    `STAR_RANGES`, `SOLVER_RANGES`, `PARAMETER_UNITS`, `STAR_CHOICES`, the validation, the
    column names and the field tables of `help(StarParams)` and `help(SolverConfig)` are all
    read from it. `differentiable=False` marks a real number that
    `simulate(sensitivities=...)` refuses (one that moves events rather than coefficients).
    `narrowed_by`: how other fields narrow the declared range, in words, which the allowed
    values state after it (the range itself, `STAR_RANGES`, stays the declared one).
    `default_means`: what a default of None stands for, in words, for the field table."""
    metadata = {"unit": unit}
    if default_means:
        metadata["default_means"] = default_means
    if narrowed_by:
        metadata["narrowed_by"] = narrowed_by
    if not differentiable:
        metadata["differentiable"] = False
    if lowest is not None:
        metadata["range"] = (lowest, highest, lowest_included)
    if choices is not None:
        metadata["choices"] = tuple(choices)
    return field(default=default, metadata=metadata)


def per_actuator(default: float, unit: str, lowest: float, highest, highest_included: bool):
    """A StarParams field of one number per actuator, A_k at index k − 1 (a tuple of
    `N_ACTUATORS` floats, all `default` by default), with its unit and its range, declared here
    once: each number in [lowest, highest] (or [lowest, highest) where not highest_included),
    `highest` a number or the name of the field that bounds it ("period"). Its allowed values
    in words follow (`allowed_values`); `StarParams.__post_init__` checks each such field
    (`PER_ACTUATOR_FIELDS`, `PER_ACTUATOR_RANGES`)."""
    top = highest if isinstance(highest, str) else f"{highest:g}"
    allowed = f"{N_ACTUATORS} numbers in [{lowest:g}, {top}" + ("]" if highest_included else ")")
    return field(default=(float(default),) * N_ACTUATORS,
                 metadata={"unit": unit, "allowed": allowed, "per_actuator": True,
                           "actuator_range": (lowest, highest, highest_included)})


MAX_ACTUATOR_GAIN = 5.0
"""Largest actuator gain: five times the measured curvature change already bends an arc far
past straight (K̄ goes from 102 to 14 1/m over a pulse at gain 1)."""


def _check_actuator_values(name, values, lowest, highest, highest_included):
    """`values` (a tuple, list or 1-D array of one real number per actuator A1..A8, or the
    text of one as a table holds it, "(1.0, 0.5, ...)") as a tuple of Python floats, each in
    [lowest, highest] (or [lowest, highest)); ValueError names the field, the actuator and the
    range."""
    span = f"[{lowest:g}, {highest:g}" + ("]" if highest_included else ")")
    if isinstance(values, str):
        values = _parse_number_list(name, values)
    if isinstance(values, np.ndarray) and values.ndim == 1:
        values = values.tolist()
    if not isinstance(values, (tuple, list)):
        raise ValueError(f"{name} must be a tuple of {N_ACTUATORS} numbers in {span} "
                         f"(A1..A8), got {values!r}")
    if len(values) != N_ACTUATORS:
        raise ValueError(f"{name} must have {N_ACTUATORS} entries (A1..A8), got {len(values)}")
    checked = []
    for index, value in enumerate(values):
        if not is_real(value) or not _in_span(value, lowest, highest,
                                              highest_included=highest_included):
            raise ValueError(f"{name}[{index}] (A{index + 1}) must be a real number in {span}, "
                             f"got {_as_stored(value)}")
        check_not_subnormal(f"{name}[{index}] (A{index + 1})", value)
        checked.append(float(value) + 0.0)  # a zero as +0.0, as `check_number`
    return tuple(checked)


def _parse_number_list(name, text):
    """The numbers of a tuple or list written as text ("(1.0, 0.5)" or "[1.0, 0.5]")."""
    inner = text.strip()
    if inner[:1] in "([" and inner[-1:] in ")]":
        inner = inner[1:-1]
    try:
        return [float(part) for part in inner.split(",") if part.strip()]
    except ValueError:
        raise ValueError(f"{name}: cannot read {text[:60]!r} as {N_ACTUATORS} numbers") from None
COMPONENT_HEIGHTS = ("hub_height", "foam_height", "actuator_height")
"""The StarParams fields of the component heights (2.5-D model): all 0 (off) or all set."""
COMPONENT_HEIGHT_MINIMUM = 1e-3
"""Smallest component height, m (a millimetre: no part of the robot is thinner)."""

_DEFAULT_PROFILE = CurvatureProfile()
PROFILE_BOUNDED = ("period", "joint_radius")
"""The StarParams fields whose range the actuation profile narrows (the period must outlast
its heating phase t0; a rest arc of its K̄(0) must span two neighbouring joints)."""
_HEIGHT_RULE = (f"0 (off) or at least {COMPONENT_HEIGHT_MINIMUM:g}, the three heights all set or "
                f"all 0")


def check_number(name, value, lowest, highest, lowest_included=True, integer=False,
                 reason="", highest_included=True):
    """Validated `value` as a Python int/float (NumPy scalars accepted); ValueError names the
    field and its range (and `reason`, words in brackets after the range, where the range is
    not the declared one)."""
    span = (("[" if lowest_included else "(") + f"{lowest:.6g}, {highest:.6g}"
            + ("]" if highest_included else ")"))
    if reason:
        span = f"{span} ({reason})"
    kind = "an integer" if integer else "a real number"
    if not (is_whole(value) if integer else is_real(value)):
        raise ValueError(f"{name} must be {kind} in {span}, got {value!r}")
    if not _in_span(value, lowest, highest, lowest_included, highest_included, integer):
        raise ValueError(f"{name} must be {kind} in {span}, got {_as_stored(value)}")
    if not integer:
        check_not_subnormal(name, value)
    # + 0.0 stores a zero as +0.0: parameters that compare equal are then the same bits
    # (build_model builds equal instances once)
    return int(value) if integer else float(value) + 0.0


def _as_stored(value) -> str:
    """A refused number as the message shows it (`checks.shown`), and where the float it would
    be stored as differs from it, that too: np.float32(0.05) is 0.05000000074505806, past a
    bound of 0.05 (a review, 2026-12)."""
    text = shown(value)
    if is_whole(value):  # an integer is stored as itself
        return text
    try:
        stored = float(value)
    except OverflowError:  # a real number past float's range (10**400 / 3)
        return text
    if math.isfinite(stored) and repr(stored) not in text:
        return f"{text} ({stored!r} as a float)"
    return text


def _in_span(value, lowest, highest, lowest_included=True, highest_included=True,
             integer=False) -> bool:
    """Whether the real number `value` is finite and within [lowest, highest] (an end
    excluded where not `..._included`), both as given and, unless an `integer`, as the float
    it is stored as: an integer beyond float's range (10**400) is out of the span (not an
    OverflowError), and a value that rounds onto an excluded end (Fraction(1, 10**400) for a
    dt in (0, 0.05] becomes 0.0) is refused (a review, 2026-12)."""
    def within(number):
        return math.isfinite(number) and lowest <= number <= highest and not (
            (number == lowest and not lowest_included)
            or (number == highest and not highest_included))

    try:
        return within(value) and (integer or within(float(value)))
    except OverflowError:
        return False


def _named_fields_only(cls):
    """Class decorator: a keyword that is not a field of the dataclass `cls` raises a TypeError
    naming it, the closest field names and all fields, instead of the stock "unexpected keyword
    argument" (StarParams(alpah=1) → "... did you mean 'alpha'?")."""
    generated_init = cls.__init__
    names = [f.name for f in fields(cls) if f.init]

    @functools.wraps(generated_init)
    def __init__(self, *args, **kwargs):
        unknown = [key for key in kwargs if key not in names]
        if unknown:
            close = difflib.get_close_matches(unknown[0], names, n=3)
            hint = f"; did you mean {' or '.join(map(repr, close))}?" if close else ""
            raise TypeError(f"{cls.__name__} has no field {unknown[0]!r}{hint} "
                            f"(fields: {', '.join(names)})")
        generated_init(self, *args, **kwargs)
    cls.__init__ = __init__
    return cls


@_named_fields_only
@dataclass(frozen=True)
class StarParams:
    """One star robot instance. Lengths in m, moduli in Pa, densities in kg/m³, times in s.

    Each field's unit, allowed values and default (from its declaration; a field's own
    documentation says what it means):"""

    gait: str = field(default="A1", metadata={"allowed": 'a gait: "A1".."A8" joined by "+", '
                                                         'or "none"'})
    """Actuators fired together each cycle: "A1".."A8" joined by "+" (no repeats), or "none".
    Stored canonically ("A2+A1" becomes "A1+A2")."""
    alpha: float = parameter(0.8, "1", 0.0, 10.0)
    """Jet ratio α (-), the fraction of the squeezed fluid jetted in plane."""
    added_mass_coeff: float = parameter(1.0, "1", 0.0, 10.0)
    """Added-mass coefficient C_a (-) of the rod nodes."""
    youngs_modulus: float = parameter(5e6, "Pa", 1e3, 1e10)
    """E of the actuator arcs, Pa."""
    limb_stiffness_ratio: float = parameter(100.0, "1", 1e-2, 1e4)
    """E_limb / E (-) for limbs, spokes and joint bending."""
    drag_parallel: float = parameter(0.01, "1", 0.0, 100.0)
    """Axial rod drag coefficient C∥ (-)."""
    drag_perpendicular: float = parameter(1.0, "1", 0.0, 100.0)
    """Normal rod drag coefficient C⊥ (-)."""
    cylinder_drag: float = parameter(10.0, "1", 0.0, 1000.0)
    """Drag coefficient C_c (-) of the central cylinder."""
    period: float = parameter(3.15, "s", 0.0, 1000.0, lowest_included=False, differentiable=False,
                              narrowed_by=f"longer than the profile's heating phase t0 "
                                          f"({_DEFAULT_PROFILE.switch_time:g} s by default)")
    """Actuation period T, s (150 ms heating pulse + 3 s rest); longer than the heating time t0."""
    jet_mode: str = parameter("contract", choices=JET_MODES)
    """"contract": jet only while an inter-limb space shrinks; "always": the paper's formula
    literally (a growing space jets too)."""
    thickness: float = parameter(3.4e-3, "m", 1e-4, 0.02)
    """Rod thickness r0, m."""
    actuator_density: float = parameter(2700.0, "kg/m^3", 10.0, 2e4)
    """Effective density of the actuator arcs, kg/m³."""
    foam_density: float = parameter(700.0, "kg/m^3", 10.0, 2e4)
    """Effective density of the foam limbs, kg/m³."""
    fluid_density: float = parameter(1000.0, "kg/m^3", 0.1, 2e4)
    """Water density ρ_f, kg/m³."""
    cylinder_mass_per_height: float = parameter(0.98, "kg/m", 1e-3, 100.0)
    """Mass of the central cylinder per unit height, kg/m (49 g / 50 mm)."""
    cylinder_diameter: float = parameter(0.03, "m", 1e-3, 0.5)
    """D_c = 2 R_c, m."""
    cylinder_added_mass_coeff: float = parameter(0.0, "1", 0.0, 10.0)
    """Added-mass coefficient of the cylinder (-), mass ρ_f·C·π D_c²/4 (the paper: none)."""
    actuation_ends: str = parameter("clamped", choices=ACTUATION_ENDS)
    """"clamped": only an actuator's interior bending triplets follow K̄(τ); "shared": each joint
    also turns by the curvature change of the arc's half-edge beside it, so that the limb keeps
    its angle to the arc's tangent (second-order accurate in n_arc with "series" joints)."""
    joint_stiffness: str = parameter("limb", choices=JOINT_STIFFNESSES)
    """Modulus of the two bending triplets at each joint: "limb" = E_limb (the paper's choice as
    we read it; it makes each arc rigid over its end half-edges); "series" = a half arc edge (E)
    in series with a half limb edge (E_limb) over the triplet's length."""
    profile_closure: str = parameter("jump", choices=PROFILE_CLOSURES)
    """How a periodic gait closes the fitted actuation profile: "jump" = the fit as published
    (the natural curvature steps by K̄(0) − K̄(T) at each new cycle); "ramp" = the difference is
    spread linearly over the cycle (continuous)."""
    damping_time: float = parameter(0.0, "s", 0.0, 1.0)
    """Kelvin–Voigt material damping time τ, s (0 = none, the paper's model); a mode of angular
    frequency ω gets a damping ratio ζ = ωτ/2."""
    actuator_profile: CurvatureProfile = field(default_factory=CurvatureProfile,
                                               metadata={"allowed": "a CurvatureProfile"})
    """The actuators' natural-curvature profile K̄(τ) (default: the paper's fit); its K̄(0) is
    the curvature of the circles the rest arcs are built on (their discrete curvature exceeds
    it at second order in the edge: 0.23 % at n_arc 18; docs/model.md)."""
    joint_radius: float = parameter(
        0.024, "m", 1e-3, 1.0,
        narrowed_by=f"below 1/(K̄(0)·sin 22.5°), the widest a rest arc spans "
                    f"({1.0 / (_DEFAULT_PROFILE.rest_curvature * math.sin(math.pi / 8)):.5g} m "
                    f"with the default profile)")
    """Radius of the eight joints from the centre, m; must let an arc of curvature K̄(0) span
    two neighbouring joints."""
    tip_radius: float = parameter(0.052, "m", 1e-3, 2.0, narrowed_by="beyond joint_radius")
    """Radius of the limb tips, m (diameter L = 104 mm); beyond joint_radius."""
    n_arc: int = parameter(18, "1", 2, 1000)
    """Edges per actuator arc (topology: equal across a batch)."""
    n_limb: int = parameter(6, "1", 1, 1000)
    """Edges per foam limb (topology: equal across a batch)."""
    jet_direction: str = parameter("hub", choices=JET_DIRECTIONS)
    """Direction t of each space's jet (model extension, docs/model.md "Jet variants"): "hub"
    = from the hub to the opening's midpoint (the paper's reading); "normal" = normal to the
    opening segment tip_k → tip_{k+1}, pointing away from the hub; "bisector" = along the
    bisector of the two limbs' directions, joint → tip, that bound the space."""
    jet_application: str = parameter("hub", choices=JET_APPLICATIONS)
    """Where each jet's force acts: "hub" = all of it on the centre node (the paper); "spread"
    = a quarter on each of the space's four corners (its two joints and two tips), the walls
    the water pushes on."""
    jet_inflow: float = parameter(0.0, "1", 0.0, 10.0)
    """Inflow ratio α_in (-): while a space opens (Ṡ > 0) the water drawn in through its
    opening pulls the robot towards it with f = (ρ_f/L)(α_in·Ṡ)²·t (0 = none, the paper's
    model). Needs jet_mode "contract" (with "always" an opening space already jets)."""
    hub_height: float = parameter(0.0, "m", 0.0, 0.5, narrowed_by=_HEIGHT_RULE)
    """Height of the hub (the central cylinder), m: with foam_height and actuator_height, the
    2.5-D model (docs/model.md "Component heights"): each component's mass, drag, added mass and
    jet scale with its height over the hub's. 0 (default) = off, every component one unit height
    (the paper); else at least COMPONENT_HEIGHT_MINIMUM (1 mm), and all three must be set."""
    foam_height: float = parameter(0.0, "m", 0.0, 0.5, narrowed_by=_HEIGHT_RULE)
    """Height of the foam limbs, m (the paper's robot: 24 mm); 0 = off, else ≥ 1 mm."""
    actuator_height: float = parameter(0.0, "m", 0.0, 0.5, narrowed_by=_HEIGHT_RULE)
    """Height of the actuator arcs, m; 0 = off, else ≥ 1 mm."""
    # ---- model extensions (docs/model.md), off by default: the defaults change no result
    linear_drag: float = parameter(0.0, "Pa*s/m", 0.0, 1e4)
    """Linear (skin-friction) drag c_l on the rod edges, Pa·s/m: a force −c_l·v per unit rod
    length and unit height on each edge's mean velocity v (`physics.linear_drag`)."""
    hub_linear_drag: float = parameter(0.0, "Pa*s", 0.0, 1e3)
    """Linear drag c_h on the hub, Pa·s: a force −c_h·v per unit height on the centre node."""
    wake_coupling: float = parameter(0.0, "Pa*s", 0.0, 1e3)
    """Coupling c_w of the entrained water to the hub, Pa·s (0 = no entrained water): a force
    c_w·(u − v) per unit height on the centre node, v its velocity, u that of the water the
    robot has set moving, which follows it as u̇ = (v − u)/τ_w and takes the opposite force
    (`physics.wake`)."""
    wake_time: float = parameter(1.0, "s", 1e-9, 1e3)
    """Exchange time τ_w of the entrained water, s: its mass per unit height is c_w·τ_w (at
    least 1 ns: 0 is no water, which c_w = 0 says; the term is smooth through 0, written in
    τ_w, until 2026-12 in 1/τ_w, which a subnormal τ_w made infinite)."""
    stroke_warming: float = parameter(0.0, "1", 0.0, 10.0)
    """Warming w of the actuators' stroke (-): a firing's gain on its curvature change is
    multiplied by 1 + w·θ, θ the heat the actuator keeps from its earlier firings (each left
    one unit, decaying as exp(−t/τ_c), `cooling_time`): an SMA wire in its silicone cools
    between pulses for longer than a period's rest, so a later pulse starts warmer and
    transforms more (`physics.bending`). 0 = off (the paper's model: every pulse the first)."""
    cooling_time: float = parameter(10.0, "s", 1e-9, 1e3)
    """Cooling time τ_c of the heat an actuator keeps between its firings, s (with
    `stroke_warming`; at least 1 ns: the term divides by it)."""
    actuator_gains: Tuple[float, ...] = per_actuator(1.0, "1", 0.0, MAX_ACTUATOR_GAIN, True)
    """Gain g_k (-) of actuator A_k (index k − 1) on its commanded curvature change: it follows
    K̄(0) + g_k·(K̄(τ) − K̄(0))."""
    actuator_delays: Tuple[float, ...] = per_actuator(0.0, "s", 0.0, "period", False)
    """Delay d_k of actuator A_k (index k − 1), s: its profile starts d_k after each firing
    (K̄(0) until then), K̄(max(τ − d_k, 0))."""
    actuation_origin: str = parameter("profile", choices=ACTUATION_ORIGINS)
    """What a fired arc triplet's natural curvature κ⁰ is measured from: "profile" = ±K̄_k(τ),
    Eq. 5 as written (the paper's model; the rest arc's discrete curvature exceeds K̄(0) at
    second order in the edge, 0.23 % at n_arc 18, so κ⁰ steps by that at the first firing);
    "rest" = the rest κ⁰ plus the profile's change ±(K̄_k(τ) − K̄(0)): no step at the first
    firing, and a gain of 0 leaves the arc exactly at rest (docs/model.md)."""

    def __post_init__(self):
        object.__setattr__(self, "gait", Gait.parse(self.gait).name)
        if not isinstance(self.actuator_profile, CurvatureProfile):
            raise ValueError(f"actuator_profile must be a CurvatureProfile, got "
                             f"{type(self.actuator_profile).__name__}")
        for name in STAR_RANGES:
            # three ranges hang on other fields (checked before them, in declaration order),
            # so that one message states the whole range whichever end a value misses
            lowest, highest, included, highest_included, reason = self._narrowed_range(name)
            if name in PROFILE_BOUNDED and not lowest < highest:
                # the profile leaves the field no value at all: blame the profile, not the field
                declared = _declared_range(type(self).__dataclass_fields__[name])
                rest = self.actuator_profile.rest_curvature
                bound = (f"its heating phase t0 = {lowest:g} s outlasts every period" if
                         name == "period" else f"a rest arc of its K̄(0) = {rest:.5g} 1/m spans "
                         f"joints at most {highest:.3g} m from the centre")
                raise ValueError(f"actuator_profile leaves {name} no value in its declared "
                                 f"{declared}: {bound}")
            object.__setattr__(self, name, check_number(
                name, getattr(self, name), lowest, highest, included, name in INTEGER_FIELDS,
                reason, highest_included))
        for name, choices in STAR_CHOICES.items():
            check_choice(name, getattr(self, name), choices)
        for f in fields(self):
            if f.metadata.get("per_actuator"):
                lowest, highest, highest_included = f.metadata["actuator_range"]
                top = getattr(self, highest) if isinstance(highest, str) else highest
                object.__setattr__(self, f.name, _check_actuator_values(
                    f.name, getattr(self, f.name), lowest, top, highest_included))
        heights = [getattr(self, name) for name in COMPONENT_HEIGHTS]
        tallest = STAR_RANGES[COMPONENT_HEIGHTS[0]][1]  # the heights share their declared range
        for name, height in zip(COMPONENT_HEIGHTS, heights):
            if 0.0 < height < COMPONENT_HEIGHT_MINIMUM:
                raise ValueError(f"{name} must be 0 (off) or in [{COMPONENT_HEIGHT_MINIMUM:g}, "
                                 f"{tallest:g}] m, got {height!r}")
        if 0.0 in heights and any(heights):
            missing = [name for name, height in zip(COMPONENT_HEIGHTS, heights) if height == 0.0]
            raise ValueError(f"{', '.join(missing)} must be in [{COMPONENT_HEIGHT_MINIMUM:g}, "
                             f"{tallest:g}] m as well: the component heights are all set or all "
                             f"0 (off)")
        if self.jet_inflow > 0.0 and self.jet_mode == "always":
            raise ValueError(f"jet_inflow must be 0 with jet_mode 'always' (its literal formula "
                             f"already jets while a space opens; an inflow would only cancel "
                             f"part of that), got {self.jet_inflow!r}: use jet_mode 'contract'")

    def _narrowed_range(self, name: str) -> Tuple[float, float, bool, bool, str]:
        """(lowest, highest, lowest included, highest included, the reason in words where the
        other fields narrow it) of numeric field `name`: its declared range (`STAR_RANGES`) as
        the fields it hangs on narrow it (read from `self`: those declared before it)."""
        lowest, highest, included = STAR_RANGES[name]
        if name == "period":
            # a firing's heating phase must end within its period
            return (self.actuator_profile.switch_time, highest, False, True,
                    "longer than the heating phase t0")
        if name == "joint_radius":
            # the rest shape's actuator arcs, of the profile's rest curvature, must reach from
            # one joint to the next
            rest = self.actuator_profile.rest_curvature
            # the smaller of the two bounds: a profile of small rest curvature let the arc's
            # bound replace the declared one (1.5 m was taken; an audit, 2026-12)
            arc_bound = 1.0 / (rest * math.sin(math.pi / 8))
            if arc_bound <= highest:
                return (lowest, arc_bound, included, False,
                        f"an actuator arc of rest curvature {rest:.5g} 1/m cannot span joints "
                        f"further apart")
        if name == "tip_radius":
            return (self.joint_radius, highest, False, True,
                    "beyond joint_radius: the limbs point outwards")
        return lowest, highest, included, True, ""

    def allowed_range(self, name: str) -> Tuple[float, float, bool, bool]:
        """(lowest, highest, lowest included, highest included) of numeric field `name` with
        these parameters: its declared range (`STAR_RANGES`) narrowed by the fields it hangs
        on (the joint radius by the profile's rest arc, the tip radius by the joint radius,
        the period by the profile's heating phase)."""
        return self._narrowed_range(name)[:4]

    @classmethod
    def preset(cls, name: str = "paper", **overrides) -> "StarParams":
        """A named model with some fields changed. "paper": the paper's model as published,
        read where it leaves a choice open (N = 193 nodes, no damping, clamped ends, limb-stiff
        joints, the jet only while a space closes: docs/model.md). "accurate": material
        damping τ = 0.94 ms, series joints and shared ends, which converge at second order in
        the mesh, on n_arc 48 (N = 433). "identified": the best model form of the model
        selection study (`IDENTIFIED_FIELDS`), e.g. `StarParams.preset("identified",
        gait="A1+A4")`."""
        check_choice("preset", name, PRESETS)
        return cls(**{**PRESET_FIELDS[name], **overrides})

    @property
    def limb_modulus(self) -> float:
        """E_limb, Pa."""
        return self.youngs_modulus * self.limb_stiffness_ratio

    @property
    def height_ratios(self) -> Tuple[float, float]:
        """(foam_height, actuator_height) over hub_height: what scales the limbs' and the arcs'
        mass, drag, added mass and the jet (the hub's own ratio is 1); exactly (1.0, 1.0) when
        the heights are off."""
        if self.hub_height == 0.0:
            return 1.0, 1.0
        return self.foam_height / self.hub_height, self.actuator_height / self.hub_height

    @property
    def gait_value(self) -> Gait:
        """The gait as a `Gait`."""
        return Gait.parse(self.gait)

    @property
    def topology_key(self):
        """The fields that fix the topology; a batch must agree on them."""
        return (self.n_arc, self.n_limb)

    @staticmethod
    def node_count(n_arc, n_limb):
        """Nodes N of a robot of n_arc edges per arc and n_limb per limb (numbers or arrays):
        the hub, and per actuator its joint, its limb's n_limb nodes and its arc's n_arc − 1
        interior ones (N = 193 at the paper's 18 and 6)."""
        return 1 + N_ACTUATORS * (n_limb + n_arc)

    @property
    def n_nodes(self) -> int:
        """N, the robot's nodes (`node_count`)."""
        return self.node_count(self.n_arc, self.n_limb)

    def replace(self, **changes) -> "StarParams":
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    @classmethod
    def field_names(cls):
        return [f.name for f in fields(cls)]

    @classmethod
    def numeric_field_names(cls):
        """The fields that take one number (the ones a sweep or a fit can vary as a whole);
        the fields of one number per actuator are `PER_ACTUATOR_FIELDS`."""
        return list(STAR_RANGES)

    @classmethod
    def columns(cls):
        """{field name: table column} of every field (see `parameter_column`)."""
        return {name: parameter_column(name) for name in cls.field_names()}

    @classmethod
    def from_row(cls, row, **overrides) -> "StarParams":
        """The parameters of one row of a result table (a pandas Series or a mapping with the
        parameter columns of `columns`, e.g. `result.summary.iloc[3]`, a row read back from a
        CSV, Parquet or netCDF file, or an xarray Dataset's row, `dataset.isel(instance=3)`
        of `to_xarray` or of a netCDF file), with some fields changed. The actuator profile may
        be a CurvatureProfile or its text (`CurvatureProfile.to_text`, as result tables hold
        it); the per-actuator tuples (`actuator_gains`, ...) tuples or their text, read back
        exactly. Raises ValueError naming a missing column or an unreadable profile."""
        # `in` on a text finds substrings, and None has no columns at all
        if isinstance(row, (str, bytes)) or not (hasattr(row, "__contains__")
                                                 and hasattr(row, "__getitem__")):
            raise ValueError(f"row must be a table row (a pandas Series or a mapping of "
                             f"columns), got {type(row).__name__}")
        values = {}
        for name, column in cls.columns().items():
            if name in overrides:
                continue
            if column not in row:
                raise ValueError(f"row has no column {column!r} (StarParams field {name!r})")
            value = row[column]
            # a NumPy scalar, or a 0-d array of an xarray Dataset's row (`to_xarray`, netCDF:
            # `dataset.isel(instance=3)`): its Python value
            if hasattr(value, "item") and np.ndim(value) == 0:
                value = value.item()
            if name == "actuator_profile" and not isinstance(value, CurvatureProfile):
                value = CurvatureProfile.from_text(value)
            values[name] = value
        return cls(**{**values, **overrides})


STAR_RANGES: Dict[str, Tuple[float, float, bool]] = {
    f.name: f.metadata["range"] for f in fields(StarParams) if "range" in f.metadata}
"""Allowed range of every numeric StarParams field (lowest, highest, lowest included), from
the fields' declarations (`parameter`)."""
PER_ACTUATOR_FIELDS = tuple(f.name for f in fields(StarParams) if f.metadata.get("per_actuator"))
"""The StarParams fields of one number per actuator (a tuple, A_k at index k − 1)."""
PER_ACTUATOR_RANGES: Dict[str, Tuple[float, object, bool]] = {
    name: StarParams.__dataclass_fields__[name].metadata["actuator_range"]
    for name in PER_ACTUATOR_FIELDS}
"""The range of each number of a per-actuator field (lowest, highest, highest included),
highest a number or the name of the StarParams field that bounds it ("period")."""
PARAMETER_UNITS: Dict[str, str] = {name: StarParams.__dataclass_fields__[name].metadata["unit"]
                                   for name in (*STAR_RANGES, *PER_ACTUATOR_FIELDS)}
"""Units of the numeric StarParams fields, per-actuator ones included ("1": dimensionless or a
count)."""
INTEGER_FIELDS = tuple(f.name for f in fields(StarParams)
                       if "range" in f.metadata and isinstance(f.default, int))
"""The numeric fields that take whole numbers (the topology)."""
DIFFERENTIABLE_FIELDS = tuple(
    f.name for f in fields(StarParams)
    if ("range" in f.metadata and f.name not in INTEGER_FIELDS
        and f.metadata.get("differentiable", True)) or f.metadata.get("per_actuator"))
"""The fields `simulate(sensitivities=...)` can differentiate by: every real number but the
period (it moves the firings, events of the scheme), and each number of a per-actuator field."""
STAR_CHOICES: Dict[str, Tuple[str, ...]] = {
    f.name: f.metadata["choices"] for f in fields(StarParams) if "choices" in f.metadata}
"""The allowed words of every StarParams field that takes one of a list."""


def allowed_values(name: str) -> str:
    """The allowed values of StarParams field `name` in words, as `help(StarParams)` shows
    them ("[0, 10]", '"jump" or "ramp"', "8 numbers in [0, 5]"); KeyError for no such field."""
    return _allowed(StarParams.__dataclass_fields__[name])


def _allowed(f) -> str:
    """The allowed values of field `f` in words, from its metadata."""
    if "range" in f.metadata:
        narrowed = f", and {f.metadata['narrowed_by']}" if "narrowed_by" in f.metadata else ""
        return _declared_range(f) + narrowed
    if "choices" in f.metadata:
        return " or ".join(f'"{choice}"' for choice in f.metadata["choices"])
    return f.metadata["allowed"]


def _declared_range(f) -> str:
    """The range declared with numeric field `f`, as "[lowest, highest]" ("(" where the lowest
    is excluded)."""
    lowest, highest, included = f.metadata["range"]
    return f"{'[' if included else '('}{lowest:g}, {highest:g}]"


def _default(f):
    return f.default if f.default is not dataclasses.MISSING else f.default_factory()


def _shown_default(f) -> str:
    """Field f's default for the table: its repr, and what None stands for where declared."""
    meaning = f.metadata.get("default_means")
    return f"{_default(f)!r}: {meaning}" if meaning else repr(_default(f))


def _unit(f) -> str:
    """The unit of field `f` for the table: numeric fields' own, "—" for texts."""
    return f.metadata["unit"] if "range" in f.metadata or "per_actuator" in f.metadata else "—"


def _add_field_table(cls):
    """Append the table of `cls`'s fields (unit, allowed values, default), read from their
    declarations, to its docstring (what `help` and the API reference show)."""
    cls.__doc__ += "\n\n    | field | unit | allowed | default |\n    |---|---|---|---|\n" + "".join(
        f"    | {f.name} | {_unit(f)} | {_allowed(f)} | {_shown_default(f)} |\n"
        for f in fields(cls))


_add_field_table(StarParams)


IDENTIFIED_FIELDS = {"alpha": 0.9786438928, "drag_perpendicular": 2.498859446,
                     "cylinder_drag": 14.80938981,
                     "actuator_gains": (0.3939133956, 0.742903281, 1.063642313, 1.98171259,
                                        0.3898143876, 1.0, 1.0, 1.0)}
"""StarParams fields of the "identified" preset (the rest are the paper's), to 10 significant
digits. The model form "gains_with_a1", rank 1 of `python -m studies model_select`: the
paper's model with a gain per actuator on its curvature change, fitted with α, C⊥ and C_c by
CMA-ES to the measured trajectories of cycles 1-3 of the five Fig. 4 gaits (A6-A8, fired by
none of them, keep gain 1). The study's own search (results/model_select/, 384 evaluations)
stopped short of the optimum (trajectory objective 1.11); these are its point continued by a
local search from there (`model_select --start results/model_select/identified.csv`, three
seeds, results/model_select_continued/seed*/identified.csv), the seed that fits cycles 1-3
best (0.327, seed 3). It swims all five gaits in the paper's directions over cycles 1-3 and
4-6, predicts cycles 4-6 at 6.73 against 16.8 for the study's point, and 3 of 5 held-out gaits
within ±35 % against 1 (docs/results.md, "Which model form explains the robot")."""

PRESET_FIELDS = {
    "paper": {},
    "accurate": {"damping_time": 0.94e-3, "joint_stiffness": "series",
                 "actuation_ends": "shared", "profile_closure": "jump", "n_arc": 48},
    "identified": IDENTIFIED_FIELDS,
}
"""StarParams fields of each preset (the rest are the defaults)."""


MAX_DT = 0.05
"""Largest time step, s: under a third of the heating pulse, so a step cannot skip it."""

F32_NEWTON_TOL_MIN = 1e-7
"""Smallest newton_tol in f32, m: its rounding of ~5 cm positions is ~4e-9 m."""
NEWTON_TOL_DEFAULTS = {"f64": 1e-10, "f32": F32_NEWTON_TOL_MIN}
"""newton_tol of each precision when SolverConfig is given none, m: f64's is what the presets
have always used; f32's is the smallest it accepts (`F32_NEWTON_TOL_MIN`), which resolves the
paper's robot (32 f32 roundings of its 5.2-cm tip_radius are 9.9e-8 m: `check_precision`)."""


@_named_fields_only
@dataclass(frozen=True)
class SolverConfig:
    """Time integration and Newton settings, shared by the batch."""

    dt: float = parameter(1e-3, "s", 0.0, MAX_DT, lowest_included=False)
    """Time step h, s (at most a third of the 0.163-s heating pulse: `MAX_DT`)."""
    newton_tol: Optional[float] = parameter(None, "m", 1e-14, 1e-6,
                                            default_means=", ".join(
                                                f"{tolerance:g} in {precision}" for precision,
                                                tolerance in NEWTON_TOL_DEFAULTS.items()))
    """Convergence: a Newton solve stops once an update moves no node coordinate by more than
    this, m (at most a micrometre, 1e-5 of the robot's size: any looser and "converged" would
    not mean the step was solved; in f32 at least `F32_NEWTON_TOL_MIN`). None (the default):
    the precision's own, 1e-10 m in f64 and 1e-7 m in f32 (`NEWTON_TOL_DEFAULTS`), set in
    its place when the config is made, so that a config reads and records a number. The
    position error left after that update is then below it: with Newton's quadratic
    convergence far below, and with the chord's and the lagged Jacobian's below in every step
    measured (the five Fig. 4c gaits at 1-, 5- and 10-ms steps: at most 0.93·newton_tol,
    docs/reliability.md).
    Until 2026-12 a solve also stopped when the contraction estimate θ/(1 − θ)·max |Δq_k|
    (θ = max |Δq_k| / max |Δq_{k−1}|) was within it, which left errors of up to 34·newton_tol
    (131 with the lagged Jacobian)."""
    residual_tol: Optional[float] = parameter(None, "N", 1e-8, 1000.0)
    """Convergence judged on the residual as well (opt-in; None: the update test alone): the
    largest component of the residual (a node's force imbalance, N) that the accepted update was
    computed from must be at most this. The robot's largest nodal forces are tens
    of newtons, and the round-off floor of the residual is the stiffness times the rounding of
    the positions: ~1e-9 N in f64, but newtons in f32 (stiff limbs), where it is unusable."""
    max_newton: int = parameter(25, "1", 1, 200)
    """Newton iterations per step before the instance is declared newton_failed (after its
    substep retries). At 1 every step that moves fails: a solve stops only on an update within
    newton_tol, and the first update is the step's whole move (the tests use it to make
    failures)."""
    precision: str = parameter("f64", choices=PRECISIONS)
    """Floating point type of the engine."""
    integrator: str = parameter("euler", choices=INTEGRATORS)
    """"euler": implicit Euler (the paper's scheme, first order); "bdf2": second-order BDF (its
    first step, a step after a retry and a step after a rejected adaptive step are implicit
    Euler)."""
    jacobian: str = parameter("newton", choices=JACOBIANS)
    """"newton": a fresh Jacobian and LU every iteration; "chord": the step's first Jacobian is
    reused while it contracts the update ≥ 4× per iteration (same converged solution to
    newton_tol, fewer factorisations); "lagged": the chord's rule across steps, a factorisation
    kept from step to step while the step size and integrator weights stay the same (opt-in:
    fixed steps about 2.5× as fast over a cycle, converged to newton_tol like the others, but
    not to Newton's far smaller actual error; a Simulator's snapshot holds the kept
    factorisations, so a loaded one continues bitwise). A chord or lagged solve that runs out
    of iterations starts again from the step's start with Newton's Jacobian before the step
    is retried."""
    max_substep_halvings: int = parameter(4, "1", 0, 10)
    """A failed step is retried as 2, 4, ... 2^max_substep_halvings substeps before the instance
    is declared failed; 0 disables retries. (Fixed steps only.)"""
    adaptive: bool = field(default=False, metadata={"unit": "—", "allowed": "True or False"})
    """Adaptive stepping: each instance chooses its own step size from a local error estimate
    (dt is then the first step's size, and the largest of a step that ends on a firing, where
    the actuation jumps); steps land exactly on record times, cycle starts and firings."""
    error_tol: float = parameter(1e-7, "m", 1e-12, 1e-3)
    """Adaptive stepping: largest local error per step of any node position, m."""
    dt_min: float = parameter(1e-6, "s", 0.0, MAX_DT, lowest_included=False)
    """Adaptive stepping: smallest step, s; at most dt_max, and at most dt when adaptive
    (unused with fixed steps)."""
    dt_max: float = parameter(MAX_DT, "s", 0.0, MAX_DT, lowest_included=False)
    """Adaptive stepping: largest step, s; at least dt when adaptive (unused with fixed
    steps)."""

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            # None is a value only where it is the default (residual_tol: the test off)
            if "range" in f.metadata and not (value is None and f.default is None):
                lowest, highest, included = f.metadata["range"]
                object.__setattr__(self, f.name, check_number(
                    f.name, value, lowest, highest, included, isinstance(f.default, int)))
        object.__setattr__(self, "adaptive", check_flag("adaptive", self.adaptive))
        if self.dt_min > self.dt_max:
            # either may be the one the caller set: both are named
            raise ValueError(f"dt_min must be <= dt_max (the adaptive step's bounds, checked with "
                             f"fixed steps too), got dt_min = {self.dt_min!r} s and dt_max = "
                             f"{self.dt_max!r} s")
        if self.adaptive and not self.dt_min <= self.dt <= self.dt_max:
            raise ValueError(f"dt (the first adaptive step) must be in [dt_min, dt_max] = "
                             f"[{self.dt_min:g}, {self.dt_max:g}] s, got {self.dt!r}")
        for f in fields(self):
            if "choices" in f.metadata:
                check_choice(f.name, getattr(self, f.name), f.metadata["choices"])
        if self.newton_tol is None:
            object.__setattr__(self, "newton_tol", NEWTON_TOL_DEFAULTS[self.precision])
        if self.precision == "f32" and self.newton_tol < F32_NEWTON_TOL_MIN:
            highest = SolverConfig.__dataclass_fields__["newton_tol"].metadata["range"][1]
            raise ValueError(f"newton_tol must be in [{F32_NEWTON_TOL_MIN:g}, {highest:g}] m with "
                             f"precision 'f32' (its rounding of ~5 cm positions is ~4e-9 m), got "
                             f"{self.newton_tol!r}")

    @classmethod
    def preset(cls, name: str = "paper", **overrides) -> "SolverConfig":
        """Named solver settings: "paper" and "identified" (implicit Euler at 1 ms with Newton's
        method, the paper's scheme, with which the model selection study fits) or "accurate" (adaptive BDF2, error_tol 1e-6 m, the chord Jacobian:
        about 300 steps per 3.15-s cycle)."""
        check_choice("preset", name, PRESETS)
        return cls(**{**SOLVER_PRESET_FIELDS[name], **overrides})

    @property
    def residual_limit(self) -> float:
        """residual_tol, N, or infinity when it is None (what the kernels compare against)."""
        return math.inf if self.residual_tol is None else self.residual_tol

    def replace(self, **changes) -> "SolverConfig":
        """A copy with some fields changed (validated again). A change of precision that leaves
        newton_tol out takes the new precision's default tolerance where this config has the
        old one's (`NEWTON_TOL_DEFAULTS`: f64's 1e-10 m is below what f32 accepts), and keeps
        any other tolerance (refused where the new precision cannot use it)."""
        if ("precision" in changes and "newton_tol" not in changes
                and self.newton_tol == NEWTON_TOL_DEFAULTS[self.precision]):
            changes["newton_tol"] = None
        return dataclasses.replace(self, **changes)


_add_field_table(SolverConfig)
SOLVER_RANGES: Dict[str, Tuple[float, float, bool]] = {
    f.name: f.metadata["range"] for f in fields(SolverConfig) if "range" in f.metadata}
"""Allowed range of every numeric SolverConfig field (lowest, highest, lowest included), from
the fields' declarations (`parameter`); an adaptive dt also lies in [dt_min, dt_max]."""


F32_UNIT_ROUNDOFF = 2.0 ** -24
"""Relative rounding of an f32 number (half its ulp at most)."""
F32_TOLERANCE_ROUNDOFFS = 32
"""With precision "f32", newton_tol must be at least this many f32 roundings of the robot's
size (its tip_radius, the largest node coordinate): Newton's updates cannot be resolved below
a few roundings of the positions, and a tolerance under that floor is met, if at all, by
rounding noise (docs/numerics.md, "What ok promises": 2-m limbs at 1e-7 m hit the
iteration cap and came out 2.3× off).
32 roundings of the paper's 5.2 cm are 9.9e-8 m (the 1e-7 m it allows); above 0.52 m the
floor passes the largest newton_tol, 1e-6 m, and f32 is refused."""
F32_MAX_SIZE_TO_EDGE = 320.0
"""With precision "f32", the largest ratio of the robot's size (tip_radius) to its shortest
rest edge (`shortest_rest_edge`). Measured, A1+A2 for 0.3 s against f64 (speeds; f32 at
newton_tol 1e-7 m): ratios 39 (the paper's robot), 98, 104, 202 and 315 (n_arc 144) within
0.7 %; 406 (joint_radius 3 mm) 4.2 % off, 700 (n_arc 320) 4.4 % off at the iteration cap,
2,350 (joint_radius 1 mm, 10-cm limbs) 12× off. Beyond it f32 is refused."""
F64_UNIT_ROUNDOFF = 2.0 ** -53
"""Relative rounding of an f64 number (half its ulp at most)."""
F64_MAX_SIZE_TO_EDGE = F32_MAX_SIZE_TO_EDGE * F32_UNIT_ROUNDOFF / F64_UNIT_ROUNDOFF
"""With precision "f64", the largest ratio of the robot's size to its shortest rest edge:
the f32 bound's share of rounding (F32_MAX_SIZE_TO_EDGE roundings of the size in an edge), in
f64's, 1.7e11. Past it the rest shape itself is rounding: a tip_radius of joint_radius ×
(1 + 1e-15) gave limb edges of one ulp and a rest curvature of 0/0 (NaN, with NumPy's bare
warnings), ×(1 + 1e-13) a run reported "ok" (an audit, 2026-12). Well under it a stiff short
edge can still make Newton fail, which the instance's status reports (the paper robot's
limbs 1.001 × its joint radius long, a ratio of 6,000, ran with capped iterations; 12,000
failed at the first step, newton_failed)."""


def changed_fields(value) -> Dict[str, object]:
    """{field: value} of the fields of a StarParams or SolverConfig whose value differs from
    its class's default, in field order: what sets it apart. A record of these (a run folder's
    definition, a model-selection result) stays that of the same model when a later version
    adds a field whose default changes nothing, where a record of every field did not (an
    unfinished run could no longer be resumed: an audit, 2026-12). ValueError for another
    type."""
    if type(value) not in (StarParams, SolverConfig):
        raise ValueError(f"value must be a StarParams or a SolverConfig, got "
                         f"{type(value).__name__}")
    defaults = type(value)()
    return {f.name: getattr(value, f.name) for f in dataclasses.fields(value)
            if getattr(value, f.name) != getattr(defaults, f.name)}


def shortest_rest_edge(params: StarParams) -> float:
    """Length of the shortest edge of the rest shape, m: a spoke (joint_radius), a limb edge
    ((tip_radius − joint_radius)/n_limb) or an arc edge (the arc of rest curvature K̄(0)
    between two neighbouring joints, over n_arc)."""
    radius = 1.0 / params.actuator_profile.rest_curvature
    half_chord = params.joint_radius * math.sin(math.pi / 8)
    arc_length = 2.0 * radius * math.asin(half_chord / radius)
    return min(params.joint_radius, (params.tip_radius - params.joint_radius) / params.n_limb,
               arc_length / params.n_arc)


def check_precision(params, solver: SolverConfig):
    """ValueError, before any compute, where the solver's precision cannot resolve an instance
    of the batch (`params`: validated StarParams): in f32 newton_tol under
    `F32_TOLERANCE_ROUNDOFFS` roundings of its size, or a size more than `F32_MAX_SIZE_TO_EDGE`
    times its shortest edge; in f64 a size more than `F64_MAX_SIZE_TO_EDGE` times it. Names the
    instance and the fields."""
    f32 = solver.precision == "f32"
    bound = F32_MAX_SIZE_TO_EDGE if f32 else F64_MAX_SIZE_TO_EDGE
    remedy = ("use precision 'f64'" if f32 else
              "lengthen that edge (a tip_radius further beyond joint_radius, fewer n_limb or "
              "n_arc)")
    for index, p in enumerate(params):
        floor = F32_TOLERANCE_ROUNDOFFS * F32_UNIT_ROUNDOFF * p.tip_radius
        if f32 and solver.newton_tol < floor:
            highest = SOLVER_RANGES["newton_tol"][1]
            advice = (f"use a newton_tol in [{floor:.2g}, {highest:g}] m" if floor <= highest
                      else "use precision 'f64'")
            raise ValueError(
                f"newton_tol must be >= {floor:.2g} m with precision 'f32' for params[{index}] "
                f"({F32_TOLERANCE_ROUNDOFFS} f32 roundings of its tip_radius {p.tip_radius:g} "
                f"m), got {solver.newton_tol!r}: {advice}")
        edge = shortest_rest_edge(p)
        if p.tip_radius > bound * edge:
            raise ValueError(
                f"precision '{solver.precision}' cannot resolve params[{index}]: its tip_radius "
                f"{p.tip_radius:g} m is {p.tip_radius / edge:.4g} times its shortest rest edge "
                f"({edge:.3g} m, from joint_radius, tip_radius, n_arc and n_limb), more than "
                f"{bound:.4g}: {remedy}")

SOLVER_PRESET_FIELDS = {
    "paper": {},
    "identified": {},
    "accurate": {"integrator": "bdf2", "adaptive": True, "error_tol": 1e-6, "dt": 1e-3,
                 "jacobian": "chord"},
}
"""SolverConfig fields of each preset."""
