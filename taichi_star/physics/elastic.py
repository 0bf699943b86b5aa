"""Elastic energy of the planar discrete rods (paper §III-A, design §2.2).

Both terms are written in edge vectors: stretching depends on one edge e = x_j − x_i, bending on
the two edges e1 = x_j − x_i, e2 = x_k − x_j of a triplet; the engine maps edge derivatives to
node derivatives. Lengths in m, stiffnesses per unit height (N for E·r0, N·m² for E·r0³/12).
"""

import taichi as ti


@ti.func
def stretch_energy(edge, rest_length, stiffness):
    """E_s = ½·k·ε²·Δl̄ with ε = |e|/Δl̄ − 1; edge (2,) m, k = E·r0 N. Returns J/m."""
    strain = edge.norm() / rest_length - 1.0
    return 0.5 * stiffness * strain * strain * rest_length


@ti.func
def stretch_gradient_hessian(edge, rest_length, stiffness):
    """∂E_s/∂e (2,) and ∂²E_s/∂e² (2, 2) for one edge."""
    length = edge.norm()
    tangent = edge / length
    strain = length / rest_length - 1.0
    outer = tangent.outer_product(tangent)
    hessian = stiffness * (outer / rest_length + strain / length * (ti.Matrix.identity(float, 2) - outer))
    return stiffness * strain * tangent, hessian


@ti.func
def turning_tangent(edge1, edge2):
    """tan(φ/2) of the turning angle φ from edge1 to edge2 (signed, counter-clockwise > 0)."""
    cross = edge1[0] * edge2[1] - edge1[1] * edge2[0]
    return cross / (edge1.norm() * edge2.norm() + edge1.dot(edge2))


@ti.func
def bend_energy(edge1, edge2, voronoi_length, natural_curvature, bending_stiffness):
    """E_b = ½·B·(κ − κ⁰)²·Δl with κ = 2 tan(φ/2)/Δl; B = E·r0³/12 (N·m²). Returns J/m."""
    curvature = 2.0 * turning_tangent(edge1, edge2) / voronoi_length
    excess = curvature - natural_curvature
    return 0.5 * bending_stiffness * excess * excess * voronoi_length


@ti.func
def angle_gradient_hessian(edge):
    """Gradient (2,) and Hessian (2, 2) of the edge's polar angle θ = atan2(e_y, e_x)."""
    squared = edge.dot(edge)
    gradient = ti.Vector([-edge[1], edge[0]]) / squared
    xy = 2.0 * edge[0] * edge[1]
    diff = edge[1] * edge[1] - edge[0] * edge[0]
    return gradient, ti.Matrix([[xy, diff], [diff, -xy]]) / (squared * squared)


@ti.func
def bend_gradient_hessian(edge1, edge2, voronoi_length, natural_curvature, bending_stiffness):
    """Derivatives of E_b with respect to (e1, e2): gradients g1, g2 (2,) and Hessian blocks
    H11, H12, H22 (2, 2) (H21 = H12ᵀ). Chain rule through φ = θ(e2) − θ(e1):
    dκ/dφ = (1 + tan²(φ/2))/Δl, d²κ/dφ² = tan(φ/2)(1 + tan²(φ/2))/Δl."""
    half_tangent = turning_tangent(edge1, edge2)
    curvature = 2.0 * half_tangent / voronoi_length
    dcurv = (1.0 + half_tangent * half_tangent) / voronoi_length
    d2curv = half_tangent * dcurv
    scale = bending_stiffness * voronoi_length
    excess = curvature - natural_curvature
    energy_phi = scale * excess * dcurv
    energy_phi_phi = scale * (dcurv * dcurv + excess * d2curv)
    grad1, hess1 = angle_gradient_hessian(edge1)
    grad2, hess2 = angle_gradient_hessian(edge2)
    h11 = energy_phi_phi * grad1.outer_product(grad1) - energy_phi * hess1
    h22 = energy_phi_phi * grad2.outer_product(grad2) + energy_phi * hess2
    h12 = -energy_phi_phi * grad1.outer_product(grad2)
    return -energy_phi * grad1, energy_phi * grad2, h11, h12, h22
