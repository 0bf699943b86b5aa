"""Tests of the NumPy reference implementation (taichi_star/reference.py).

Finite-difference tolerances, once for all checks below: a central difference with step δ on a
function whose features have length scale ℓ has truncation error ~(δ/ℓ)² and round-off error
~ε_mach·ℓ/δ relative to the derivative. The element checks use δ = 1e-6·ℓ, with ℓ the smallest
length the element depends on (an edge, or the displacement x_new − x_old that sets a velocity),
so both errors are ~1e-10 relative (the assembled check explains its own δ); the checks allow
1e-6 relative to the largest entry, orders of magnitude above that, while a missing or wrong
term gives an O(1) error. The perturbed coordinate's actual
step (x + δ) − (x − δ) is used, so the rounding of x + δ does not enter.
"""

import math

import numpy as np
import pytest

from taichi_star.actuation import CurvatureProfile
from taichi_star.geometry import ARC_BEND, discrete_curvature
from taichi_star.params import SolverConfig, StarParams
from taichi_star.reference import (NewtonDidNotConverge, ReferenceSimulator, bend_element,
                                   cylinder_drag_element, jet_element, quad_area,
                                   rod_drag_element, stretch_element)

FD_RTOL = 1e-6

FLUID_OFF = dict(alpha=0.0, added_mass_coeff=0.0, drag_parallel=0.0, drag_perpendicular=0.0,
                 cylinder_drag=0.0)


def central_jacobian(func, x, step):
    """∂func/∂x by central differences: func maps (..., n) to (..., m); returns (..., m, n).

    Elements along the leading axes are independent, so each coordinate is perturbed in all of
    them at once."""
    columns = []
    for m in range(x.shape[-1]):
        xp, xm = x.copy(), x.copy()
        xp[..., m] += step
        xm[..., m] -= step
        actual = (xp[..., m] - xm[..., m])[..., None]
        columns.append((func(xp) - func(xm)) / actual)
    return np.stack(columns, axis=-1)


def assert_close_to_scale(actual, expected, rtol=FD_RTOL):
    scale = np.abs(expected).max()
    assert scale > 0
    assert np.abs(actual - expected).max() <= rtol * scale, (
        np.abs(actual - expected).max() / scale)


# ---- elastic elements ------------------------------------------------------------------------

def test_stretch_element_gradient_and_hessian():
    rng = np.random.default_rng(1)
    n = 20
    xi = rng.uniform(-1e-3, 1e-3, (n, 2))
    direction = rng.normal(size=(n, 2))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    xj = xi + rng.uniform(0.7e-3, 1.3e-3, n)[:, None] * direction
    rest = rng.uniform(0.8e-3, 1.2e-3, n)
    stiffness = rng.uniform(1e4, 2e6, n)
    x = np.concatenate([xi, xj], axis=1)

    def energy(y):
        return stretch_element(y[:, :2], y[:, 2:], rest, stiffness)[0][:, None]

    def gradient(y):
        return stretch_element(y[:, :2], y[:, 2:], rest, stiffness)[1]

    _, grad, hess = stretch_element(xi, xj, rest, stiffness)
    step = 1e-6 * 0.7e-3
    assert_close_to_scale(grad, central_jacobian(energy, x, step)[:, 0, :])
    assert_close_to_scale(hess, central_jacobian(gradient, x, step))
    assert np.allclose(hess, np.swapaxes(hess, -1, -2), rtol=0, atol=1e-12 * np.abs(hess).max())


def test_bend_element_gradient_and_hessian():
    rng = np.random.default_rng(2)
    n = 30
    xj = rng.uniform(-1e-3, 1e-3, (n, 2))
    heading = rng.uniform(-math.pi, math.pi, n)
    turn = rng.uniform(-1.2, 1.2, n)  # turning angles up to ~70°, well inside (−π, π)
    l1 = rng.uniform(0.6e-3, 1.4e-3, n)
    l2 = rng.uniform(0.6e-3, 1.4e-3, n)
    xi = xj - l1[:, None] * np.stack([np.cos(heading), np.sin(heading)], 1)
    xk = xj + l2[:, None] * np.stack([np.cos(heading + turn), np.sin(heading + turn)], 1)
    voronoi = rng.uniform(0.8e-3, 1.2e-3, n)
    kappa0 = rng.uniform(-150.0, 150.0, n)
    stiffness = rng.uniform(0.01, 2.0, n)
    x = np.concatenate([xi, xj, xk], axis=1)

    def element(y):
        return bend_element(y[:, :2], y[:, 2:4], y[:, 4:], voronoi, kappa0, stiffness)

    energy, grad, hess = element(x)
    # The element's curvature is the spec's formula (shared with the rest shape's construction).
    kappa = discrete_curvature(xi, xj, xk, voronoi)
    assert np.allclose(energy, 0.5 * stiffness * (kappa - kappa0) ** 2 * voronoi, rtol=1e-12)
    step = 1e-6 * 0.6e-3
    assert_close_to_scale(grad, central_jacobian(lambda y: element(y)[0][:, None], x, step)[:, 0])
    assert_close_to_scale(hess, central_jacobian(lambda y: element(y)[1], x, step))


