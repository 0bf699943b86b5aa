"""The jet of each inter-limb space (paper Eq. 2), and its documented variants.

Space i lies between limbs k and k+1 (it holds actuator A_{k+1}): x1 = J_k, x2 = tip_k,
x3 = tip_{k+1}, x4 = J_{k+1}; S = ½|(x3 − x1) × (x4 − x2)|, L = |x2 − x3|. The jet is
f = −(ρ_f/L)·(α·Ṡ)²·t with Ṡ the integrator's rate of S: the water squeezed out through the
opening (a flux α·Ṡ per unit height through the width L, so a speed α·Ṡ/L) carries the momentum
flux ρ_f·(α·Ṡ)²/L out along t, and the robot takes the opposite. The paper's formula also pushes
while a space opens, which would make an opening space jet like a closing one: by default
(`jet_mode="contract"`) the jet acts only while Ṡ < 0.

Variants (StarParams fields, per instance; the defaults are the paper's model, bitwise):

- `jet_direction`, the unit vector t: "hub" (default), from the hub to the opening's midpoint
  ½(x2 + x3); "normal", the normal of the opening segment, t = R₉₀·(x2 − x3)/L (R₉₀ turns by
  +90°; the corners run counter-clockwise around the hub, so this points away from it): the
  water leaves the opening across it, whatever the hub's position; "bisector", the bisector of
  the two limbs' own directions, t ∝ (x2 − x1)/|x2 − x1| + (x3 − x4)/|x3 − x4|. The limbs are
  the walls of the channel the water leaves through, and the channel's axis is the bisector of
  its walls. We take each limb's direction joint → tip, not hub → tip: the limb is the foam rod
  from its joint, and as it rows about its joint its direction turns by the whole rowing angle,
  while the line from the hub to its tip turns by less and also moves with the hub's offset
  from the joints. In the rest shape the three directions coincide (radial through the
  opening's midpoint); they differ as the limbs row.
- `jet_application`: "hub" (default), the whole force on the centre node; "spread", a quarter
  on each of the four corners x1..x4. The water is pushed out by the walls of the space (the
  two limbs and the arc between their joints), and the reaction acts on them, not on the hub;
  the total force is the same, its point of application (hence the torque and how it loads the
  soft arcs) is not.
- `jet_inflow` α_in ≥ 0: while a space opens (Ṡ > 0, only with `jet_mode="contract"`) the
  water that refills it is drawn in through the opening, a flux α_in·Ṡ at the speed α_in·Ṡ/L
  along −t. The robot accelerates that water from rest into the space, so by the same momentum
  balance as the jet it takes the opposite momentum: f = +(ρ_f/L)·(α_in·Ṡ)²·t, pulling it
  towards the opening. (Water that is stopped inside the space returns part of that momentum,
  and the suction's lower pressure at the opening acts against it; α_in is the net fraction,
  to be fitted, 0 = none.) The force is continuous at Ṡ = 0 with its derivative (both vanish
  there), so Newton's Jacobian stays exact across the switch.

With the component heights on (`foam_height` etc.), the force scales with the foam's height
over the hub's: the limbs are the space's walls and its opening is as tall as they are (the
coefficient `jet_fluid_density` is ρ_f times that ratio).
"""

import numpy as np
import taichi as ti

from ..gait import N_ACTUATORS
from ..geometry import CENTRE
from ..params import JET_APPLICATIONS, JET_DIRECTIONS
from .base import Term

HUB_DIRECTION, NORMAL_DIRECTION, BISECTOR_DIRECTION = range(len(JET_DIRECTIONS))
"""Codes of the `jet_direction` choices (the int coefficient `jet_direction`)."""
SPREAD = JET_APPLICATIONS.index("spread")
"""Code of `jet_application="spread"` (the int coefficient `jet_application`)."""

@ti.func
def quad_signed_area(x1, x2, x3, x4):
    """½ (x3 − x1) × (x4 − x2), m²: the signed area of the quadrilateral x1 x2 x3 x4."""
    diagonal13 = x3 - x1
    diagonal24 = x4 - x2
    return 0.5 * (diagonal13[0] * diagonal24[1] - diagonal13[1] * diagonal24[0])


@ti.func
def no_derivatives():
    """Five zero (2, 2) derivatives, with respect to x_c and x1..x4."""
    zero = ti.Matrix.zero(float, 2, 2)
    return zero, zero, zero, zero, zero


