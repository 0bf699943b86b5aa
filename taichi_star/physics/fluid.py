"""Fluid forces (paper Eqs. 1–3, design §2.5): rod drag, cylinder drag and the jet.

Each returns the force and its exact derivatives with respect to the new positions; velocities
are the implicit ones, v = (x_new − x_old)/h. The added mass (Eq. 3) is a diagonal mass and
lives in the engine's inertia term. Forces in N/m (per unit height), velocities in m/s.
"""

import taichi as ti


@ti.func
def rod_drag(velocity, edge, parallel_coeff, perpendicular_coeff):
    """Drag on one edge (Eq. 1): F = −(c∥|a|a·t + c⊥|b|b·n), a = v·t, b = v·n, n = t rotated by
    +90°, with c = ½·ρ_f·Δl̄·C (N·s²/m³·m). Returns F (2,), ∂F/∂v and ∂F/∂e (2, 2) where v is the
    edge's mean velocity and e its edge vector (the tangent's dependence on positions)."""
    length = edge.norm()
    tangent = edge / length
    normal = ti.Vector([-tangent[1], tangent[0]])
    along = velocity.dot(tangent)
    across = velocity.dot(normal)
    force = -(parallel_coeff * ti.abs(along) * along * tangent
              + perpendicular_coeff * ti.abs(across) * across * normal)
    d_velocity = -2.0 * (parallel_coeff * ti.abs(along) * tangent.outer_product(tangent)
                         + perpendicular_coeff * ti.abs(across) * normal.outer_product(normal))
    rotation = ti.Matrix([[0.0, -1.0], [1.0, 0.0]])
    rotated_velocity = ti.Vector([velocity[1], -velocity[0]])
    d_tangent = -(parallel_coeff * (2.0 * ti.abs(along) * tangent.outer_product(velocity)
                                    + ti.abs(along) * along * ti.Matrix.identity(float, 2))
                  + perpendicular_coeff * (2.0 * ti.abs(across) * normal.outer_product(rotated_velocity)
                                           + ti.abs(across) * across * rotation))
    tangent_d_edge = (ti.Matrix.identity(float, 2) - tangent.outer_product(tangent)) / length
    return force, d_velocity, d_tangent @ tangent_d_edge


@ti.func
def cylinder_drag(velocity, coeff):
    """Drag on the cylinder: F = −c|v|v with c = ½·ρ_f·C_c·D_c. Returns F and ∂F/∂v."""
    speed = velocity.norm()
    d_velocity = ti.Matrix.zero(float, 2, 2)
    if speed > 0.0:
        d_velocity = -coeff * (speed * ti.Matrix.identity(float, 2) + velocity.outer_product(velocity) / speed)
    return -coeff * speed * velocity, d_velocity


@ti.func
def quad_signed_area(x1, x2, x3, x4):
    """½ (x3 − x1) × (x4 − x2), m²: the signed area of the quadrilateral x1 x2 x3 x4."""
    diagonal13 = x3 - x1
    diagonal24 = x4 - x2
    return 0.5 * (diagonal13[0] * diagonal24[1] - diagonal13[1] * diagonal24[0])


@ti.func
def jet(centre, x1, x2, x3, x4, old_area, rate_gain, rate_offset, alpha, fluid_density, always):
    """Jet force of one inter-limb space on the centre (Eq. 2):
    f = −(ρ_f/L)(α·Ṡ)²·t, L = |x2 − x3|, t = unit(½(x2 + x3) − x_c), only while Ṡ < 0 unless
    `always` (design §2.5). The integrator's Ṡ = rate_gain·(S − S_old) + rate_offset (implicit
    Euler: (S − S_old)/h). x1, x4 are the joints, x2, x3 the tips; areas in m², gain in 1/s.
    Returns f (2,) and ∂f/∂x_c, ∂f/∂x1, ∂f/∂x2, ∂f/∂x3, ∂f/∂x4 (2, 2)."""
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
