"""Quadratic drag on every rod edge (paper Eq. 1), spokes excepted (a choice: docs/model.md).

Per edge, on the mean of its two nodes' implicit velocities v, with t its unit tangent:
F = −½·ρ_f·Δl̄·(C∥|v∥|v∥ + C⊥|v⊥|v⊥), half to each node. The paper writes the drag per node; a
joint has no single tangent, so we apply it per edge.
"""

import numpy as np
import taichi as ti

from ..geometry import ARC, SPOKE
from .assembly import KEEP_EXPANSION
from .base import Term


@ti.func
def rod_drag(velocity, edge, parallel_coeff, perpendicular_coeff):
    """Drag on one edge: F = −(c∥|a|a·t + c⊥|b|b·n), a = v·t, b = v·n, n = t rotated by +90°,
    c = ½·ρ_f·Δl̄·C (kg/m² per unit height). Returns F (2,) N/m, ∂F/∂v and ∂F/∂e (2, 2) with
    v the edge's mean velocity (m/s) and e its edge vector (m)."""
    length = edge.norm()
    tangent = edge / length
    normal = ti.Vector([-tangent[1], tangent[0]])
    along = velocity.dot(tangent)
    across = velocity.dot(normal)
    along_size = ti.abs(along)
    across_size = ti.abs(across)
    force = -(parallel_coeff * along_size * along * tangent
              + perpendicular_coeff * across_size * across * normal)
    d_velocity = -2.0 * (parallel_coeff * along_size * tangent.outer_product(tangent)
                         + perpendicular_coeff * across_size * normal.outer_product(normal))
    # in the plane ∂t/∂e = n·nᵀ/|e| and ∂n/∂e = −t·nᵀ/|e| (the unit vectors only turn), so
    # ∂a/∂e = (b/|e|)·nᵀ, ∂b/∂e = −(a/|e|)·nᵀ and ∂F/∂e has rank one: −(p·t + q·n)·nᵀ/|e|
    # with p, q the tangent and normal weights below; half the arithmetic of the chain rule
    # through ∂F/∂t and ∂t/∂e = (I − t·tᵀ)/|e|
    tangent_weight = across * (2.0 * parallel_coeff * along_size - perpendicular_coeff * across_size)
    normal_weight = along * (parallel_coeff * along_size - 2.0 * perpendicular_coeff * across_size)
    d_edge = -(tangent_weight * tangent + normal_weight * normal).outer_product(normal) / length
    return force, d_velocity, d_edge


def rod_edges(topology) -> np.ndarray:
    """Indices of the edges that feel drag (every edge but the spokes)."""
    return np.flatnonzero(topology.edge_kind != SPOKE)


def rod_height_ratios(params, topology) -> np.ndarray:
    """(B, R) height over the hub's of each rod edge (`rod_edges`) of each instance, what its
    drag scales with: the arcs' actuator_height ratio, the limbs' foam_height ratio (all 1.0
    without component heights; `StarParams.height_ratios`)."""
    foam, actuator = np.array([p.height_ratios for p in params]).reshape(-1, 2).T
    on_arc = topology.edge_kind[rod_edges(topology)] == ARC
    return np.where(on_arc[None, :], actuator[:, None], foam[:, None])


@ti.data_oriented
class RodEdgeTerm(Term):
    """Base of the terms that act on every rod edge (`rod_edges`): their Jacobian pattern, the
    device tables `rods` (R, 2) and `rod_slot` (R, 4), and on when any coefficient is > 0."""

    @staticmethod
    def configuration(coefficients):
        used = any((values > 0).any() for values in coefficients.values())
        return () if used else None

    @staticmethod
    def coupled_pairs(topology):
        return [tuple(topology.edges[e]) for e in rod_edges(topology)]

    def build(self, topology):
        rods = rod_edges(topology)
        self.n_rods = len(rods)
        self.rods = self.assembly.index(topology.edges[rods])
        self.rod_slot = self.assembly.pair_slots(topology.edges[rods])


