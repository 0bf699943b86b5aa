"""Quadratic drag on the central cylinder: F = −½·ρ_f·C_c·D_c·|v|v on the hub node."""

import numpy as np
import taichi as ti

from ..geometry import CENTRE
from .base import Term


@ti.func
def cylinder_drag(velocity, coeff, branch_velocity, frozen):
    """F = −c|v|v (N/m) with c = ½·ρ_f·C_c·D_c (kg/m²), v (2,) m/s. With `frozen` (a replica,
    `assembly.Assembly.branch_instance`) |v| is v's component along `branch_velocity` (m/s;
    0 where that is 0) instead: at v = branch_velocity the same force and first derivative,
    and a polynomial in v, with no kink at 0. Returns F and ∂F/∂v."""
    speed = velocity.norm()
    d_velocity = ti.Matrix.zero(float, 2, 2)
    if frozen != 0:
        # |v| → v·u, u the branch's unit direction (0 for none): ∂(v·u)v/∂v = (v·u)I + v⊗u
        branch_speed = branch_velocity.norm()
        direction = ti.Vector.zero(float, 2)
        if branch_speed > 0.0:
            direction = branch_velocity / branch_speed
        speed = velocity.dot(direction)
        d_velocity = -coeff * (speed * ti.Matrix.identity(float, 2) + velocity.outer_product(direction))
    elif speed > 0.0:
        d_velocity = -coeff * (speed * ti.Matrix.identity(float, 2) + velocity.outer_product(velocity) / speed)
    return -coeff * speed * velocity, d_velocity


@ti.data_oriented
class CylinderDrag(Term):
    name = "cylinder_drag"

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
        branch = self.assembly.branch_instance(b)
        force, d_velocity = cylinder_drag(
            velocity, self.cylinder_drag_coeff[b],
            self.assembly.implicit_velocity(branch, CENTRE, rate_gain), branch != b)
        self.assembly.add_residual(b, CENTRE, -force)
        self.assembly.add_block(b, self.centre_slot, -rate_gain * d_velocity, jacobian)
