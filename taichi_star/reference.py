"""Single-instance NumPy reference implementation of the model of design §2, for tests.

It is written independently of the Taichi batch engine, from the specification alone, so that
the two can check each other. Everything is double precision; each Newton iteration assembles
the exact Jacobian of all forces as a scipy.sparse matrix and factors it with SuperLU (N = 193
nodes, 386 degrees of freedom: ~3 ms per iteration).

Units are SI, per unit out-of-plane height H = 1 m: positions in m, forces in N/m, energies in
J/m, masses in kg/m. A configuration `q` is an (N, 2) array; its flat degree-of-freedom vector is
`q.reshape(-1)`, so node i owns DOFs 2i (x) and 2i + 1 (y).

The element functions below are pure and vectorised: every position argument has shape (..., 2)
and every scalar argument broadcasts against the leading axes `...`, so a single call evaluates
one element (shape (2,)) for the tests or all elements of a kind at once for the assembly.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from .gait import Gait
from .geometry import ARC, ARC_BEND, SPOKE, build_topology
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
# Elastic elements (design §2.2)
# --------------------------------------------------------------------------------------------

def stretch_element(xi, xj, rest_length, stiffness):
    """Stretching energy of one edge and its derivatives.

    E = ½ k ε² Δl̄ with ε = |xj − xi| / Δl̄ − 1.

    Args: xi, xj (..., 2) end positions, m; rest_length Δl̄ (...), m; stiffness k = E·r0 (...), N/m.
    Returns: energy (...) J/m; gradient (..., 4) over (xi, xj), N/m; Hessian (..., 4, 4), N/m².
    """
    rest_length, stiffness = np.asarray(rest_length), np.asarray(stiffness)
    d = xj - xi
    length = np.linalg.norm(d, axis=-1)
    strain = length / rest_length - 1.0
    energy = 0.5 * stiffness * strain ** 2 * rest_length
    u = d / length[..., None]
    g = (stiffness * strain)[..., None] * u
    uu = _outer(u, u)
    h = ((stiffness / rest_length)[..., None, None] * uu
         + (stiffness * strain / length)[..., None, None] * (np.eye(2) - uu))
    grad = np.concatenate([-g, g], axis=-1)
    hess = _blocks([[h, -h], [-h, h]])
    return energy, grad, hess


def _angle_hessian(e):
    """Hessian (..., 2, 2) of the direction angle atan2(e_y, e_x) with respect to e."""
    x, y = e[..., 0], e[..., 1]
    r4 = (x * x + y * y) ** 2
    off = (y * y - x * x) / r4
    return np.stack([np.stack([2 * x * y / r4, off], -1),
                     np.stack([off, -2 * x * y / r4], -1)], -2)


def bend_element(xi, xj, xk, voronoi_length, natural_curvature, bending_stiffness):
    """Bending energy of one triplet (angle at xj) and its derivatives.

    κ = 2 (e1 × e2) / ((|e1||e2| + e1·e2) Δl) = 2 tan(φ/2) / Δl, e1 = xj − xi, e2 = xk − xj,
    φ the signed turning angle; E = ½ B (κ − κ⁰)² Δl.

    Args: xi, xj, xk (..., 2), m; voronoi_length Δl (...), m; natural_curvature κ⁰ (...), 1/m;
        bending_stiffness B = E·r0³/12 (...), N·m.
    Returns: energy (...) J/m; gradient (..., 6) over (xi, xj, xk), N/m;
        Hessian (..., 6, 6), N/m².
    """
    voronoi_length = np.asarray(voronoi_length)
    bending_stiffness = np.asarray(bending_stiffness)
    e1 = xj - xi
    e2 = xk - xj
    n1 = _dot(e1, e1)
    n2 = _dot(e2, e2)
    # tan(φ/2) from the cross and dot products: the same expression as the spec's κ, and it
    # needs no atan2; the derivatives go through φ = angle(e2) − angle(e1).
    half_tan = _cross(e1, e2) / (np.sqrt(n1 * n2) + _dot(e1, e2))
    curvature = 2.0 * half_tan / voronoi_length
    dk = (1.0 + half_tan ** 2) / voronoi_length
    ddk = half_tan * (1.0 + half_tan ** 2) / voronoi_length
    excess = curvature - natural_curvature
    energy = 0.5 * bending_stiffness * excess ** 2 * voronoi_length

    g1 = -_perp(e1) / n1[..., None]
    g2 = _perp(e2) / n2[..., None]
    grad_phi = np.concatenate([-g1, g1 - g2, g2], axis=-1)
    h1 = -_angle_hessian(e1)
    h2 = _angle_hessian(e2)
    hess_phi = _blocks([[h1, -h1, 0], [-h1, h1 + h2, -h2], [0, -h2, h2]])

    scale = bending_stiffness * voronoi_length
    grad = (scale * excess * dk)[..., None] * grad_phi
    gg = _outer(grad_phi, grad_phi)
    hess = (scale[..., None, None] * ((dk ** 2 + excess * ddk)[..., None, None] * gg
                                      + (excess * dk)[..., None, None] * hess_phi))
    return energy, grad, hess


# --------------------------------------------------------------------------------------------
# Fluid elements (design §2.5); velocities are implicit, v = (x_new − x_old) / h
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


def quad_area(x1, x2, x3, x4):
    """Area ½|(x3 − x1) × (x4 − x2)| (...) of the quadrilateral x1 x2 x3 x4, m²."""
    return 0.5 * np.abs(_cross(x3 - x1, x4 - x2))


def jet_element(x1, x2, x3, x4, xc, area_old, dt, fluid_density, alpha, contract_only):
    """Jet force of one inter-limb space, applied at the centre, and its Jacobian.

    Ṡ = (S(x_new) − S_old)/h, L = |x2 − x3|, t = unit vector from xc to ½(x2 + x3);
    f = −(ρ_f / L) (α Ṡ)² t, switched off where Ṡ ≥ 0 if `contract_only`.

    Args: x1..x4 (..., 2) new quad corners (J_k, tip_k, tip_{k+1}, J_{k+1}), m; xc (..., 2) new
        centre, m; area_old S(x_old) (...), m²; dt h, s; fluid_density ρ_f, kg/m³; alpha α (-);
        contract_only (bool, broadcasts).
    Returns: force (..., 2) on the centre, N/m; Jacobian (..., 2, 10) = ∂f/∂(x1, x2, x3, x4, xc),
        N/m².
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

    r = 0.5 * (x2 + x3) - xc
    r_norm = np.linalg.norm(r, axis=-1)
    t = r / r_norm[..., None]
    dt_dr = (np.eye(2) - _outer(t, t)) / r_norm[..., None, None]
    dt_dx = np.concatenate([np.zeros_like(dt_dr), 0.5 * dt_dr, 0.5 * dt_dr,
                            np.zeros_like(dt_dr), -dt_dr], axis=-1)

    on = np.where(np.asarray(contract_only) & (area_rate >= 0.0), 0.0, 1.0)
    c = on * fluid_density * alpha ** 2
    g = area_rate ** 2 / length
    grad_g = ((2.0 * area_rate / length)[..., None] * grad_rate
              - (area_rate ** 2 / length ** 2)[..., None] * grad_length)
    force = -(c * g)[..., None] * t
    jac = -(c[..., None, None] * _outer(t, grad_g) + (c * g)[..., None, None] * dt_dx)
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
    return scipy.sparse.csc_matrix((np.concatenate(values),
                                    (np.concatenate(rows), np.concatenate(cols))),
                                   shape=(n_dof, n_dof))


