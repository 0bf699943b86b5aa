"""Stretching of every edge: E_s = ½·E·r0·ε²·Δl̄, ε = |e|/Δl̄ − 1 (e = x_j − x_i, Δl̄ its rest
length). Arc edges use the actuator modulus E, limbs and spokes E_limb."""

import numpy as np
import taichi as ti

from ..geometry import ARC
from .strain import StrainTerm


@ti.func
def stretch_energy(edge, rest_length, stiffness, target_strain):
    """½·k·(ε − ε*)²·Δl̄ (J/m) for an edge vector (2,) m, k = E·r0 (N), target strain ε* (0 for
    elasticity; the material damping uses the same form about a moving target). The engine
    needs only its derivatives (`stretch_gradient_hessian`); the tests difference this energy
    to check them."""
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
class Stretching(StrainTerm):
    """Strain elements: the edges, s = ε, k = E·r0 (its energy ½·k·(ε − ε⁰)²·Δl̄, ε⁰ = 0)."""

    name = "stretching"
    linear_coefficients = ("edge_stiffness",)

    @staticmethod
    def coefficients(params, topologies, topology):
        thickness = np.array([p.thickness for p in params])[:, None]
        return {"rest_length": topologies.stack("rest_length"),
                "edge_stiffness": edge_modulus(params, topology) * thickness}

    @staticmethod
    def coupled_pairs(topology):
        return [tuple(edge) for edge in topology.edges]

    @staticmethod
    def element_count(topology):
        return topology.n_edges

    def build(self, topology):
        self.n_elements = topology.n_edges
        self.edges = self.assembly.index(topology.edges)
        self.edge_slot = self.assembly.pair_slots(topology.edges)

    @ti.func
    def edge_vector(self, b, e):
        """(i, j, x_j − x_i) of edge e at instance b's current positions."""
        i, j = self.edges[e, 0], self.edges[e, 1]
        return i, j, self.assembly.positions[b, j] - self.assembly.positions[b, i]

    @ti.func
    def stiffness(self, b, e):
        return self.edge_stiffness[b, e]

    @ti.func
    def strain(self, b, e):
        _, _, edge = self.edge_vector(b, e)
        return edge.norm() / self.rest_length[b, e] - 1.0

    @ti.func
    def add_element(self, b, e, stiffness, target, jacobian):
        i, j, edge = self.edge_vector(b, e)
        gradient, hessian = stretch_gradient_hessian(edge, self.rest_length[b, e], stiffness, target)
        self.assembly.scatter_edge(b, self.edge_slot, e, i, j, gradient, hessian, jacobian)
