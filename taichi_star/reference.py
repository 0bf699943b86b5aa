"""Single-instance NumPy reference implementation of the star swimmer model, for tests.

It is written independently of the Taichi batch engine, from the specification alone, so that
the two can check each other. Implicit Euler or BDF2 in time; elasticity, Kelvin–Voigt material
damping, rod and cylinder drag (quadratic and linear), jets, added mass, per-actuator gains
and delays, and the entrained water (its velocity two more unknowns of each step). Everything
is double precision; each Newton iteration assembles the exact Jacobian of all forces as a
scipy.sparse matrix and factors it with SuperLU (N = 193 nodes, 386 degrees of freedom: ~3 ms
per iteration).

Units are SI, per unit out-of-plane height H = 1 m: positions in m, forces in N/m, energies in
J/m, masses in kg/m. A configuration `q` is an (N, 2) array; its flat degree-of-freedom vector is
`q.reshape(-1)`, so node i owns DOFs 2i (x) and 2i + 1 (y).

The element functions below are pure and vectorised: every position argument has shape (..., 2)
and every scalar argument broadcasts against the leading axes `...`, so a single call evaluates
one element (shape (2,)) for the tests or all elements of a kind at once for the assembly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .actuation import snapped_to_switch
from .extras import require
from .gait import Gait
from .geometry import ARC, ARC_BEND, JOINT_BEND, SPOKE, build_topology
from .params import SolverConfig, StarParams


class NewtonDidNotConverge(RuntimeError):
    """A time step whose Newton iteration did not reach `newton_tol` within `max_newton`."""


def _cross(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _perp(a):
    """a rotated by +90°: (-a_y, a_x)."""
    return np.stack([-a[..., 1], a[..., 0]], axis=-1)


def _outer(a, b):
    return a[..., :, None] * b[..., None, :]


def _dot(a, b):
    return (a * b).sum(-1)


def _blocks(rows):
    """Assemble a (..., 2n, 2n) matrix from an n×n nested list of (..., 2, 2) blocks (or 0)."""
    shape = next(np.shape(b) for row in rows for b in row if not np.isscalar(b))
    filled = [[np.broadcast_to(b, shape) if not np.isscalar(b) else np.zeros(shape) for b in row]
              for row in rows]
    return np.concatenate([np.concatenate(row, axis=-1) for row in filled], axis=-2)


# --------------------------------------------------------------------------------------------
# Elastic and material-damping elements
#
# Both elastic energies are quadratic in a strain s of the element: E = ½ k_s s², with
# s = ε = |e|/Δl̄ − 1, k_s = E·r0·Δl̄ for a stretching edge and s = δ = κ − κ⁰,
# k_s = (E·r0³/12)·Δl for a bending triplet. The strain functions give s with its gradient and
# Hessian; `quadratic_strain_element` turns them into an energy, and `damping_element` into the
# Kelvin–Voigt viscous force on the rate of the same strain.
# --------------------------------------------------------------------------------------------

def stretch_strain(xi, xj, rest_length):
    """Axial strain ε = |xj − xi| / Δl̄ − 1 of one edge and its derivatives.

    Args: xi, xj (..., 2) end positions, m; rest_length Δl̄ (...), m.
    Returns: ε (...) (-); gradient (..., 4) over (xi, xj), 1/m; Hessian (..., 4, 4), 1/m².
    """
    rest_length = np.asarray(rest_length)
    d = xj - xi
    length = np.linalg.norm(d, axis=-1)
    strain = length / rest_length - 1.0
    u = d / length[..., None]
    g = u / rest_length[..., None]
    h = (np.eye(2) - _outer(u, u)) / (length * rest_length)[..., None, None]
    return strain, np.concatenate([-g, g], axis=-1), _blocks([[h, -h], [-h, h]])


def _angle_hessian(e):
    """Hessian (..., 2, 2) of the direction angle atan2(e_y, e_x) with respect to e."""
    x, y = e[..., 0], e[..., 1]
    r4 = (x * x + y * y) ** 2
    off = (y * y - x * x) / r4
    return np.stack([np.stack([2 * x * y / r4, off], -1),
                     np.stack([off, -2 * x * y / r4], -1)], -2)


def bend_strain(xi, xj, xk, voronoi_length, natural_curvature):
    """Bending strain δ = κ − κ⁰ of one triplet (angle at xj) and its derivatives.

    κ = 2 (e1 × e2) / ((|e1||e2| + e1·e2) Δl) = 2 tan(φ/2) / Δl, e1 = xj − xi, e2 = xk − xj,
    φ the signed turning angle.

    Args: xi, xj, xk (..., 2), m; voronoi_length Δl (...), m; natural_curvature κ⁰ (...), 1/m.
    Returns: δ (...), 1/m; gradient (..., 6) over (xi, xj, xk), 1/m²; Hessian (..., 6, 6), 1/m³.
    """
    voronoi_length = np.asarray(voronoi_length)
    e1 = xj - xi
    e2 = xk - xj
    n1 = _dot(e1, e1)
    n2 = _dot(e2, e2)
    # tan(φ/2) from the cross and dot products: the same expression as the spec's κ, and it
    # needs no atan2; the derivatives go through φ = angle(e2) − angle(e1).
    half_tan = _cross(e1, e2) / (np.sqrt(n1 * n2) + _dot(e1, e2))
    curvature = 2.0 * half_tan / voronoi_length
    dk_dphi = (1.0 + half_tan ** 2) / voronoi_length
    d2k_dphi2 = half_tan * (1.0 + half_tan ** 2) / voronoi_length

    g1 = -_perp(e1) / n1[..., None]
    g2 = _perp(e2) / n2[..., None]
    grad_phi = np.concatenate([-g1, g1 - g2, g2], axis=-1)
    h1 = -_angle_hessian(e1)
    h2 = _angle_hessian(e2)
    hess_phi = _blocks([[h1, -h1, 0], [-h1, h1 + h2, -h2], [0, -h2, h2]])
    grad = dk_dphi[..., None] * grad_phi
    hess = (d2k_dphi2[..., None, None] * _outer(grad_phi, grad_phi)
            + dk_dphi[..., None, None] * hess_phi)
    return curvature - natural_curvature, grad, hess


def quadratic_strain_element(strain, strain_gradient, strain_hessian, stiffness, offset=0.0):
    """W = ½ k (s − s₀)² of a strain s with known derivatives, and the derivatives of W.

    Args: strain s (...); strain_gradient (..., n); strain_hessian (..., n, n) (any units
        [s], [s]/m, [s]/m²); stiffness k (...), J/m per [s]²; offset s₀ (...), [s].
    Returns: W (...), J/m; gradient k (s − s₀) ∇s (..., n), N/m;
        Hessian k (∇s ∇sᵀ + (s − s₀) ∇²s) (..., n, n), N/m².
    """
    stiffness = np.asarray(stiffness)
    excess = strain - offset
    energy = 0.5 * stiffness * excess ** 2
    grad = (stiffness * excess)[..., None] * strain_gradient
    hess = stiffness[..., None, None] * (_outer(strain_gradient, strain_gradient)
                                         + excess[..., None, None] * strain_hessian)
    return energy, grad, hess


def stretch_element(xi, xj, rest_length, stiffness):
    """Stretching energy E = ½ k ε² Δl̄ of one edge and its derivatives.

    Args: xi, xj (..., 2) end positions, m; rest_length Δl̄ (...), m; stiffness k = E·r0 (...), N/m.
    Returns: energy (...) J/m; gradient (..., 4) over (xi, xj), N/m; Hessian (..., 4, 4), N/m².
    """
    return quadratic_strain_element(*stretch_strain(xi, xj, rest_length),
                                    np.asarray(stiffness) * np.asarray(rest_length))


def bend_element(xi, xj, xk, voronoi_length, natural_curvature, bending_stiffness):
    """Bending energy E = ½ B (κ − κ⁰)² Δl of one triplet (see `bend_strain`) and its
    derivatives.

    Args: xi, xj, xk (..., 2), m; voronoi_length Δl (...), m; natural_curvature κ⁰ (...), 1/m;
        bending_stiffness B = E·r0³/12 (...), N·m.
    Returns: energy (...) J/m; gradient (..., 6) over (xi, xj, xk), N/m;
        Hessian (..., 6, 6), N/m².
    """
    return quadratic_strain_element(
        *bend_strain(xi, xj, xk, voronoi_length, natural_curvature),
        np.asarray(bending_stiffness) * np.asarray(voronoi_length))


def damping_element(strain, strain_gradient, strain_hessian, strain_anchor, rate_gain,
                    strain_stiffness, damping_time):
    """Kelvin–Voigt damping of one element's strain s over an implicit step.

    The integrator's discrete strain rate is ṡ = γ (s − s*), with s* fixed by the history
    (implicit Euler: γ = 1/h, s* = s_k; BDF2: γ = 3/(2h), s* = s_k + (s_k − s_{k−1})/3, so that
    ṡ = (3 s_{k+1} − 4 s_k + s_{k−1})/(2h)). The viscous force f = −τ k_s ṡ ∇s is then minus
    the gradient of the pseudo-potential P = ½ τ γ k_s (s − s*)², whose Hessian
    τ k_s (γ ∇s ∇sᵀ + ṡ ∇²s) is the exact (symmetric) Jacobian.

    Args: strain s (...), strain_gradient (..., n), strain_hessian (..., n, n): the element's
        strain and its derivatives (`stretch_strain` or `bend_strain`); strain_anchor s* (...);
        rate_gain γ, 1/s; strain_stiffness k_s (...), J/m per [s]² (the element's energy is
        ½ k_s s²); damping_time τ, s.
    Returns: P (...), J/m; gradient (..., n) = −f, N/m; Hessian (..., n, n), N/m².
    """
    return quadratic_strain_element(strain, strain_gradient, strain_hessian,
                                    damping_time * rate_gain * np.asarray(strain_stiffness),
                                    strain_anchor)


# --------------------------------------------------------------------------------------------
# Fluid elements; velocities are implicit, v = (x_new − x_old) / h (BDF2 passes an effective
# x_old and h, see ImplicitStep)
# --------------------------------------------------------------------------------------------

def rod_drag_element(xa, xb, xa_old, xb_old, dt, rest_length, fluid_density,
                     drag_parallel, drag_perpendicular):
    """Drag on one rod edge, split equally between its two nodes, and its Jacobian.

    v = mean node velocity, t = unit tangent of (xb − xa), n = (−t_y, t_x), a = v·t, b = v·n;
    F = −½ ρ_f Δl̄ (C∥ |a| a t + C⊥ |b| b n); each node receives F/2.

    Args: xa, xb (..., 2) new positions, m; xa_old, xb_old (..., 2) old positions, m; dt h, s;
        rest_length Δl̄ (...), m; fluid_density ρ_f, kg/m³; drag_parallel C∥, drag_perpendicular
        C⊥ (-).
    Returns: forces (..., 4) on (xa, xb), N/m; Jacobian (..., 4, 4) = ∂forces/∂(xa, xb), N/m².
    """
    d = xb - xa
    length = np.linalg.norm(d, axis=-1)
    t = d / length[..., None]
    n = _perp(t)
    v = 0.5 * ((xa - xa_old) + (xb - xb_old)) / dt
    a = _dot(v, t)
    b = _dot(v, n)
    c = 0.5 * fluid_density * np.asarray(rest_length)
    cp = c * drag_parallel
    cn = c * drag_perpendicular
    force = -((cp * np.abs(a) * a)[..., None] * t + (cn * np.abs(b) * b)[..., None] * n)
    dF_dv = -2.0 * ((cp * np.abs(a))[..., None, None] * _outer(t, t)
                    + (cn * np.abs(b))[..., None, None] * _outer(n, n))
    # The tangent turns with the edge: ∂t/∂d = n nᵀ/|d| and ∂n/∂d = −t nᵀ/|d|.
    turn = -(((cp * 2 * np.abs(a) * b - cn * np.abs(b) * b)[..., None] * t
              + (cp * np.abs(a) * a - cn * 2 * np.abs(b) * a)[..., None] * n)
             / length[..., None])
    dF_dd = _outer(turn, n)
    jac_a = 0.5 * (dF_dv / (2.0 * dt) - dF_dd)
    jac_b = 0.5 * (dF_dv / (2.0 * dt) + dF_dd)
    forces = np.concatenate([0.5 * force, 0.5 * force], axis=-1)
    jac = _blocks([[jac_a, jac_b], [jac_a, jac_b]])
    return forces, jac


def cylinder_drag_element(x, x_old, dt, fluid_density, drag_coeff, diameter):
    """Drag on the central cylinder, F = −½ ρ_f C_c D_c |v| v, and its Jacobian.

    Args: x, x_old (..., 2) new and old centre positions, m; dt h, s; fluid_density ρ_f, kg/m³;
        drag_coeff C_c (-); diameter D_c, m.
    Returns: force (..., 2), N/m; Jacobian (..., 2, 2) = ∂F/∂x, N/m².
    """
    v = (x - x_old) / dt
    speed = np.linalg.norm(v, axis=-1)
    c = np.asarray(0.5 * fluid_density * drag_coeff * diameter)
    force = -(c * speed)[..., None] * v
    # v vᵀ/|v| → 0 as v → 0, so a resting cylinder has a zero Jacobian rather than 0/0.
    safe = np.where(speed > 0.0, speed, 1.0)
    jac = -(c / dt)[..., None, None] * (speed[..., None, None] * np.eye(2)
                                        + _outer(v, v) / safe[..., None, None])
    return force, jac


def linear_rod_drag_element(xa, xb, xa_old, xb_old, dt, rest_length, linear_drag):
    """Linear (skin-friction) drag on one rod edge, split equally between its two nodes.

    v = mean node velocity; F = −c_l Δl̄ v; each node receives F/2.

    Args: xa, xb (..., 2) new positions, m; xa_old, xb_old (..., 2) old positions, m; dt h, s;
        rest_length Δl̄ (...), m; linear_drag c_l (...), Pa·s/m.
    Returns: forces (..., 4) on (xa, xb), N/m; Jacobian (..., 4, 4) = ∂forces/∂(xa, xb), N/m².
    """
    velocity = 0.5 * ((xa - xa_old) + (xb - xb_old)) / dt
    edge_coeff = linear_drag * np.asarray(rest_length)
    force = -edge_coeff[..., None] * velocity
    # each node's half force depends on both nodes' velocities through the mean: ½·½/h each
    block = -(edge_coeff / (4.0 * dt))[..., None, None] * np.eye(2)
    return np.concatenate([0.5 * force, 0.5 * force], axis=-1), _blocks([[block, block],
                                                                         [block, block]])


def hub_linear_drag_element(x, x_old, dt, hub_linear_drag):
    """Linear drag on the hub, F = −c_h v, and its Jacobian.

    Args: x, x_old (..., 2) new and old centre positions, m; dt h, s; hub_linear_drag c_h, Pa·s.
    Returns: force (..., 2), N/m; Jacobian (..., 2, 2) = ∂F/∂x, N/m².
    """
    velocity = (x - x_old) / dt
    jac = np.broadcast_to(-(hub_linear_drag / dt) * np.eye(2), velocity.shape + (2,))
    return -hub_linear_drag * velocity, jac


def quad_area(x1, x2, x3, x4):
    """Area ½|(x3 − x1) × (x4 − x2)| (...) of the quadrilateral x1 x2 x3 x4, m²."""
    return 0.5 * np.abs(_cross(x3 - x1, x4 - x2))


def _unit_with_derivative(v):
    """u = v/|v| (..., 2) and ∂u/∂v = (I − u uᵀ)/|v| (..., 2, 2)."""
    length = np.linalg.norm(v, axis=-1)
    u = v / length[..., None]
    return u, (np.eye(2) - _outer(u, u)) / length[..., None, None]


FIRING_SNAP = 1e-9
"""A time within this share of the period (≤) below a cycle's start is that start (rounding of
a summed step time, ~1e-16 relative; the shortest step allowed, `dt_min` 1 µs, is over 1e-6 of
any period, which is longer than the profile's heating time of ~0.16 s)."""