# ---- fluid elements --------------------------------------------------------------------------

def test_rod_drag_element_jacobian():
    rng = np.random.default_rng(3)
    n = 20
    xa = rng.uniform(-1e-3, 1e-3, (n, 2))
    xb = xa + rng.uniform(-1e-3, 1e-3, (n, 2)) + np.array([1.5e-3, 0.0])
    # Node displacements of ~1e-4 m over 1 ms: velocities ~0.1 m/s, with both a and b nonzero.
    xa_old = xa - rng.uniform(-1e-4, 1e-4, (n, 2))
    xb_old = xb - rng.uniform(-1e-4, 1e-4, (n, 2))
    dt, rest = 1e-3, rng.uniform(0.8e-3, 1.2e-3, n)
    x = np.concatenate([xa, xb], axis=1)

    def element(y):
        return rod_drag_element(y[:, :2], y[:, 2:], xa_old, xb_old, dt, rest, 1000.0, 0.01, 1.0)

    forces, jac = element(x)
    step = 1e-6 * 1e-5  # smallest velocity-setting displacement is ~1e-5 m
    assert_close_to_scale(jac, central_jacobian(lambda y: element(y)[0], x, step))

    # The formula itself, on one edge: tangent/normal split of the mean velocity.
    t = (xb[0] - xa[0]) / np.linalg.norm(xb[0] - xa[0])
    nrm = np.array([-t[1], t[0]])
    v = 0.5 * ((xa[0] - xa_old[0]) + (xb[0] - xb_old[0])) / dt
    a, b = v @ t, v @ nrm
    expected = -0.5 * 1000.0 * rest[0] * (0.01 * abs(a) * a * t + 1.0 * abs(b) * b * nrm)
    assert np.allclose(forces[0, :2], 0.5 * expected, rtol=1e-12)
    assert np.allclose(forces[0, 2:], 0.5 * expected, rtol=1e-12)
    # Drag dissipates: the power of the two node forces is negative.
    power = (forces[:, :2] * (xa - xa_old) + forces[:, 2:] * (xb - xb_old)).sum(1) / dt
    assert np.all(power < 0)


def test_cylinder_drag_element_jacobian():
    rng = np.random.default_rng(4)
    x = rng.uniform(-1e-3, 1e-3, (10, 2))
    x_old = x - rng.uniform(-1e-4, 1e-4, (10, 2))
    dt = 1e-3

    def element(y):
        return cylinder_drag_element(y, x_old, dt, 1000.0, 10.0, 0.03)

    force, jac = element(x)
    assert_close_to_scale(jac, central_jacobian(lambda y: element(y)[0], x, 1e-6 * 1e-5))
    v = (x - x_old) / dt
    assert np.allclose(force, -0.5 * 1000 * 10 * 0.03 * np.linalg.norm(v, axis=1)[:, None] * v,
                       rtol=1e-12)
    # At rest the force and its Jacobian vanish (the limit of v vᵀ/|v|), not NaN.
    f0, j0 = cylinder_drag_element(x[0], x[0], dt, 1000.0, 10.0, 0.03)
    assert np.all(f0 == 0) and np.all(j0 == 0)


def _jet_configuration(shrink):
    """A jet quad of the rest shape, randomly perturbed, whose old shape is scaled by `shrink`
    about the centre (shrink > 1: the space was larger, so it is contracting)."""
    rng = np.random.default_rng(5)
    topo = ReferenceSimulator(StarParams()).topology
    corners = topo.rest_positions[topo.jet_quads[2]] + rng.uniform(-1e-3, 1e-3, (4, 2))
    centre = rng.uniform(-1e-3, 1e-3, 2)
    old = centre + shrink * (corners - centre) + rng.uniform(-1e-4, 1e-4, (4, 2))
    return np.concatenate([corners.reshape(-1), centre]), quad_area(*old)


