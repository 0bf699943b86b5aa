"""The jet of each inter-limb space (paper Eq. 2), pushing on the hub.

Space i lies between limbs k and k+1 (it holds actuator A_{k+1}): x1 = J_k, x2 = tip_k,
x3 = tip_{k+1}, x4 = J_{k+1}; S = ½|(x3 − x1) × (x4 − x2)|, L = |x2 − x3|, t = unit vector from
the hub to the opening's midpoint. f = −(ρ_f/L)·(α·Ṡ)²·t with Ṡ the integrator's rate of S; the
paper's formula also pushes while a space opens, which would make an opening space jet like a
closing one: by default (`jet_mode="contract"`) the jet acts only while Ṡ < 0.
"""

import numpy as np
import taichi as ti

from ..gait import N_ACTUATORS
from ..geometry import CENTRE
from .base import Term


@ti.func
def quad_signed_area(x1, x2, x3, x4):
    """½ (x3 − x1) × (x4 − x2), m²: the signed area of the quadrilateral x1 x2 x3 x4."""
    diagonal13 = x3 - x1
    diagonal24 = x4 - x2
    return 0.5 * (diagonal13[0] * diagonal24[1] - diagonal13[1] * diagonal24[0])


@ti.func
def jet(centre, x1, x2, x3, x4, old_area, rate_gain, rate_offset, alpha, fluid_density, always):
    """Jet force of one space on the hub: f = −(ρ_f/L)(α·Ṡ)²·t, only while Ṡ < 0 unless
    `always`. Ṡ = rate_gain·(S − S_old) + rate_offset (implicit Euler: (S − S_old)/h); x1, x4 the
    joints, x2, x3 the tips (m), areas m², gain 1/s. Returns f (2,) N/m and ∂f/∂x_c, ∂f/∂x1..x4
    (2, 2)."""
    signed_area = quad_signed_area(x1, x2, x3, x4)
    area_rate = rate_gain * (ti.abs(signed_area) - old_area) + rate_offset
    force = ti.Vector([0.0, 0.0])
    d_centre = ti.Matrix.zero(float, 2, 2)
    d1 = ti.Matrix.zero(float, 2, 2)
    d2 = ti.Matrix.zero(float, 2, 2)
    d3 = ti.Matrix.zero(float, 2, 2)
    d4 = ti.Matrix.zero(float, 2, 2)
    if always != 0 or area_rate < 0.0:
        area_sign = 1.0 if signed_area >= 0.0 else -1.0
        diagonal13 = x3 - x1
        diagonal24 = x4 - x2
        area_d3 = 0.5 * area_sign * ti.Vector([diagonal24[1], -diagonal24[0]])
        area_d4 = 0.5 * area_sign * ti.Vector([-diagonal13[1], diagonal13[0]])
        squared_rate = alpha * alpha * area_rate * area_rate
        squared_rate_d_area = 2.0 * alpha * alpha * area_rate * rate_gain
        opening = x2 - x3
        width = opening.norm()
        opening_unit = opening / width
        reach = 0.5 * (x2 + x3) - centre
        reach_length = reach.norm()
        direction = reach / reach_length
        direction_d_reach = (ti.Matrix.identity(float, 2) - direction.outer_product(direction)) / reach_length
        magnitude = fluid_density * squared_rate / width
        force = -magnitude * direction
        # f = −ρ g t / L: the three factors' derivatives, each as an outer product or through t
        d_rate = -(fluid_density / width) * squared_rate_d_area * direction
        d_width = (fluid_density * squared_rate / (width * width)) * direction
        d1 = -d_rate.outer_product(area_d3)
        d3 = d_rate.outer_product(area_d3) - d_width.outer_product(opening_unit) - 0.5 * magnitude * direction_d_reach
        d4 = d_rate.outer_product(area_d4)
        d2 = -d_rate.outer_product(area_d4) + d_width.outer_product(opening_unit) - 0.5 * magnitude * direction_d_reach
        d_centre = magnitude * direction_d_reach
    return force, d_centre, d1, d2, d3, d4


@ti.data_oriented
class Jet(Term):
    name = "jet"

    @staticmethod
    def coefficients(params, topologies, topology):
        return {"jet_alpha": np.array([p.alpha for p in params]),
                "fluid_density": np.array([p.fluid_density for p in params]),
                "jet_always": np.array([p.jet_mode == "always" for p in params], dtype=np.int32)}

    @staticmethod
    def configuration(coefficients):
        return () if (coefficients["jet_alpha"] > 0).any() else None

    @staticmethod
    def coupled_pairs(topology):
        return [(CENTRE, node) for quad in topology.jet_quads for node in quad]

    @staticmethod
    def history(topology, terms=()):
        # S at the start of the step, and the integrator's offset of Ṡ (BDF2: from the step before)
        return {"previous_areas": (N_ACTUATORS,), "area_rate_offset": (N_ACTUATORS,)}

    def build(self, topology):
        self.jet_quads = self.assembly.index(topology.jet_quads)
        slot = self.assembly.slot
        self.jet_slot = self.assembly.index([[slot(CENTRE, CENTRE)] + [slot(CENTRE, n) for n in quad]
                                             for quad in topology.jet_quads])

    @ti.func
    def area(self, b, k):
        """S (m²) of space k at instance b's current positions."""
        positions = ti.static(self.assembly.positions)
        return ti.abs(quad_signed_area(
            positions[b, self.jet_quads[k, 0]], positions[b, self.jet_quads[k, 1]],
            positions[b, self.jet_quads[k, 2]], positions[b, self.jet_quads[k, 3]]))

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
        for k in range(N_ACTUATORS):
            force, d_centre, d1, d2, d3, d4 = jet(
                positions[b, CENTRE], positions[b, self.jet_quads[k, 0]],
                positions[b, self.jet_quads[k, 1]], positions[b, self.jet_quads[k, 2]],
                positions[b, self.jet_quads[k, 3]], self.previous_areas[b, k], rate_gain,
                self.area_rate_offset[b, k], self.jet_alpha[b], self.fluid_density[b],
                self.jet_always[b])
            self.assembly.add_residual(b, CENTRE, -force)
            self.assembly.add_block(b, self.jet_slot[k, 0], -d_centre, jacobian)
            self.assembly.add_block(b, self.jet_slot[k, 1], -d1, jacobian)
            self.assembly.add_block(b, self.jet_slot[k, 2], -d2, jacobian)
            self.assembly.add_block(b, self.jet_slot[k, 3], -d3, jacobian)
            self.assembly.add_block(b, self.jet_slot[k, 4], -d4, jacobian)
