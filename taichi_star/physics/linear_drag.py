"""Linear (skin-friction) drag on the rod edges and on the hub, off unless `linear_drag` or
`hub_linear_drag` is set.

The quadratic drag of `rod_drag` and `cylinder_drag` (∝ |v|v) vanishes in the slow glide
between pulses, where the robot moves at ~1 mm/s; there the viscous (laminar, Stokes-like)
friction of the boundary layer, ∝ v, is what is left to stop it. Per rod edge, on the mean v of
its two nodes' implicit velocities: F = −c_l·Δl̄·v, half to each node; on the hub node:
F = −c_h·v (forces per unit height, N/m).

One isotropic coefficient per component, by choice: a slender body's viscous resistance
normal to itself is about twice that along it (slender-body Stokes flow), but the ratio is then
fixed by theory and adds nothing to fit, while a free ratio is a second number that five
measured net speeds cannot separate from the first; the anisotropy of the fast strokes is
carried by the quadratic term's C∥ and C⊥.
"""

import numpy as np
import taichi as ti

from ..geometry import CENTRE
from .rod_drag import RodEdgeTerm, rod_edges, rod_height_ratios


@ti.data_oriented
class LinearDrag(RodEdgeTerm):
    name = "linear_drag"
    linear_fields = ("linear_drag", "hub_linear_drag")

    @staticmethod
    def coefficients(params, topologies, topology):
        """linear_rod_coeff (B, R) = c_l·Δl̄ (times the edge's height ratio with component
        heights), N·s/m² per edge; linear_hub_coeff (B,) = c_h, N·s/m² (both per unit height
        of the hub)."""
        rods = rod_edges(topology)
        # with the component heights on, an edge's friction scales with its height over the hub's
        lengths = (topologies.stack("rest_length")[:, rods]
                   * rod_height_ratios(params, topology))
        return {"linear_rod_coeff": lengths * np.array([p.linear_drag for p in params])[:, None],
                "linear_hub_coeff": np.array([p.hub_linear_drag for p in params])}

    def build(self, topology):
        super().build(topology)
        self.centre_slot = self.assembly.slot(CENTRE, CENTRE)

    @ti.func
    def assemble(self, b, rate_gain, jacobian):
        identity = ti.Matrix.identity(float, 2)
        for r in range(self.n_rods):
            i, j = self.rods[r, 0], self.rods[r, 1]
            coeff = self.linear_rod_coeff[b, r]
            velocity = 0.5 * (self.assembly.implicit_velocity(b, i, rate_gain)
                              + self.assembly.implicit_velocity(b, j, rate_gain))
            # F = −c·v, half on each node; ∂v/∂x_i = ∂v/∂x_j = ½·rate_gain
            self.assembly.add_residual(b, i, 0.5 * coeff * velocity)
            self.assembly.add_residual(b, j, 0.5 * coeff * velocity)
            block = 0.25 * coeff * rate_gain * identity
            for corner in ti.static(range(4)):
                self.assembly.add_block(b, self.rod_slot[r, corner], block, jacobian)
        hub = self.linear_hub_coeff[b]
        self.assembly.add_residual(b, CENTRE, hub * self.assembly.implicit_velocity(b, CENTRE, rate_gain))
        self.assembly.add_block(b, self.centre_slot, hub * rate_gain * identity, jacobian)