@ti.func
def unit_and_projector(vector):
    """v/|v| and its derivative with respect to v, (I − u uᵀ)/|v| (2, 2)."""
    length = vector.norm()
    unit = vector / length
    return unit, (ti.Matrix.identity(float, 2) - unit.outer_product(unit)) / length


@ti.func
def jet_direction(kind, centre, x1, x2, x3, x4):
    """The jet's unit direction t of one space for `jet_direction` code `kind` (see the module
    docstring) and its derivatives ∂t/∂x_c, ∂t/∂x1..x4 (2, 2) (positions m, derivatives 1/m)."""
    direction = ti.Vector([0.0, 0.0])
    d_centre, d1, d2, d3, d4 = no_derivatives()
    if kind == HUB_DIRECTION:
        reach = 0.5 * (x2 + x3) - centre
        reach_length = reach.norm()
        direction = reach / reach_length
        direction_d_reach = (ti.Matrix.identity(float, 2) - direction.outer_product(direction)) / reach_length
        d_centre = -direction_d_reach
        d2 = 0.5 * direction_d_reach
        d3 = 0.5 * direction_d_reach
    elif kind == NORMAL_DIRECTION:
        opening_unit, opening_projector = unit_and_projector(x2 - x3)
        direction = ti.Vector([-opening_unit[1], opening_unit[0]])
        quarter_turn = ti.Matrix([[0.0, -1.0], [1.0, 0.0]])
        d2 = quarter_turn @ opening_projector
        d3 = -d2
    else:
        limb_unit, limb_projector = unit_and_projector(x2 - x1)
        next_limb_unit, next_limb_projector = unit_and_projector(x3 - x4)
        direction, bisector_projector = unit_and_projector(limb_unit + next_limb_unit)
        d2 = bisector_projector @ limb_projector
        d1 = -d2
        d3 = bisector_projector @ next_limb_projector
        d4 = -d3
    return direction, d_centre, d1, d2, d3, d4


@ti.func
def jet(centre, x1, x2, x3, x4, area_rate, rate_gain, alpha, fluid_density, always, inflow,
        direction_kind):
    """Force of one space on the robot: the jet f = −(ρ_f/L)(α·Ṡ)²·t while Ṡ < 0 (always if
    `always`), or the inflow f = +(ρ_f/L)(α_in·Ṡ)²·t while Ṡ > 0 (α_in = `inflow`, not with
    `always`), t by `jet_direction` code `direction_kind`. Ṡ = `area_rate` (m²/s), the
    integrator's rate of S, whose derivative with respect to S is `rate_gain` (1/s; implicit
    Euler: Ṡ = (S − S_old)/h, gain 1/h); x1, x4 the joints, x2, x3 the tips (m). Returns f (2,)
    N/m, ∂f/∂x_c, ∂f/∂x1..x4 (2, 2) and ∂f/∂Ṡ (2,) N·s/m³."""
    signed_area = quad_signed_area(x1, x2, x3, x4)
    force = ti.Vector([0.0, 0.0])
    force_d_rate = ti.Vector([0.0, 0.0])
    d_centre, d1, d2, d3, d4 = no_derivatives()
    jetting = always != 0 or area_rate < 0.0
    # `!= 0`, not `> 0`: the same for every instance (α_in ≥ 0), and the inflow, α_in², stays
    # even past 0 for a sensitivities' replica below it (at `> 0` one of a pair about a small
    # α_in switched it off: 2.06 times the derivative at 1e-6: a review, 2026-12)
    if jetting or (inflow != 0.0 and area_rate > 0.0):
        # strength α² (jet) or α_in² (inflow); sense −1: pushed along −t, +1: pulled along +t
        strength = inflow * inflow
        sense = 1.0
        if jetting:
            strength = alpha * alpha
            sense = -1.0
        area_sign = 1.0 if signed_area >= 0.0 else -1.0
        diagonal13 = x3 - x1
        diagonal24 = x4 - x2
        area_d3 = 0.5 * area_sign * ti.Vector([diagonal24[1], -diagonal24[0]])
        area_d4 = 0.5 * area_sign * ti.Vector([-diagonal13[1], diagonal13[0]])
        squared_rate = strength * area_rate * area_rate
        squared_rate_d_area = 2.0 * strength * area_rate * rate_gain
        opening = x2 - x3
        width = opening.norm()
        opening_unit = opening / width
        direction, direction_d_centre, direction_d1, direction_d2, direction_d3, direction_d4 = \
            jet_direction(direction_kind, centre, x1, x2, x3, x4)
        signed_magnitude = sense * (fluid_density * squared_rate / width)
        force = signed_magnitude * direction
        force_d_rate = sense * (fluid_density / width) * 2.0 * strength * area_rate * direction
        # f = ±ρ g t / L: the three factors' derivatives, each as an outer product or through t
        d_rate = sense * (fluid_density / width) * squared_rate_d_area * direction
        d_width = -sense * (fluid_density * squared_rate / (width * width)) * direction
        d1 = -d_rate.outer_product(area_d3) + signed_magnitude * direction_d1
        d3 = d_rate.outer_product(area_d3) - d_width.outer_product(opening_unit) + signed_magnitude * direction_d3
        d4 = d_rate.outer_product(area_d4) + signed_magnitude * direction_d4
        d2 = -d_rate.outer_product(area_d4) + d_width.outer_product(opening_unit) + signed_magnitude * direction_d2
        d_centre = signed_magnitude * direction_d_centre
    return force, d_centre, d1, d2, d3, d4, force_d_rate