@pytest.mark.parametrize("contract_only", [True, False])
def test_jet_element_jacobian_while_contracting(contract_only):
    x, area_old = _jet_configuration(shrink=1.05)
    dt = 1e-3

    def element(y):
        return jet_element(y[0:2], y[2:4], y[4:6], y[6:8], y[8:10], area_old, dt, 1000.0, 0.8,
                           contract_only)

    force, jac = element(x)
    area_rate = (quad_area(x[0:2], x[2:4], x[4:6], x[6:8]) - area_old) / dt
    assert area_rate < 0
    opening = np.linalg.norm(x[2:4] - x[4:6])
    direction = 0.5 * (x[2:4] + x[4:6]) - x[8:10]
    direction /= np.linalg.norm(direction)
    assert np.allclose(force, -(1000.0 / opening) * (0.8 * area_rate) ** 2 * direction,
                       rtol=1e-12)
    # The area changes by ~5e-5 m² against corner derivatives of ~3e-2 m, so ℓ ~ 1e-3 m.
    assert_close_to_scale(jac, central_jacobian(lambda y: element(y)[0], x, 1e-6 * 1e-3))


def test_jet_is_off_while_expanding_only_in_contract_mode():
    x, area_old = _jet_configuration(shrink=0.95)
    corners = [x[0:2], x[2:4], x[4:6], x[6:8]]
    assert quad_area(*corners) > area_old
    f_contract, j_contract = jet_element(*corners, x[8:10], area_old, 1e-3, 1000.0, 0.8, True)
    f_always, j_always = jet_element(*corners, x[8:10], area_old, 1e-3, 1000.0, 0.8, False)
    assert np.all(f_contract == 0) and np.all(j_contract == 0)
    assert np.linalg.norm(f_always) > 0

    def element(y):
        return jet_element(y[0:2], y[2:4], y[4:6], y[6:8], y[8:10], area_old, 1e-3, 1000.0, 0.8,
                           False)[0]

    assert_close_to_scale(j_always, central_jacobian(element, x, 1e-6 * 1e-3))


# ---- the assembled system ---------------------------------------------------------------------

@pytest.mark.parametrize("jet_mode,shrink", [("contract", 1.001), ("always", 0.999)])
def test_assembled_force_jacobian(jet_mode, shrink):
    sim = ReferenceSimulator(StarParams(gait="A1+A2", jet_mode=jet_mode, cylinder_drag=10.0))
    rng = np.random.default_rng(6)
    rest = sim.topology.rest_positions
    q_new = rest + rng.uniform(-2e-5, 2e-5, rest.shape)
    # The old shape is uniformly scaled (every inter-limb space contracts for shrink > 1, expands
    # for shrink < 1) and shaken, so all drag and jet terms are active: ~5e-5 m in 1 ms.
    q_old = shrink * q_new + rng.uniform(-5e-5, 5e-5, rest.shape)
    t_new, dt = 0.08, 1e-3
    forces, jac = sim.force_jacobian(q_new, q_old, t_new, dt)

    def total(y):
        q = y.reshape(rest.shape)
        return (sim.elastic_forces(q, t_new) + sim.fluid_forces(q, q_old, dt)).reshape(-1)

    def fluid(y):
        return sim.fluid_forces(y.reshape(rest.shape), q_old, dt).reshape(-1)

    x = q_new.reshape(-1)
    assert np.allclose(forces.reshape(-1), total(x), rtol=0, atol=1e-12 * np.abs(forces).max())
    # δ = 1e-6 × the ~1 mm edges. Against the ~5e-5 m displacements that set the velocities,
    # (δ/ℓ)² ≈ 4e-10 (a kink of |a|a within δ of an edge is improbable at this δ). A smaller δ
    # would be dominated by the round-off of the summed, partly cancelling element forces.
    step = 1e-9
    assert_close_to_scale(jac, central_jacobian(total, x, step))
    # The fluid Jacobian is ~1e8 times smaller than the elastic one, so check it on its own.
    elastic_jac = sim.force_jacobian(q_new, q_new, t_new, dt)[1]  # q_old = q_new: v = 0
    fluid_jac = jac - elastic_jac
    assert_close_to_scale(fluid_jac, central_jacobian(fluid, x, step))
    centre_jet = fluid_jac[0:2, 2:]  # the jet couples the centre to joints and tips
    assert np.abs(centre_jet).max() > 0


# ---- invariants -------------------------------------------------------------------------------