_QUARTER_TURN = np.array([[0.0, -1.0], [1.0, 0.0]])
"""R with R a = _perp(a)."""


def jet_direction(x1, x2, x3, x4, xc, direction):
    """Unit jet direction t (..., 2) of a space and ∂t/∂(x1, x2, x3, x4, xc) (..., 2, 10).

    "hub": from xc to ½(x2 + x3). "normal": the unit normal R₉₀·(x2 − x3)/|x2 − x3| of the
    opening (outwards while the corners run counter-clockwise around the hub; as the engine,
    whatever the hub's position). "bisector": the bisector of the limb directions (x2 − x1)/|x2 − x1| and
    (x3 − x4)/|x3 − x4| (each joint → tip).
    """
    zero = np.zeros(np.shape(x1)[:-1] + (2, 2))
    if direction == "hub":
        t, d_reach = _unit_with_derivative(0.5 * (x2 + x3) - xc)
        return t, np.concatenate([zero, 0.5 * d_reach, 0.5 * d_reach, zero, -d_reach], axis=-1)
    if direction == "normal":
        along, d_along = _unit_with_derivative(x2 - x3)
        d_x2 = _QUARTER_TURN @ d_along
        return _perp(along), np.concatenate([zero, d_x2, -d_x2, zero, zero], axis=-1)
    first, d_first = _unit_with_derivative(x2 - x1)
    second, d_second = _unit_with_derivative(x3 - x4)
    t, d_sum = _unit_with_derivative(first + second)
    d_x2 = d_sum @ d_first
    d_x3 = d_sum @ d_second
    return t, np.concatenate([-d_x2, d_x2, d_x3, -d_x3, zero], axis=-1)