class ReferenceSimulator:
    """One robot advanced by implicit Euler with an exact-Jacobian Newton solve (design §2.6).

    Attributes: params, solver, topology; mass (N,) lumped mass without added mass, kg/m;
    added_mass (N,) diagonal added mass, kg/m.
    """

    def __init__(self, params: StarParams, solver: SolverConfig = SolverConfig()):
        self.params = params
        self.solver = solver
        topo = build_topology(params)
        self.topology = topo
        p = params
        r0 = p.thickness

        arc_len, limb_len = topo.lumped_length[:, 0], topo.lumped_length[:, 1]
        self.mass = r0 * (p.actuator_density * arc_len + p.foam_density * limb_len)
        self.mass[0] += p.cylinder_mass_per_height
        self.added_mass = p.fluid_density * p.added_mass_coeff * r0 * (arc_len + limb_len)
        self.added_mass[0] += (p.fluid_density * p.cylinder_added_mass_coeff
                               * math.pi * p.cylinder_diameter ** 2 / 4.0)
        self._inertia = np.repeat(self.mass + self.added_mass, 2)

        modulus = np.where(topo.edge_kind == ARC, p.youngs_modulus, p.limb_modulus)
        self._stretch_stiffness = modulus * r0
        bend_modulus = np.where(topo.triplet_kind == ARC_BEND, p.youngs_modulus, p.limb_modulus)
        self._bend_stiffness = bend_modulus * r0 ** 3 / 12.0
        mask = Gait.parse(p.gait).mask
        actuator = topo.triplet_actuator
        self._actuated = (actuator >= 0) & (mask[np.maximum(actuator, 0)] == 1)
        clamped = topo.joint_actuator
        self._shared_ends = ((clamped >= 0) & (mask[np.maximum(clamped, 0)] == 1)
                             & (p.actuation_ends == "shared"))
        self._rod_edges = np.flatnonzero(topo.edge_kind != SPOKE)

    # ---- elasticity ------------------------------------------------------------------------

    def natural_curvature(self, t):
        """κ⁰ (T,) in 1/m at time t (s): rest curvature, or ±K̄(t mod T) on actuated triplets."""
        topo = self.topology
        kappa0 = topo.rest_curvature.copy()
        driven = self.params.actuator_profile.curvature(math.fmod(t, self.params.period))
        if self._actuated.any():
            kappa0[self._actuated] = np.sign(kappa0[self._actuated]) * driven
        if self._shared_ends.any():
            # "shared" ends: the joint's natural turning angle follows the arc's end half-edge
            ends = self._shared_ends
            voronoi = topo.voronoi_length[ends]
            angle = (2.0 * np.arctan(kappa0[ends] * voronoi / 2.0) + topo.end_turning_length[ends]
                     * (driven - self.params.actuator_profile.rest_curvature))
            kappa0[ends] = 2.0 * np.tan(angle / 2.0) / voronoi
        return kappa0

    def _elastic(self, q, t):
        """Total energy and the terms (gradient, Hessian) of all stretch and bend elements."""
        topo = self.topology
        i, j = topo.edges.T
        es, gs, hs = stretch_element(q[i], q[j], topo.rest_length, self._stretch_stiffness)
        a, b, c = topo.triplets.T
        eb, gb, hb = bend_element(q[a], q[b], q[c], topo.voronoi_length,
                                  self.natural_curvature(t), self._bend_stiffness)
        terms = [(topo.edges, topo.edges, gs, hs), (topo.triplets, topo.triplets, gb, hb)]
        return es.sum() + eb.sum(), terms

    def elastic_energy(self, q, t) -> float:
        """Total stretching + bending energy (J/m) of positions q (N, 2) m at time t (s)."""
        return float(self._elastic(np.asarray(q, dtype=np.float64), t)[0])

    def elastic_forces(self, q, t) -> np.ndarray:
        """Elastic forces −∇E (N, 2), N/m, of positions q (N, 2) m at time t (s)."""
        q = np.asarray(q, dtype=np.float64)
        return -_assemble_vector(q.size, self._elastic(q, t)[1]).reshape(q.shape)

    # ---- fluid -----------------------------------------------------------------------------

    def _fluid(self, q_new, q_old, dt):
        """The terms (force, Jacobian) of rod drag, cylinder drag and the eight jets."""
        p, topo = self.params, self.topology
        rods = topo.edges[self._rod_edges]
        a, b = rods.T
        f_rod, k_rod = rod_drag_element(q_new[a], q_new[b], q_old[a], q_old[b], dt,
                                        topo.rest_length[self._rod_edges], p.fluid_density,
                                        p.drag_parallel, p.drag_perpendicular)
        f_cyl, k_cyl = cylinder_drag_element(q_new[0], q_old[0], dt, p.fluid_density,
                                             p.cylinder_drag, p.cylinder_diameter)
        quads = topo.jet_quads
        centre = np.zeros((len(quads), 1), dtype=quads.dtype)
        area_old = quad_area(*[q_old[quads[:, m]] for m in range(4)])
        f_jet, k_jet = jet_element(*[q_new[quads[:, m]] for m in range(4)], q_new[centre[:, 0]],
                                   area_old, dt, p.fluid_density, p.alpha,
                                   p.jet_mode == "contract")
        return [(rods, rods, f_rod, k_rod),
                (centre[:1], centre[:1], f_cyl[None], k_cyl[None]),
                (centre, np.concatenate([quads, centre], axis=1), f_jet, k_jet)]

    def fluid_forces(self, q_new, q_old, dt) -> np.ndarray:
        """Rod drag + cylinder drag + jet (N, 2), N/m, for the step q_old -> q_new (m) of dt s."""
        q_new = np.asarray(q_new, dtype=np.float64)
        terms = self._fluid(q_new, np.asarray(q_old, dtype=np.float64), dt)
        return _assemble_vector(q_new.size, terms).reshape(q_new.shape)

    # ---- time stepping ---------------------------------------------------------------------

    def _force_jacobian(self, q_new, q_old, t_new, dt):
        elastic = [(r, c, -g, -h) for r, c, g, h in self._elastic(q_new, t_new)[1]]
        terms = elastic + self._fluid(q_new, q_old, dt)
        return _assemble_vector(q_new.size, terms), _assemble_matrix(q_new.size, terms)

    def force_jacobian(self, q_new, q_old, t_new, dt):
        """Total force F = F_int(q_new; t_new) + F_fluid(q_new, q_old) and ∂F/∂q_new.

        Returns: forces (N, 2), N/m; dense Jacobian (2N, 2N), N/m² (DOF order of
        q.reshape(-1)).
        """
        q_new = np.asarray(q_new, dtype=np.float64)
        force, jac = self._force_jacobian(q_new, np.asarray(q_old, dtype=np.float64), t_new, dt)
        return force.reshape(q_new.shape), jac.toarray()

    def step(self, q, v, t, dt=None):
        """One implicit Euler step from time t to t + dt (default solver.dt).

        Solves M (q_new − q − h v)/h² − F(q_new) = 0 with M = mass + added mass, starting
        Newton from q + h v. Args: q (N, 2) m, v (N, 2) m/s, t s.
        Returns: (q_new (N, 2), v_new (N, 2), Newton iterations).
        Raises NewtonDidNotConverge if max|Δq| > newton_tol after max_newton iterations, or if a
        non-finite value appears.
        """
        h = self.solver.dt if dt is None else dt
        q = np.asarray(q, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        inertia = self._inertia / h ** 2
        target = (q + h * v).reshape(-1)
        q_new = target.copy()
        for iteration in range(1, self.solver.max_newton + 1):
            force, jac = self._force_jacobian(q_new.reshape(q.shape), q, t + h, h)
            residual = inertia * (q_new - target) - force
            # Sparse LU (SuperLU) rather than a dense solve: it is fast, and it does not use the
            # threaded BLAS, whose threads thrash when other processes share the cores.
            system = (scipy.sparse.diags(inertia) - jac).tocsc()
            delta = -scipy.sparse.linalg.splu(system).solve(residual)
            q_new += delta
            change = np.abs(delta).max()
            if not np.isfinite(change):
                raise NewtonDidNotConverge(f"non-finite Newton update at t = {t + h:.6g} s")
            if change <= self.solver.newton_tol:
                q_new = q_new.reshape(q.shape)
                return q_new, (q_new - q) / h, iteration
        raise NewtonDidNotConverge(
            f"step to t = {t + h:.6g} s: max|Δq| = {change:.3g} m > newton_tol = "
            f"{self.solver.newton_tol:.3g} m after {self.solver.max_newton} iterations")

    def run(self, n_steps) -> np.ndarray:
        """Positions (n_steps + 1, N, 2), m, from rest in the rest shape at t = 0."""
        h = self.solver.dt
        q = self.topology.rest_positions.copy()
        v = np.zeros_like(q)
        out = np.empty((n_steps + 1,) + q.shape)
        out[0] = q
        for k in range(n_steps):
            q, v, _ = self.step(q, v, k * h, h)
            out[k + 1] = q
        return out

    def centroid(self, q) -> np.ndarray:
        """Mass-weighted mean (2,) of positions q (N, 2), m; added mass excluded."""
        return self.mass @ np.asarray(q, dtype=np.float64) / self.mass.sum()
