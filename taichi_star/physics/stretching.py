"""Stretching of every edge: E_s = ½·E·r0·ε²·Δl̄, ε = |e|/Δl̄ − 1 (e = x_j − x_i, Δl̄ its rest
length). Arc edges use the actuator modulus E, limbs and spokes E_limb."""

import numpy as np
import taichi as ti

from ..geometry import ARC
from .base import Term


@ti.func
def stretch_energy(edge, rest_length, stiffness, target_strain):
    """½·k·(ε − ε*)²·Δl̄ (J/m) for an edge vector (2,) m, k = E·r0 (N), target strain ε* (0 for
    elasticity; the material damping uses the same form about a moving target)."""
    excess = edge.norm() / rest_length - 1.0 - target_strain
    return 0.5 * stiffness * excess * excess * rest_length


@ti.func
def stretch_gradient_hessian(edge, rest_length, stiffness, target_strain):
    """∂E/∂e (2,) and ∂²E/∂e² (2, 2) of `stretch_energy`."""
    length = edge.norm()
    tangent = edge / length
    excess = length / rest_length - 1.0 - target_strain
    outer = tangent.outer_product(tangent)
    hessian = stiffness * (outer / rest_length + excess / length * (ti.Matrix.identity(float, 2) - outer))
    return stiffness * excess * tangent, hessian


def edge_modulus(params, topology) -> np.ndarray:
    """(B, E) Young's modulus of every edge, Pa: E on arcs, E_limb elsewhere."""
    arc = topology.edge_kind == ARC
    return np.where(arc, np.array([p.youngs_modulus for p in params])[:, None],
                    np.array([p.limb_modulus for p in params])[:, None])


@ti.data_oriented
class Stretching(Term):
    name = "stretching"

    @staticmethod
    def coefficients(params, topologies, topology):
        thickness = np.array([p.thickness for p in params])[:, None]
        return {"rest_length": np.stack([t.rest_length for t in topologies]),
                "edge_stiffness": edge_modulus(params, topology) * thickness}

    @staticmethod
    def coupled_pairs(topology):
        return [tuple(edge) for edge in topology.edges]

    def build(self, topology):
        self.n_edges = topology.n_edges
        self.edges = self.engine.arena.index(topology.edges)
        self.edge_slot = self.engine.pair_slots(topology.edges)

    @ti.func
    def assemble(self, b, rate_gain, jacobian):
        for e in range(self.n_edges):
            i, j = self.edges[e, 0], self.edges[e, 1]
            stiffness, target = self.reshaped(b, e, self.edge_stiffness[b, e], 0.0, rate_gain)
            gradient, hessian = stretch_gradient_hessian(
                self.engine.state.positions[b, j] - self.engine.state.positions[b, i],
                self.rest_length[b, e], stiffness, target)
            self.engine.scatter_edge(b, self.edge_slot, e, i, j, gradient, hessian, jacobian)