def jet_element(x1, x2, x3, x4, xc, area_old, dt, fluid_density, alpha, contract_only,
                inflow=0.0, direction="hub"):
    """Jet (or inflow) force of one inter-limb space and its Jacobian.

    Ṡ = (S(x_new) − S_old)/h, L = |x2 − x3|, t = `jet_direction(..., direction)`;
    f = −(ρ_f / L) (α Ṡ)² t, switched off where Ṡ ≥ 0 if `contract_only`; there, where Ṡ > 0,
    the inflow f = +(ρ_f / L) (α_in Ṡ)² t instead (α_in = `inflow`).

    Args: x1..x4 (..., 2) new quad corners (J_k, tip_k, tip_{k+1}, J_{k+1}), m; xc (..., 2) new
        centre, m; area_old S(x_old) (...), m²; dt h, s; fluid_density ρ_f, kg/m³; alpha α (-);
        contract_only (bool, broadcasts); inflow α_in (-); direction "hub" | "normal" |
        "bisector".
    Returns: force (..., 2) of the space on the robot, N/m; Jacobian (..., 2, 10) =
        ∂f/∂(x1, x2, x3, x4, xc), N/m².
    """
    p = x3 - x1
    q = x4 - x2
    signed = _cross(p, q)
    s = np.sign(signed)
    area_rate = (0.5 * np.abs(signed) - area_old) / dt
    # ∂(p × q)/∂p = (q_y, −q_x) = −perp(q), ∂(p × q)/∂q = perp(p).
    dp = (-0.5 * s / dt)[..., None] * _perp(q)
    dq = (0.5 * s / dt)[..., None] * _perp(p)
    grad_rate = np.concatenate([-dp, -dq, dp, dq, np.zeros_like(dp)], axis=-1)

    opening = x2 - x3
    length = np.linalg.norm(opening, axis=-1)
    u = opening / length[..., None]
    zero = np.zeros_like(u)
    grad_length = np.concatenate([zero, u, -u, zero, zero], axis=-1)

    t, dt_dx = jet_direction(x1, x2, x3, x4, xc, direction)

    jetting = ~np.asarray(contract_only) | (area_rate < 0.0)
    # the signed coefficient of g·t: −ρ α² while jetting, +ρ α_in² while refilling
    c = np.where(jetting, -fluid_density * alpha ** 2,
                 np.where(area_rate > 0.0, fluid_density * inflow ** 2, 0.0))
    g = area_rate ** 2 / length
    grad_g = ((2.0 * area_rate / length)[..., None] * grad_rate
              - (area_rate ** 2 / length ** 2)[..., None] * grad_length)
    force = (c * g)[..., None] * t
    jac = c[..., None, None] * _outer(t, grad_g) + (c * g)[..., None, None] * dt_dx
    return force, jac