@ti.data_oriented
class RodDrag(RodEdgeTerm):
    name = "rod_drag"
    # C∥ barely moves the robot (its derivative ~1e-2 mm of displacement per unit over 0.3 s
    # from rest, α's ~1): at ε = 1e-5 its replicas' offsets were ~1e-12 m, 1e5 roundings of a
    # position, and its derivative 6e-5 to 1.6e-3 off (0.3 s of A1, A1+A2 and A1+A3 at C∥ =
    # 0.01 and 0.1, implicit Euler, fixed 1-ms steps, against Richardson differences at h =
    # 1e-2 and 3e-2 of C∥, which agree with each other to 3e-7); at 1e-2 all six are within
    # 1e-6. The force is linear in C∥, so a larger ε adds no truncation of its own
    sensitivity_steps = {"drag_parallel": 1e-2}
    linear_fields = ("drag_perpendicular", "drag_parallel", "fluid_density")
    pairs_linearly = True
    linear_coefficients = ("drag_parallel_coeff", "drag_perpendicular_coeff")

    @staticmethod
    def coefficients(params, topologies, topology):
        rods = rod_edges(topology)
        fluid = np.array([p.fluid_density for p in params])[:, None]
        # with the component heights on, an edge's drag scales with its height over the hub's
        wetted = (0.5 * fluid * topologies.stack("rest_length")[:, rods]
                  * rod_height_ratios(params, topology))
        return {"drag_parallel_coeff": wetted * np.array([p.drag_parallel for p in params])[:, None],
                "drag_perpendicular_coeff": wetted * np.array([p.drag_perpendicular for p in params])[:, None]}

    def build(self, topology):
        super().build(topology)
        if self.assembly.replicated:
            self.kept_velocity_derivative = self.assembly.batch_field(
                float, (self.assembly.capacity, self.n_rods, 4))
            """(capacity, R, 4): for a simulated instance, ∂F/∂v of each rod's drag at its
            converged state, row by row (kg/(m·s)), kept by its tangent step's assembly
            (`KEEP_EXPANSION`) for `pair_difference`."""

    @ti.func
    def edge_velocity(self, b, i, j, rate_gain):
        """The mean of the implicit velocities of nodes i and j of instance b (2,) m/s: what
        the drag of their edge acts on."""
        return 0.5 * (self.assembly.implicit_velocity(b, i, rate_gain)
                      + self.assembly.implicit_velocity(b, j, rate_gain))

    @ti.func
    def assemble(self, b, rate_gain, jacobian):
        primal = self.assembly.primal_instance(b)
        for r in range(self.n_rods):
            i, j = self.rods[r, 0], self.rods[r, 1]
            velocity = self.edge_velocity(b, i, j, rate_gain)
            # a replica: the drag's Taylor expansion about its instance's velocity
            # (`Assembly.primal_instance`)
            expansion_velocity = velocity
            if primal != b:
                expansion_velocity = self.edge_velocity(primal, i, j, rate_gain)
            force, d_velocity, d_edge = rod_drag(
                expansion_velocity, self.assembly.positions[b, j] - self.assembly.positions[b, i],
                self.drag_parallel_coeff[b, r], self.drag_perpendicular_coeff[b, r])
            if primal != b:
                force += d_velocity @ (velocity - expansion_velocity)
            if ti.static(self.assembly.replicated):
                if jacobian == KEEP_EXPANSION:
                    for k in ti.static(range(4)):
                        self.kept_velocity_derivative[b, r, k] = d_velocity[k // 2, k % 2]
            # half of F on each node; v is the mean of both, e = x_j − x_i
            d_first = 0.5 * (0.5 * rate_gain * d_velocity - d_edge)
            d_second = 0.5 * (0.5 * rate_gain * d_velocity + d_edge)
            self.assembly.add_residual(b, i, -0.5 * force)
            self.assembly.add_residual(b, j, -0.5 * force)
            self.assembly.add_block(b, self.rod_slot[r, 0], -d_first, jacobian)
            self.assembly.add_block(b, self.rod_slot[r, 1], -d_second, jacobian)
            self.assembly.add_block(b, self.rod_slot[r, 2], -d_first, jacobian)
            self.assembly.add_block(b, self.rod_slot[r, 3], -d_second, jacobian)

    @ti.func
    def pair_difference(self, b, plus, minus, rate_gain, coefficients_differ):
        """Add to rhs[b] half the difference of the residuals of replicas `plus` and `minus`
        of simulated instance b (at b's converged positions): each rod's kept ∂F/∂v times half
        the pair's difference of its mean velocity, the rest of their expansions about b being
        the same (`Term.pairs_linearly`), and where their drag coefficients differ from b's
        (`coefficients_differ`, `Term.linear_coefficients`) the drag at b's velocity with
        half the pair's difference of them as its coefficients."""
        for r in range(self.n_rods):
            i, j = self.rods[r, 0], self.rods[r, 1]
            velocity_plus = self.edge_velocity(plus, i, j, rate_gain)
            velocity_minus = self.edge_velocity(minus, i, j, rate_gain)
            d_velocity = ti.Matrix([[self.kept_velocity_derivative[b, r, 0],
                                     self.kept_velocity_derivative[b, r, 1]],
                                    [self.kept_velocity_derivative[b, r, 2],
                                     self.kept_velocity_derivative[b, r, 3]]])
            force = d_velocity @ (0.5 * (velocity_plus - velocity_minus))
            if coefficients_differ:
                # F is linear in c∥ and c⊥: F(v, c+) − F(v, c−) = F(v, c+ − c−), exactly
                scaled_force, _, _ = rod_drag(
                    self.edge_velocity(b, i, j, rate_gain),
                    self.assembly.positions[b, j] - self.assembly.positions[b, i],
                    0.5 * (self.drag_parallel_coeff[plus, r] - self.drag_parallel_coeff[minus, r]),
                    0.5 * (self.drag_perpendicular_coeff[plus, r]
                           - self.drag_perpendicular_coeff[minus, r]))
                force += scaled_force
            # as `assemble`: half of F on each node, with the residual's sign
            self.assembly.add_residual(b, i, -0.5 * force)
            self.assembly.add_residual(b, j, -0.5 * force)