def test_rest_shape_is_force_free_without_actuation():
    sim = ReferenceSimulator(StarParams(gait="none"))
    rest = sim.topology.rest_positions
    # Force scale: a limb edge strained by 1e-9 (k_limb·1e-9, N/m). Round-off in the strains of
    # the exact rest shape is ~1e-16, so an equilibrium shape sits far below it.
    scale = StarParams().limb_modulus * StarParams().thickness * 1e-9
    for t in (0.0, 0.1, 1.0):
        assert np.abs(sim.elastic_forces(rest, t)).max() <= scale
    # The same shape while actuators are driven (t = 0.1 s: K̄ ≈ 30 1/m) is far from equilibrium.
    driven = ReferenceSimulator(StarParams(gait="A1"))
    assert np.abs(driven.elastic_forces(rest, 0.1)).max() > 1e4 * scale


def test_elastic_forces_invariant_under_rigid_motion():
    sim = ReferenceSimulator(StarParams(gait="A1+A3"))
    rng = np.random.default_rng(7)
    q = sim.topology.rest_positions + rng.uniform(-5e-5, 5e-5, (sim.topology.n_nodes, 2))
    t = 0.1
    forces = sim.elastic_forces(q, t)
    energy = sim.elastic_energy(q, t)
    angle = 0.7
    rotation = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    moved = q @ rotation.T + np.array([0.013, -0.021])
    # Moving the shape re-rounds positions of ~5e-2 m (ulp ~7e-18 m), i.e. ~1e-14 relative
    # changes in edge vectors; 1e-9 relative is far above that and far below any real error.
    assert_close_to_scale(sim.elastic_forces(moved, t), forces @ rotation.T, rtol=1e-9)
    assert abs(sim.elastic_energy(moved, t) - energy) <= 1e-9 * energy
    assert np.abs(forces.sum(0)).max() <= 1e-9 * np.abs(forces).max()


def test_linear_momentum_conserved_without_fluid():
    sim = ReferenceSimulator(StarParams(gait="none", **FLUID_OFF))
    rng = np.random.default_rng(8)
    rest = sim.topology.rest_positions
    q = rest + rng.uniform(-2e-5, 2e-5, rest.shape)
    v = np.array([0.01, -0.005]) + rng.uniform(-0.01, 0.01, rest.shape)
    momentum0 = sim.mass @ v
    scale = sim.mass @ np.linalg.norm(v, axis=1)
    t = 0.0
    for _ in range(20):
        q, v, _ = sim.step(q, v, t)
        t += sim.solver.dt
    # Σ_i R_i = Σ_i m_i(q_i − q_old,i − h v_old,i)/h² since internal forces sum to zero, so the
    # summed residual is linear in q and the first Newton update already zeroes it: momentum is
    # conserved to round-off, independently of newton_tol (which alone would only bound the
    # drift by Σm·tol/h per step ≈ 1e-5 relative). Round-off: ε·|J|·|Δq| ~ 1e-16·2e9·1e-5 per
    # DOF per iteration, ~1e-12 kg m/s over the run against a scale of ~3e-2: allow 1e-9.
    assert np.abs(sim.mass @ v - momentum0).max() <= 1e-9 * scale
    assert np.abs(q - rest).max() > 1e-5  # the robot did move and deform


def _mirror_permutation(positions, angle):
    """perm with positions[perm] = positions reflected across the line at `angle` (rad)."""
    c, s = math.cos(2 * angle), math.sin(2 * angle)
    mirrored = positions @ np.array([[c, s], [s, -c]]).T
    distance = np.linalg.norm(mirrored[:, None, :] - positions[None, :, :], axis=2)
    perm = distance.argmin(axis=1)
    assert distance.min(axis=1).max() < 1e-12 and len(set(perm)) == len(perm)
    return perm, np.array([[c, s], [s, -c]])