# --------------------------------------------------------------------------------------------
# The simulator
# --------------------------------------------------------------------------------------------

def _dofs(nodes):
    """(n_el, 2k) DOF indices of element node lists (n_el, k)."""
    return np.stack([2 * nodes, 2 * nodes + 1], axis=-1).reshape(len(nodes), -1)


def _assemble_vector(n_dof, terms):
    """Sum the element vectors of `terms` into a (n_dof,) vector.

    A term is (row_nodes (n_el, k), col_nodes (n_el, l), vectors (n_el, 2k),
    matrices (n_el, 2k, 2l) or None)."""
    return sum(np.bincount(_dofs(rows).ravel(), vectors.ravel(), n_dof)
               for rows, _, vectors, _ in terms)


def _assemble_matrix(n_dof, terms):
    """Sum the element matrices of `terms` (see _assemble_vector) into a sparse CSC matrix."""
    rows, cols, values = [], [], []
    for row_nodes, col_nodes, _, blocks in terms:
        rows.append(np.broadcast_to(_dofs(row_nodes)[:, :, None], blocks.shape).ravel())
        cols.append(np.broadcast_to(_dofs(col_nodes)[:, None, :], blocks.shape).ravel())
        values.append(blocks.ravel())
    # Duplicate (row, col) pairs add up on conversion to CSC.
    sparse = require("scipy.sparse", "test")
    return sparse.csc_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))),
                             shape=(n_dof, n_dof))


@dataclass(frozen=True)
class ImplicitStep:
    """What one implicit step to `time` knows before it is solved.

    Every rate in the step is rate_gain·(value(q_new) − anchor): node velocities (drag),
    inter-limb area rates (jet) and strain rates (damping); the inertia residual is
    inertia_gain·M·(q_new − inertia_target).
    - Implicit Euler: γ = 1/h, anchors = the values at t_k, inertia gain 1/h²,
      target q_k + h v_k.
    - BDF2: γ = 3/(2h) and the anchor of a value y is y_k + (y_k − y_{k−1})/3, so that
      γ(y − anchor) = (3/(2h))(y − y_k) − (y_k − y_{k−1})/(2h); inertia gain 9/(4h²), target
      q_k + (q_k − q_{k−1})/3 + (2h/9)(4v_k − v_{k−1}).
    """

    time: float
    """t_{k+1}, s: the natural curvatures of the step are taken here."""
    rate_gain: float
    """γ, 1/s."""
    position_anchor: np.ndarray
    """(N, 2), m."""
    area_anchor: np.ndarray
    """(8,) inter-limb areas, m²."""
    stretch_anchor: np.ndarray
    """(E,) edge strains (-); zeros when the model has no damping."""
    bend_anchor: np.ndarray
    """(T,) bending strains κ − κ⁰, 1/m; zeros when the model has no damping."""
    inertia_gain: float
    """1/s²."""
    inertia_target: np.ndarray
    """(N, 2), m."""


