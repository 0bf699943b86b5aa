"""Quadratic drag on the central cylinder: F = −½·ρ_f·C_c·D_c·|v|v on the hub node."""

import numpy as np
import taichi as ti

from ..geometry import CENTRE
from .base import Term


@ti.func
def cylinder_drag(velocity, coeff):
    """F = −c|v|v (N/m) with c = ½·ρ_f·C_c·D_c (kg/m²), v (2,) m/s. Returns F and ∂F/∂v."""
    speed = velocity.norm()
    d_velocity = ti.Matrix.zero(float, 2, 2)
    if speed > 0.0:
        d_velocity = -coeff * (speed * ti.Matrix.identity(float, 2) + velocity.outer_product(velocity) / speed)
    return -coeff * speed * velocity, d_velocity


@ti.data_oriented
class CylinderDrag(Term):
    name = "cylinder_drag"
    # C_c moves the robot little (the hub is one node): at ε = 1e-4 of it the replicas'
    # offsets are few roundings of a position, and A1 at C_c = 10 (n_arc 6, n_limb 2, implicit
    # Euler, 1-ms steps, newton_tol 1e-12) was 1.05e-5 off its extrapolated differences over
    # 0.687 s, falling to 7.8e-7 at 1e-3 and 1.5e-8 at 1e-2 (Taylor ratios 3.94 → 4.00;
    # found by a fuzz audit, 2026-12). The force is linear in C_c, so a larger ε adds no
    # truncation of its own
    sensitivity_steps = {"cylinder_drag": 1e-2}
    linear_fields = ("cylinder_drag", "fluid_density")

    @staticmethod
    def coefficients(params, topologies, topology):
        return {"cylinder_drag_coeff": np.array(
            [0.5 * p.fluid_density * p.cylinder_drag * p.cylinder_diameter for p in params])}

    @staticmethod
    def configuration(coefficients):
        return () if (coefficients["cylinder_drag_coeff"] > 0).any() else None

    def build(self, topology):
        self.centre_slot = self.assembly.slot(CENTRE, CENTRE)

    @ti.func
    def assemble(self, b, rate_gain, jacobian):
        velocity = self.assembly.implicit_velocity(b, CENTRE, rate_gain)
        # a replica: the drag's Taylor expansion about its instance's velocity
        # (`Assembly.primal_instance`)
        primal = self.assembly.primal_instance(b)
        expansion_velocity = velocity
        if primal != b:
            expansion_velocity = self.assembly.implicit_velocity(primal, CENTRE, rate_gain)
        force, d_velocity = cylinder_drag(expansion_velocity, self.cylinder_drag_coeff[b])
        if primal != b:
            force += d_velocity @ (velocity - expansion_velocity)
        self.assembly.add_residual(b, CENTRE, -force)
        self.assembly.add_block(b, self.centre_slot, -rate_gain * d_velocity, jacobian)