@ti.data_oriented
class Jet(Term):
    name = "jet"
    linear_fields = ("alpha", "jet_inflow", "fluid_density")  # α² and α_in²: quadratic

    @staticmethod
    def coefficients(params, topologies, topology):
        return {"jet_alpha": np.array([p.alpha for p in params]),
                # ρ_f times the space's height over the hub's: the foam limbs are its walls
                "jet_fluid_density": np.array([p.fluid_density * p.height_ratios[0]
                                               for p in params]),
                "jet_always": np.array([p.jet_mode == "always" for p in params], dtype=np.int32),
                "jet_inflow": np.array([p.jet_inflow for p in params]),
                "jet_direction": np.array([JET_DIRECTIONS.index(p.jet_direction) for p in params],
                                          dtype=np.int32),
                "jet_application": np.array([JET_APPLICATIONS.index(p.jet_application)
                                             for p in params], dtype=np.int32)}

    @staticmethod
    def configuration(coefficients):
        """None without jet and inflow; else the variants some instance uses: "variants" (a
        direction, application or inflow other than the paper's) and "spread" (the force on the
        corners). Without them the kernel code is the paper's jet alone."""
        if not ((coefficients["jet_alpha"] > 0).any() or (coefficients["jet_inflow"] > 0).any()):
            return None
        spread = (coefficients["jet_application"] == SPREAD).any()
        variants = spread or (coefficients["jet_direction"] != HUB_DIRECTION).any() or (
            coefficients["jet_inflow"] > 0).any()
        return tuple(name for name, used in (("variants", variants), ("spread", spread)) if used)

    @staticmethod
    def coupled_pairs(topology):
        return [(CENTRE, node) for quad in topology.jet_quads for node in quad]

    @classmethod
    def configured_pairs(cls, topology, configuration):
        """With "spread", a corner's force depends on the hub and all four corners."""
        pairs = cls.coupled_pairs(topology)
        if "spread" in configuration:
            pairs += [(int(a), int(c)) for quad in topology.jet_quads for a in quad for c in quad
                      if a < c]
        return pairs

    @staticmethod
    def history(topology, terms=()):
        # S at the start of the step, and the integrator's offset of Ṡ (BDF2: from the step before)
        return {"previous_areas": (N_ACTUATORS,), "area_rate_offset": (N_ACTUATORS,)}

    def build(self, topology):
        self.jet_quads = self.assembly.index(topology.jet_quads)
        slot = self.assembly.slot
        self.jet_slot = self.assembly.index([[slot(CENTRE, CENTRE)] + [slot(CENTRE, n) for n in quad]
                                             for quad in topology.jet_quads])
        if "spread" in self.configuration_switches:
            # (8, 4·5): for corner a of each space, the slots of (a, c) and (a, x1..x4)
            self.corner_slot = self.assembly.index(
                [[slot(a, n) for a in quad for n in (CENTRE, *quad)] for quad in topology.jet_quads])

    @ti.func
    def area(self, b, k):
        """S (m²) of space k at instance b's current positions."""
        positions = ti.static(self.assembly.positions)
        return ti.abs(quad_signed_area(
            positions[b, self.jet_quads[k, 0]], positions[b, self.jet_quads[k, 1]],
            positions[b, self.jet_quads[k, 2]], positions[b, self.jet_quads[k, 3]]))

    @ti.func
    def area_rate(self, b, k, rate_gain):
        """Ṡ (m²/s) of space k at instance b's current positions, by the integrator's rate."""
        return rate_gain * (self.area(b, k) - self.previous_areas[b, k]) + self.area_rate_offset[b, k]

    @ti.func
    def begin_step(self, b, start_time, end_time, h, ratio, rate_gain, use_history):
        for k in range(N_ACTUATORS):
            area = self.area(b, k)
            self.area_rate_offset[b, k] = self.assembly.rate_offset(
                area, self.previous_areas[b, k], h, ratio, use_history)
            self.previous_areas[b, k] = area

    @ti.func
    def assemble(self, b, rate_gain, jacobian):
        positions = ti.static(self.assembly.positions)
        variants = ti.static("variants" in self.configuration_switches)
        primal = self.assembly.primal_instance(b)
        inflow = 0.0
        direction_kind = HUB_DIRECTION
        if ti.static(variants):
            # a replica of an instance without inflow has none either: the inflow force is
            # α_in²-flat at 0, and a pair at ±ε would switch it on on one side only
            if self.jet_inflow[primal] != 0.0:
                inflow = self.jet_inflow[b]
            direction_kind = self.jet_direction[b]
        for k in range(N_ACTUATORS):
            area_rate = self.area_rate(b, k, rate_gain)
            # a replica: the force's Taylor expansion in Ṡ about its instance's Ṡ
            # (`Assembly.primal_instance`), so it also jets (or draws in) when its instance's
            # space does: the switch at Ṡ = 0 is a kink, and an instance's space that reopens
            # slowly keeps Ṡ just above it for many steps
            expansion_rate = area_rate
            if primal != b:
                expansion_rate = self.area_rate(primal, k, rate_gain)
            force, d_centre, d1, d2, d3, d4, force_d_rate = jet(
                positions[b, CENTRE], positions[b, self.jet_quads[k, 0]],
                positions[b, self.jet_quads[k, 1]], positions[b, self.jet_quads[k, 2]],
                positions[b, self.jet_quads[k, 3]], expansion_rate, rate_gain,
                self.jet_alpha[b], self.jet_fluid_density[b], self.jet_always[b], inflow,
                direction_kind)
            if primal != b:
                force += force_d_rate * (area_rate - expansion_rate)
            if ti.static("spread" in self.configuration_switches):
                if self.jet_application[b] == SPREAD:
                    self.spread_on_corners(b, k, force, d_centre, d1, d2, d3, d4, jacobian)
                else:
                    self.apply_on_hub(b, k, force, d_centre, d1, d2, d3, d4, jacobian)
            else:
                self.apply_on_hub(b, k, force, d_centre, d1, d2, d3, d4, jacobian)

    @ti.func
    def apply_on_hub(self, b, k, force, d_centre, d1, d2, d3, d4, jacobian):
        """Space k's force f and its derivatives on the hub."""
        self.assembly.add_residual(b, CENTRE, -force)
        self.assembly.add_block(b, self.jet_slot[k, 0], -d_centre, jacobian)
        self.assembly.add_block(b, self.jet_slot[k, 1], -d1, jacobian)
        self.assembly.add_block(b, self.jet_slot[k, 2], -d2, jacobian)
        self.assembly.add_block(b, self.jet_slot[k, 3], -d3, jacobian)
        self.assembly.add_block(b, self.jet_slot[k, 4], -d4, jacobian)

    @ti.func
    def spread_on_corners(self, b, k, force, d_centre, d1, d2, d3, d4, jacobian):
        """A quarter of space k's force f and of its derivatives on each of its four corners."""
        for corner in ti.static(range(4)):
            self.assembly.add_residual(b, self.jet_quads[k, corner], -0.25 * force)
            row = ti.static(5 * corner)
            self.assembly.add_block(b, self.corner_slot[k, row], -0.25 * d_centre, jacobian)
            self.assembly.add_block(b, self.corner_slot[k, row + 1], -0.25 * d1, jacobian)
            self.assembly.add_block(b, self.corner_slot[k, row + 2], -0.25 * d2, jacobian)
            self.assembly.add_block(b, self.corner_slot[k, row + 3], -0.25 * d3, jacobian)
            self.assembly.add_block(b, self.corner_slot[k, row + 4], -0.25 * d4, jacobian)