class ReferenceSimulator:
    """One robot advanced by implicit Euler or BDF2 with an exact-Jacobian Newton solve.

    Attributes: params, solver, topology; foam_scale, actuator_scale: the limbs' and arcs'
    heights over the hub's (1 without component heights); mass (N,) lumped mass without added
    mass, kg/m (per hub height);
    added_mass (N,) diagonal added mass, kg/m; stretch_modulus (E,) and bend_modulus (T,), Pa,
    the Young's modulus of each edge and triplet (elasticity and damping alike).
    """

    UNIMPLEMENTED_SOLVER = {"precision": "f64", "adaptive": False, "jacobian": "newton"}
    """The SolverConfig fields the reference does not implement, each with the one value it
    runs: it always runs f64, fixed steps and Newton's Jacobian, so another value would be
    compared against a run it does not make."""

    def __init__(self, params: StarParams, solver: SolverConfig = SolverConfig()):
        for name, value in self.UNIMPLEMENTED_SOLVER.items():
            if getattr(solver, name) != value:
                raise ValueError(f"the reference implements only {name} = {value!r} (it runs "
                                 f"f64, fixed steps and Newton's Jacobian), got "
                                 f"{getattr(solver, name)!r}")
        self.params = params
        self.solver = solver
        topo = build_topology(params)
        self.topology = topo
        p = params
        r0 = p.thickness

        # 2.5-D: every rod component per hub height, i.e. times its height over the hub's
        self.foam_scale, self.actuator_scale = (
            (1.0, 1.0) if p.hub_height == 0.0 else
            (p.foam_height / p.hub_height, p.actuator_height / p.hub_height))
        arc_len = self.actuator_scale * topo.lumped_length[:, 0]
        limb_len = self.foam_scale * topo.lumped_length[:, 1]
        self.mass = r0 * (p.actuator_density * arc_len + p.foam_density * limb_len)
        self.mass[0] += p.cylinder_mass_per_height
        self.added_mass = p.fluid_density * p.added_mass_coeff * r0 * (arc_len + limb_len)
        self.added_mass[0] += (p.fluid_density * p.cylinder_added_mass_coeff
                               * math.pi * p.cylinder_diameter ** 2 / 4.0)
        self._inertia = np.repeat(self.mass + self.added_mass, 2)

        self.stretch_modulus = np.where(topo.edge_kind == ARC, p.youngs_modulus, p.limb_modulus)
        self.bend_modulus = np.where(topo.triplet_kind == ARC_BEND, p.youngs_modulus,
                                     p.limb_modulus)
        if p.joint_stiffness == "series":
            # A joint triplet spans half an arc edge (E) and half a limb edge (E_limb): their
            # compliances add over its Voronoi length ½(Δl_a + Δl_l).
            joint = topo.triplet_kind == JOINT_BEND
            rest = topo.rest_positions
            a, b, c = topo.triplets[joint].T
            arc_edge = np.linalg.norm(rest[b] - rest[a], axis=1)
            limb_edge = np.linalg.norm(rest[c] - rest[b], axis=1)
            self.bend_modulus[joint] = topo.voronoi_length[joint] / (
                0.5 * arc_edge / p.youngs_modulus + 0.5 * limb_edge / p.limb_modulus)
        # k_s of each element's energy ½ k_s s²
        self._stretch_strain_stiffness = self.stretch_modulus * r0 * topo.rest_length
        self._bend_strain_stiffness = self.bend_modulus * r0 ** 3 / 12.0 * topo.voronoi_length

        mask = Gait.parse(p.gait).mask
        actuator = topo.triplet_actuator
        self._actuated = (actuator >= 0) & (mask[np.maximum(actuator, 0)] == 1)
        clamped = topo.joint_actuator
        self._shared_ends = ((clamped >= 0) & (mask[np.maximum(clamped, 0)] == 1)
                             & (p.actuation_ends == "shared"))
        self._rod_edges = np.flatnonzero(topo.edge_kind != SPOKE)

    # ---- elasticity and damping ------------------------------------------------------------

    def driven_curvature(self, t) -> np.ndarray:
        """K̄ (8,) in 1/m that the actuators A1..A8 follow, when fired, at time t (s): the
        profile with its closure at the time since the cycle's start less each actuator's delay
        (K̄(0) during the delay), its change from K̄(0) scaled by each actuator's gain (warmed by
        the heat the earlier cycles' firings left, with `stroke_warming`)."""
        p = self.params
        rest = p.actuator_profile.rest_curvature
        since_firing = math.fmod(t, p.period)
        if p.period - since_firing <= FIRING_SNAP * p.period:
            # a step's end time summed in floats (k·h + h) can land a rounding below a cycle's
            # start k·T: it is that start, whose firing the step ending there already sees
            # (the engine counts steps: `actuation.Schedule.fire_due`); fmod read the cooling
            # tail K̄(T⁻) there instead of K̄(0) (an audit, 2026-12)
            since_firing = 0.0
        warming = 1.0
        if p.stroke_warming != 0.0:
            # the heat kept from the earlier firings of this cycle's: θ_0 = 0,
            # θ_k = (θ_{k−1} + 1)·exp(−T/τ_c)
            heat = 0.0
            for _ in range(round((t - since_firing) / p.period)):
                heat = (heat + 1.0) * math.exp(-p.period / p.cooling_time)
            warming = 1.0 + p.stroke_warming * heat
        driven = np.empty(len(p.actuator_gains))
        for actuator, (gain, delay) in enumerate(zip(p.actuator_gains, p.actuator_delays)):
            tau = snapped_to_switch(max(since_firing - delay, 0.0),
                                    p.actuator_profile.switch_time, t)
            curvature = float(p.actuator_profile.cycle_curvature(tau, p.period,
                                                                 p.profile_closure))
            driven[actuator] = rest + gain * warming * (curvature - rest)
        return driven

    def natural_curvature(self, t):
        """κ⁰ (T,) in 1/m at time t (s): rest curvature, or ±K̄(t mod T) of its actuator on
        actuated triplets (with `actuation_origin` "rest": the rest curvature plus
        ±(K̄ − K̄(0))), and with "shared" ends the joints turned with the arc's end
        half-edges."""
        topo = self.topology
        kappa0 = topo.rest_curvature.copy()
        driven = self.driven_curvature(t)
        if self._actuated.any():
            actuated = self._actuated
            target = driven[topo.triplet_actuator[actuated]]
            if self.params.actuation_origin == "rest":
                change = target - self.params.actuator_profile.rest_curvature
                kappa0[actuated] = kappa0[actuated] + np.sign(kappa0[actuated]) * change
            else:
                kappa0[actuated] = np.sign(kappa0[actuated]) * target
        if self._shared_ends.any():
            ends = self._shared_ends
            voronoi = topo.voronoi_length[ends]
            angle = (2.0 * np.arctan(kappa0[ends] * voronoi / 2.0) + topo.end_turning_length[ends]
                     * (driven[topo.joint_actuator[ends]]
                        - self.params.actuator_profile.rest_curvature))
            kappa0[ends] = 2.0 * np.tan(angle / 2.0) / voronoi
        return kappa0

    def strains(self, q, t, derivatives=False):
        """Elastic strains of positions q (N, 2) m at time t (s): edge strains ε (E,) and bending
        strains δ = κ − κ⁰(t) (T,) 1/m. With derivatives, each is the (s, ∇s, ∇²s) triple of
        `stretch_strain` / `bend_strain`."""
        topo = self.topology
        q = np.asarray(q, dtype=np.float64)
        i, j = topo.edges.T
        stretch = stretch_strain(q[i], q[j], topo.rest_length)
        a, b, c = topo.triplets.T
        bend = bend_strain(q[a], q[b], q[c], topo.voronoi_length, self.natural_curvature(t))
        return (stretch, bend) if derivatives else (stretch[0], bend[0])

    def _elastic(self, q, t):
        """Total energy and the terms (gradient, Hessian) of all stretch and bend elements."""
        stretch, bend = self.strains(q, t, derivatives=True)
        es, gs, hs = quadratic_strain_element(*stretch, self._stretch_strain_stiffness)
        eb, gb, hb = quadratic_strain_element(*bend, self._bend_strain_stiffness)
        topo = self.topology
        terms = [(topo.edges, topo.edges, gs, hs), (topo.triplets, topo.triplets, gb, hb)]
        return es.sum() + eb.sum(), terms

    def _damping(self, q_new, step: ImplicitStep):
        """The terms (gradient of the pseudo-potential, Hessian) of the material damping."""
        stretch, bend = self.strains(q_new, step.time, derivatives=True)
        tau, gain = self.params.damping_time, step.rate_gain
        _, gs, hs = damping_element(*stretch, step.stretch_anchor, gain,
                                    self._stretch_strain_stiffness, tau)
        _, gb, hb = damping_element(*bend, step.bend_anchor, gain,
                                    self._bend_strain_stiffness, tau)
        topo = self.topology
        return [(topo.edges, topo.edges, gs, hs), (topo.triplets, topo.triplets, gb, hb)]

    def elastic_energy(self, q, t) -> float:
        """Total stretching + bending energy (J/m) of positions q (N, 2) m at time t (s)."""
        return float(self._elastic(np.asarray(q, dtype=np.float64), t)[0])

    def elastic_forces(self, q, t) -> np.ndarray:
        """Elastic forces −∇E (N, 2), N/m, of positions q (N, 2) m at time t (s)."""
        q = np.asarray(q, dtype=np.float64)
        return -_assemble_vector(q.size, self._elastic(q, t)[1]).reshape(q.shape)

    # ---- fluid -----------------------------------------------------------------------------

    def _fluid(self, q_new, q_old, dt, area_old=None):
        """The terms (force, Jacobian) of rod drag, cylinder drag, the eight jets and, where
        set, the linear drag of the rods and the hub for the velocities (q_new − q_old)/dt and
        area rates (S(q_new) − area_old)/dt (area_old defaults to the areas of q_old)."""
        p, topo = self.params, self.topology
        rods = topo.edges[self._rod_edges]
        a, b = rods.T
        edge_scale = np.where(topo.edge_kind[self._rod_edges] == ARC, self.actuator_scale,
                              self.foam_scale)
        f_rod, k_rod = rod_drag_element(q_new[a], q_new[b], q_old[a], q_old[b], dt,
                                        topo.rest_length[self._rod_edges],
                                        p.fluid_density * edge_scale, p.drag_parallel,
                                        p.drag_perpendicular)
        f_cyl, k_cyl = cylinder_drag_element(q_new[0], q_old[0], dt, p.fluid_density,
                                             p.cylinder_drag, p.cylinder_diameter)
        quads = topo.jet_quads
        centre = np.zeros((len(quads), 1), dtype=quads.dtype)
        f_jet, k_jet = self.space_jets(q_new, q_old, dt, area_old)
        jet_nodes = np.concatenate([quads, centre], axis=1)
        if p.jet_application == "spread":
            # a quarter of each space's force on each of its four corners
            jet_term = (quads, jet_nodes, np.tile(f_jet / 4.0, 4),
                        np.concatenate([k_jet / 4.0] * 4, axis=-2))
        else:
            jet_term = (centre, jet_nodes, f_jet, k_jet)
        terms = [(rods, rods, f_rod, k_rod),
                 (centre[:1], centre[:1], f_cyl[None], k_cyl[None]), jet_term]
        if p.linear_drag > 0.0:
            terms.append((rods, rods) + linear_rod_drag_element(
                q_new[a], q_new[b], q_old[a], q_old[b], dt, topo.rest_length[self._rod_edges],
                p.linear_drag * edge_scale))
        if p.hub_linear_drag > 0.0:
            f_hub, k_hub = hub_linear_drag_element(q_new[0], q_old[0], dt, p.hub_linear_drag)
            terms.append((centre[:1], centre[:1], f_hub[None], k_hub[None]))
        return terms

    def space_jets(self, q_new, q_old, dt, area_old=None):
        """Each inter-limb space's jet (or inflow) force on the robot (..., 8, 2), N/m, and its
        Jacobian (..., 8, 2, 10) in the space's corners and the centre, for the area rates
        (S(q_new) − area_old)/dt (area_old defaults to the areas of q_old); q_new, q_old
        (..., N, 2) m, any leading axes (a run's steps at once); space k lies between limbs k
        and k+1 and holds actuator A(k+1)."""
        p, quads = self.params, self.topology.jet_quads
        if area_old is None:
            area_old = self.areas(q_old)
        centre = q_new[..., np.zeros(len(quads), dtype=quads.dtype), :]
        return jet_element(*[q_new[..., quads[:, m], :] for m in range(4)], centre, area_old, dt,
                           p.fluid_density * self.foam_scale, p.alpha, p.jet_mode == "contract",
                           p.jet_inflow, p.jet_direction)

    def areas(self, q) -> np.ndarray:
        """Areas S (..., 8), m², of the eight inter-limb spaces (jet quadrilaterals) of q
        (..., N, 2) m."""
        q = np.asarray(q, dtype=np.float64)
        return quad_area(*[q[..., self.topology.jet_quads[:, m], :] for m in range(4)])

    def fluid_forces(self, q_new, q_old, dt) -> np.ndarray:
        """Rod drag + cylinder drag + jet (N, 2), N/m, for the step q_old -> q_new (m) of dt s."""
        q_new = np.asarray(q_new, dtype=np.float64)
        terms = self._fluid(q_new, np.asarray(q_old, dtype=np.float64), dt)
        return _assemble_vector(q_new.size, terms).reshape(q_new.shape)

    # ---- time stepping ---------------------------------------------------------------------

    def implicit_step(self, q, v, t, h, previous=None) -> ImplicitStep:
        """The known part of a step of h s from state (q, v) at time t s: implicit Euler, or
        BDF2 when `previous` = (q_prev, v_prev), the state at t − h, is given.
        Args: q, v (N, 2) in m and m/s."""
        q = np.asarray(q, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        damped = self.params.damping_time > 0.0
        topo = self.topology
        stretch, bend = (self.strains(q, t) if damped
                         else (np.zeros(topo.n_edges), np.zeros(topo.n_triplets)))
        areas = self.areas(q)
        if previous is None:
            return ImplicitStep(time=t + h, rate_gain=1.0 / h, position_anchor=q,
                                area_anchor=areas, stretch_anchor=stretch, bend_anchor=bend,
                                inertia_gain=1.0 / h ** 2, inertia_target=q + h * v)
        q_prev, v_prev = (np.asarray(x, dtype=np.float64) for x in previous)
        if damped:
            stretch_prev, bend_prev = self.strains(q_prev, t - h)
            stretch = stretch + (stretch - stretch_prev) / 3.0
            bend = bend + (bend - bend_prev) / 3.0
        step_back = q - q_prev
        return ImplicitStep(
            time=t + h, rate_gain=1.5 / h, position_anchor=q + step_back / 3.0,
            area_anchor=areas + (areas - self.areas(q_prev)) / 3.0,
            stretch_anchor=stretch, bend_anchor=bend, inertia_gain=9.0 / (4.0 * h ** 2),
            inertia_target=q + step_back / 3.0 + (2.0 * h / 9.0) * (4.0 * v - v_prev))

    def _step_forces(self, q_new, step: ImplicitStep):
        """Total force (2N,) and its sparse Jacobian (2N, 2N) at q_new (N, 2) for `step`."""
        elastic = self._elastic(q_new, step.time)[1]
        if self.params.damping_time > 0.0:
            elastic += self._damping(q_new, step)
        terms = [(r, c, -g, -h) for r, c, g, h in elastic] + self._fluid(
            q_new, step.position_anchor, 1.0 / step.rate_gain, step.area_anchor)
        return _assemble_vector(q_new.size, terms), _assemble_matrix(q_new.size, terms)

    def force_jacobian(self, q_new, q_old, t_new, dt, q_older=None):
        """Total force F = F_int(q_new; t_new) + F_damping + F_fluid and ∂F/∂q_new, with the rates
        of implicit Euler from q_old at t_new − dt, or of BDF2 from q_old and q_older (at
        t_new − 2 dt) when q_older is given. Positions (N, 2), m; times s.

        Returns: forces (N, 2), N/m; dense Jacobian (2N, 2N), N/m² (DOF order of
        q.reshape(-1)).
        """
        q_new = np.asarray(q_new, dtype=np.float64)
        q_old = np.asarray(q_old, dtype=np.float64)
        previous = None if q_older is None else (q_older, np.zeros_like(q_old))
        step = self.implicit_step(q_old, np.zeros_like(q_old), t_new - dt, dt, previous)
        force, jac = self._step_forces(q_new, step)
        return force.reshape(q_new.shape), jac.toarray()

    def step(self, q, v, t, dt=None, previous=None, water=None):
        """One implicit step from time t to t + dt (default solver.dt): BDF2 when the solver's
        integrator is "bdf2" and `previous` = (q_prev, v_prev), the state at t − dt, is given;
        implicit Euler otherwise.

        With the entrained water (`wake_coupling` > 0), `water` = (u, u_prev) is its velocity
        (2,) m/s at t and at t − dt (u_prev is read only for BDF2), and the step solves for the
        water's velocity at t + dt with the positions: two more unknowns u', with the residual
        m_w·γ·(u' − anchor) − c_w·(v_hub − u') = 0 (m_w = c_w·τ_w; the anchor as for any rate,
        `ImplicitStep`) beside the nodes', on which the hub's force c_w·(u' − v_hub) acts. It
        then returns u' as a fourth value.

        Solves inertia_gain·M·(q_new − inertia_target) − F(q_new) = 0 (see `ImplicitStep`) with
        M = mass + added mass, starting Newton from q + dt·v, or from q + dt·(2v − v_prev) when
        `previous` is given (with either integrator). Args: q (N, 2) m, v (N, 2) m/s,
        t s. Returns: (q_new (N, 2), v_new (N, 2) the integrator's velocity at q_new, Newton
        iterations).
        Converged when an update max|Δq| is <= newton_tol and the residual before that update
        has max|r| <= residual_tol (when it is set), as the engine's rule. Raises
        NewtonDidNotConverge if not after max_newton iterations, or if a non-finite value
        appears, from the plain start q + dt·v: a step from the carried start that fails is
        solved again from there as an implicit Euler step, as the engine redoes it (the
        carried acceleration is a poor start where the forcing jumps) before its substeps,
        which this reference does not take.
        """
        try:
            return self._solve(q, v, t, dt, previous, water)
        except NewtonDidNotConverge:
            if previous is None:
                raise
            return self._solve(q, v, t, dt, None, water)

    def _solve(self, q, v, t, dt, previous, water):
        """`step`'s one solve: Newton from q + dt·v, or from q + dt·(2v − v_prev) when
        `previous` is given (BDF2 then if the solver's integrator is)."""
        h = self.solver.dt if dt is None else dt
        q = np.asarray(q, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        bdf2 = self.solver.integrator == "bdf2" and previous is not None
        step = self.implicit_step(q, v, t, h, previous if bdf2 else None)
        inertia = step.inertia_gain * self._inertia
        target = step.inertia_target.reshape(-1)
        # Newton's start: the last step's acceleration carried on when there is one
        start = q + h * v if previous is None else q + h * (2.0 * v - np.asarray(previous[1]))
        q_new = start.reshape(-1)
        wake = self._water_system(step, water, bdf2)
        if wake is not None:
            q_new = np.concatenate([q_new, np.asarray(water[0], dtype=np.float64)])
        sparse_lu = require("scipy.sparse.linalg", "test").splu
        sparse = require("scipy.sparse", "test")
        for iteration in range(1, self.solver.max_newton + 1):
            force, jac = self._step_forces(q_new[:q.size].reshape(q.shape), step)
            residual = inertia * (q_new[:q.size] - target) - force
            # Sparse LU (SuperLU) rather than a dense solve: it is fast, and it does not use the
            # threaded BLAS, whose threads thrash when other processes share the cores.
            system = (sparse.diags(inertia) - jac).tocsc()
            if wake is not None:
                residual, system = wake(q_new, residual, system)
            delta = -sparse_lu(system).solve(residual)
            q_new += delta
            change = np.abs(delta).max()
            if not np.isfinite(change):
                raise NewtonDidNotConverge(f"non-finite Newton update at t = {t + h:.6g} s")
            if change <= self.solver.newton_tol \
                    and np.abs(residual).max() <= self.solver.residual_limit:
                positions = q_new[:q.size].reshape(q.shape)
                solved = (positions, step.rate_gain * (positions - step.position_anchor), iteration)
                return solved if wake is None else solved + (q_new[q.size:].copy(),)
        raise NewtonDidNotConverge(
            f"step to t = {t + h:.6g} s: max|Δq| = {change:.3g} m (newton_tol "
            f"{self.solver.newton_tol:.3g} m), max|r| = {np.abs(residual).max():.3g} N "
            f"(residual_tol {self.solver.residual_tol} N) after {self.solver.max_newton} "
            f"iterations")

    def _water_system(self, step: ImplicitStep, water, bdf2: bool):
        """None without the entrained water; else a function that adds the water's two
        unknowns (after the 2N of the nodes) to a Newton iteration's residual (2N,) and
        matrix (2N, 2N) at the unknowns z (2N + 2,) and returns them extended."""
        p = self.params
        if p.wake_coupling == 0.0:
            return None
        if water is None:
            raise ValueError("a step with wake_coupling > 0 needs water = (u, u_prev)")
        sparse = require("scipy.sparse", "test")
        u, u_prev = (np.asarray(w, dtype=np.float64) for w in water)
        anchor = u + (u - u_prev) / 3.0 if bdf2 else u
        gain, coupling = step.rate_gain, p.wake_coupling
        water_mass = coupling * p.wake_time
        hub_anchor = step.position_anchor[0]
        n = 2 * self.topology.n_nodes
        # the water's blocks are linear, the same at every iterate: the hub's own (its force's
        # ∂/∂x_hub = −c_w·γ), the hub by the water, the water by the hub, the water's own
        hub_rows = ([0, 1], [0, 1])
        hub_block = sparse.csc_matrix((np.full(2, coupling * gain), hub_rows), shape=(n, n))
        hub_by_water = sparse.csc_matrix((np.full(2, -coupling), hub_rows), shape=(n, 2))
        water_by_hub = sparse.csc_matrix((np.full(2, -coupling * gain), hub_rows), shape=(2, n))
        water_block = (water_mass * gain + coupling) * sparse.identity(2, format="csc")

        def extend(z, residual, system):
            hub_velocity = gain * (z[:2] - hub_anchor)
            water_velocity = z[n:]
            hub = residual.copy()
            hub[:2] -= coupling * (water_velocity - hub_velocity)
            water_residual = (water_mass * gain * (water_velocity - anchor)
                              - coupling * (hub_velocity - water_velocity))
            system = sparse.bmat([[system + hub_block, hub_by_water],
                                  [water_by_hub, water_block]]).tocsc()
            return np.concatenate([hub, water_residual]), system

        return extend

    def run(self, n_steps, q0=None, v0=None, return_velocities=False):
        """Positions (n_steps + 1, N, 2), m, at t = 0, h, ..., n_steps·h (h = solver.dt), from
        (q0, v0) (default: at rest in the rest shape) at t = 0; BDF2 steps after a first implicit
        Euler step when the solver's integrator is "bdf2". With return_velocities, also the
        velocities (n_steps + 1, N, 2), m/s."""
        h = self.solver.dt
        q = self.topology.rest_positions.copy() if q0 is None else np.array(q0, dtype=np.float64)
        v = np.zeros_like(q) if v0 is None else np.array(v0, dtype=np.float64)
        positions = np.empty((n_steps + 1,) + q.shape)
        velocities = np.empty_like(positions)
        positions[0], velocities[0] = q, v
        previous = None
        # the entrained water (if any) starts at rest
        water = (np.zeros(2), np.zeros(2)) if self.params.wake_coupling > 0.0 else None
        for k in range(n_steps):
            solved = self.step(q, v, k * h, h, previous, water)
            if water is not None:
                water = (solved[3], water[0])
            previous, q, v = (q, v), solved[0], solved[1]
            positions[k + 1], velocities[k + 1] = q, v
        return (positions, velocities) if return_velocities else positions

    def centroid(self, q) -> np.ndarray:
        """Mass-weighted mean (2,) of positions q (N, 2), m; added mass excluded."""
        return self.mass @ np.asarray(q, dtype=np.float64) / self.mass.sum()