def test_actuated_run_converges_and_is_mirror_symmetric():
    params = StarParams(gait="A1+A2")
    sim = ReferenceSimulator(params)
    topo = sim.topology
    rest = topo.rest_positions
    steps = 50
    q, v = rest.copy(), np.zeros_like(rest)
    for k in range(steps):
        q, v, iterations = sim.step(q, v, k * sim.solver.dt)
        assert 1 <= iterations <= sim.solver.max_newton
    assert np.all(np.isfinite(q)) and np.all(np.isfinite(v))
    history = sim.run(steps)
    assert history.shape == (steps + 1, topo.n_nodes, 2)
    assert np.array_equal(history[0], rest)  # from rest in the rest shape
    assert np.array_equal(history[-1], q)

    # The driven arcs straighten towards K̄(t) (from 102 to ~74 1/m at 50 ms), the opposite ones
    # barely change.
    kappa = discrete_curvature(q[topo.triplets[:, 0]], q[topo.triplets[:, 1]],
                               q[topo.triplets[:, 2]], topo.voronoi_length)
    rest_k = np.abs(topo.rest_curvature[topo.triplet_actuator == 0]).mean()
    target = CurvatureProfile().curvature(steps * sim.solver.dt)
    mean_k = [np.abs(kappa[topo.triplet_actuator == m]).mean() for m in range(8)]
    assert target < mean_k[0] < rest_k - 0.1 * (rest_k - target)
    assert abs(mean_k[4] - rest_k) < 0.1 * (rest_k - mean_k[0])

    # A1+A2 is symmetric about the line at 22.5°: so is the robot's whole motion, to the
    # accumulated Newton tolerance (50 steps × 1e-10 m).
    perm, mirror = _mirror_permutation(rest, math.radians(22.5))
    assert np.abs(q @ mirror.T - q[perm]).max() <= 1e-8
    displacement = sim.centroid(q) - sim.centroid(rest)
    assert np.linalg.norm(displacement) > 0
    assert abs(np.arctan2(displacement[1], displacement[0]) - math.radians(22.5)) < 1e-3 or \
        abs(np.arctan2(-displacement[1], -displacement[0]) - math.radians(22.5)) < 1e-3


def test_step_solves_the_implicit_euler_equation():
    """The returned state satisfies paper Eq. 4 with the public force functions, the natural
    curvature taken at the end of the step."""
    solver = SolverConfig(newton_tol=1e-12)
    sim = ReferenceSimulator(StarParams(gait="A1"), solver)
    h = solver.dt
    q, v = sim.topology.rest_positions.copy(), np.zeros_like(sim.topology.rest_positions)
    for k in range(30):  # into the heating phase: moving, dragging and jetting
        q, v, _ = sim.step(q, v, k * h)
    t = 30 * h
    q_new, v_new, _ = sim.step(q, v, t)
    assert np.allclose(v_new, (q_new - q) / h, rtol=0, atol=1e-15)
    inertia = (sim.mass + sim.added_mass)[:, None]
    residual = (inertia * (q_new - q - h * v) / h ** 2 - sim.elastic_forces(q_new, t + h)
                - sim.fluid_forces(q_new, q, h))
    # The returned q is within ~newton_tol of the exact root (the last update was at most that
    # and Newton converges quadratically), so |R| ≤ ‖M/h² − ∂F/∂q‖∞·newton_tol.
    system = np.diag(np.repeat(inertia[:, 0], 2) / h ** 2) - sim.force_jacobian(q_new, q, t + h,
                                                                               h)[1]
    bound = np.abs(system).sum(1).max() * solver.newton_tol
    assert np.abs(residual).max() <= bound
    # Taking κ⁰ at the start of the step instead violates the equation by far more.
    stale = (inertia * (q_new - q - h * v) / h ** 2 - sim.elastic_forces(q_new, t)
             - sim.fluid_forces(q_new, q, h))
    assert np.abs(stale).max() > 10 * bound


def test_newton_failure_is_raised():
    sim = ReferenceSimulator(StarParams(gait="A1"), SolverConfig(max_newton=1))
    rest = sim.topology.rest_positions
    with pytest.raises(NewtonDidNotConverge):
        sim.step(rest, np.zeros_like(rest), 0.05)


def test_masses():
    params = StarParams()
    sim = ReferenceSimulator(params)
    topo = sim.topology
    # Independent lumping straight from the edges: every non-spoke edge gives half its mass and
    # half its added mass to each end.
    arcs = topo.edge_kind == 2
    limbs = topo.edge_kind == 1
    rod_mass = params.thickness * (params.actuator_density * topo.rest_length[arcs].sum()
                                   + params.foam_density * topo.rest_length[limbs].sum())
    assert math.isclose(sim.mass.sum(), rod_mass + params.cylinder_mass_per_height, rel_tol=1e-12)
    rod_length = topo.rest_length[arcs | limbs].sum()
    assert math.isclose(sim.added_mass.sum(), params.fluid_density * params.added_mass_coeff
                        * params.thickness * rod_length, rel_tol=1e-12)
    assert sim.added_mass[0] == 0.0  # the cylinder has no added mass by default
    with_cyl = ReferenceSimulator(params.replace(cylinder_added_mass_coeff=1.0))
    assert math.isclose(with_cyl.added_mass[0], 1000.0 * math.pi * 0.03 ** 2 / 4, rel_tol=1e-12)
    assert np.allclose(sim.centroid(topo.rest_positions), 0.0, atol=1e-15)
    assert sim.topology.triplet_kind[sim.topology.triplet_actuator >= 0].tolist() == \
        [ARC_BEND] * int((sim.topology.triplet_actuator >= 0).sum())
