"""One force term assembled on its own: no engine, only a toy `Assembly` (a 4-node chain, dense
Jacobian slots, one instance) that the term fills through the same interface as in the engine.

The residual must equal the NumPy reference's energy gradient (`reference.stretch_element`,
`reference.bend_element`): both are closed forms of the same derivative, written differently, so
they agree to rounding, ~1e-13 relative in f64; 1e-9 of the largest entry leaves room for that and
fails for any wrong term or misplaced scatter (O(1) relative). The Jacobian must equal central
differences of the assembled residual: with δ = 1e-7 of the edge length the truncation error
O(δ²) and the rounding error O(ε/δ) are both ~1e-9 relative, so 1e-6 of the largest entry.
"""

from types import SimpleNamespace

import numpy as np
import pytest
import taichi as ti

from taichi_star import reference
from taichi_star.fields import FieldArena
from taichi_star.integrators import ImplicitEuler
from taichi_star.model import InstanceTopologies
from taichi_star.geometry import LIMB
from taichi_star.physics import (Bending, CylinderDrag, LinearDrag, MaterialDamping, RodDrag,
                                  Stretching, Wake)
from taichi_star.physics.assembly import Assembly, distinct_rows
from taichi_star.params import StarParams
from taichi_star.physics.base import connect_terms, load_field, numpy_to_field_type

EDGES = np.array([[0, 1], [1, 2], [2, 3]])
TRIPLETS = np.array([[0, 1, 2], [1, 2, 3]])
REST = np.array([[0.0, 0.0], [1.0e-3, 0.1e-3], [2.1e-3, 0.0], [3.0e-3, -0.3e-3]])
N_NODES = len(REST)
TOY_EDGE_KIND = np.full(len(EDGES), LIMB)
"""Every edge of the chain is a rod (a limb): the drag terms act on all of them."""
REFERENCE_RTOL = 1e-9
DIFFERENCE_RTOL = 1e-6


def toy_system(term_classes, coefficients, configurations, capacity=1, primal_count=None):
    """The term classes' device objects on a toy Assembly of `capacity` instances: ({name:
    term}, assembly). With `primal_count`, the first that many are simulated instances and the
    rest their replicas (instance b's at primal_count·k + b, as in the engine)."""
    arena = FieldArena()
    nodes = (capacity, N_NODES)
    state = SimpleNamespace(**{name: arena.batch_field(float, nodes, vector=2)
                               for name in ("positions", "previous", "velocity_offset")},
                            fire_time=arena.batch_field(float, (capacity, 8)),
                            previous_fire_time=arena.batch_field(float, (capacity, 8)))
    system = SimpleNamespace(rhs=arena.batch_field(float, nodes, vector=2),
                             blocks=arena.batch_field(float, (capacity, N_NODES * N_NODES),
                                                      matrix=(2, 2)))
    primal = None if primal_count is None else arena.field(ti.i32)
    topology = SimpleNamespace(n_nodes=N_NODES, edges=EDGES, n_edges=len(EDGES),
                               edge_kind=TOY_EDGE_KIND, triplets=TRIPLETS,
                               n_triplets=len(TRIPLETS), triplet_actuator=np.full(2, -1),
                               joint_actuator=np.full(2, -1))
    slot = {(i, j): i * N_NODES + j for i in range(N_NODES) for j in range(N_NODES)}
    assembly = Assembly(topology, capacity, arena, slot, ImplicitEuler(), state, system, primal)
    terms = {}
    for cls in term_classes:
        shapes = {name: (values.shape[1:], numpy_to_field_type(values))
                  for name, values in coefficients[cls.name].items()}
        terms[cls.name] = cls(assembly, configurations[cls.name], shapes, term_classes)
    connect_terms(list(terms.values()))
    arena.finalize()
    for cls in term_classes:
        for name, field in terms[cls.name].coefficient_fields().items():
            load_field(field, coefficients[cls.name][name])
    if primal is not None:
        primal[None] = primal_count
    return terms, assembly


@ti.kernel
def _assemble(term: ti.template(), rate_gain: float):
    term.assemble(0, rate_gain, 1)


@ti.kernel
def _assemble_two(first: ti.template(), second: ti.template(), rate_gain: float):
    first.assemble(0, rate_gain, 1)
    second.assemble(0, rate_gain, 1)


@ti.kernel
def _assemble_all(term: ti.template(), rate_gain: float, count: ti.i32):
    for b in range(count):
        term.assemble(b, rate_gain, 0)


@ti.kernel
def _begin_step(term: ti.template(), h: float):
    term.begin_step(0, 0.0, h, h, 1.0, 1.0 / h, 0)


@ti.kernel
def _accept_step(term: ti.template(), rate_gain: float):
    term.accept_step(0, rate_gain)


def residual_and_jacobian(term, assembly, positions, rate_gain=1.0, other=None):
    """(8,) residual and (8, 8) Jacobian the term (and `other`, if given) assembles at
    `positions` (N, 2)."""
    load_field(assembly.positions, positions[None])
    assembly.rhs.fill(0.0)
    assembly.blocks.fill(0.0)
    if other is None:
        _assemble(term, rate_gain)
    else:
        _assemble_two(term, other, rate_gain)
    blocks = assembly.blocks.to_numpy()[0]
    jacobian = np.zeros((2 * N_NODES, 2 * N_NODES))
    for (i, j), slot in assembly.slots.items():
        jacobian[2 * i:2 * i + 2, 2 * j:2 * j + 2] = blocks[slot]
    return assembly.rhs.to_numpy()[0].ravel(), jacobian


def central_jacobian(residual, positions, step):
    columns = []
    for index in range(positions.size):
        forward, backward = positions.ravel().copy(), positions.ravel().copy()
        forward[index] += step
        backward[index] -= step
        columns.append((residual(forward.reshape(positions.shape))
                        - residual(backward.reshape(positions.shape))) / (2 * step))
    return np.stack(columns, axis=1)


def reference_gradient(elements, positions, element):
    """(8,) sum of the reference elements' gradients over their nodes."""
    gradient = np.zeros(2 * N_NODES)
    for e, nodes in enumerate(elements):
        local = element(e, *positions[nodes])[1]
        for a, node in enumerate(nodes):
            gradient[2 * node:2 * node + 2] += local[2 * a:2 * a + 2]
    return gradient


def assert_close(actual, expected, rtol):
    scale = np.abs(expected).max()
    assert scale > 0, "the expected values are all zero: the check would be vacuous"
    np.testing.assert_allclose(actual, expected, rtol=0, atol=rtol * scale)


STRETCHING = {"rest_length": np.linalg.norm(REST[EDGES[:, 1]] - REST[EDGES[:, 0]], axis=1)[None],
              "edge_stiffness": np.array([[1.7e4, 2.3e4, 0.9e4]])}
BENDING = {"voronoi_length": np.array([[1.05e-3, 1.0e-3]]),
           "rest_curvature": np.array([[-150.0, 80.0]]),
           "end_turning_length": np.zeros((1, 2)), "bend_stiffness": np.array([[2.0e-5, 3.5e-5]]),
           "profile": np.zeros((1, 9)), "profile_rest": np.zeros(1), "closure_rate": np.zeros(1),
           "period": np.ones(1), "gait_mask": np.zeros((1, 8), dtype=np.int32)}


def deformed():
    """The rest chain moved off its rest shape by ~10 % of an edge: every element strained."""
    return REST + 1e-4 * np.random.default_rng(5).normal(size=REST.shape)


@pytest.mark.parametrize("term_class", [Stretching, Bending])
def test_one_term_assembles_the_reference_gradient_and_its_own_exact_jacobian(taichi_cpu, term_class):
    coefficients = {"stretching": STRETCHING, "bending": BENDING}
    terms, assembly = toy_system([term_class], coefficients,
                                 {"stretching": (), "bending": (False,)})
    term = terms[term_class.name]
    positions = deformed()
    residual, jacobian = residual_and_jacobian(term, assembly, positions)
    if term_class is Stretching:
        expected = reference_gradient(EDGES, positions, lambda e, xi, xj: reference.stretch_element(
            xi, xj, STRETCHING["rest_length"][0, e], STRETCHING["edge_stiffness"][0, e]))
    else:
        expected = reference_gradient(TRIPLETS, positions, lambda t, xi, xj, xk: reference.bend_element(
            xi, xj, xk, BENDING["voronoi_length"][0, t], BENDING["rest_curvature"][0, t],
            BENDING["bend_stiffness"][0, t]))
    assert_close(residual, expected, REFERENCE_RTOL)
    numeric = central_jacobian(lambda q: residual_and_jacobian(term, assembly, q)[0], positions, 1e-10)
    assert_close(jacobian, numeric, DIFFERENCE_RTOL)
    # a gradient's Jacobian is symmetric; the scatter sums its blocks in different orders, so
    # up to rounding
    assert_close(jacobian, jacobian.T, 1e-12)


def test_damping_reshapes_every_strain_term_through_the_base_interface(taichi_cpu):
    """Damping with stretching and bending on the toy chain, no names involved: after a step's
    begin (implicit Euler, h = 1 ms, from the deformed shape) and a move of the nodes, the
    assembled residual is the elastic gradient plus τ·k_s·ṡ·∇s of every element (the reference's
    `damping_element` at its anchor s* = s_k), for both terms."""
    tau, h = 2e-3, 1e-3
    coefficients = {"stretching": STRETCHING, "bending": BENDING,
                    "damping": {"damping_time": np.array([tau])}}
    classes = [Stretching, Bending, MaterialDamping]
    terms, assembly = toy_system(classes, coefficients,
                                 {"stretching": (), "bending": (False,), "damping": ()})
    assert [t.name for t in terms["damping"].reshaped_terms] == ["stretching", "bending"]
    start = deformed()
    load_field(assembly.positions, start[None])
    _begin_step(terms["damping"], h)
    moved = start + 2e-5 * np.random.default_rng(6).normal(size=start.shape)
    residual = residual_and_jacobian(terms["stretching"], assembly, moved, 1.0 / h,
                                     terms["bending"])[0]

    def stretch(e, xi, xj):
        rest, stiffness = STRETCHING["rest_length"][0, e], STRETCHING["edge_stiffness"][0, e]
        strain, gradient, hessian = reference.stretch_strain(xi, xj, rest)
        anchor = reference.stretch_strain(*start[EDGES[e]], rest)[0]
        elastic = reference.stretch_element(xi, xj, rest, stiffness)
        damped = reference.damping_element(strain, gradient, hessian, anchor, 1.0 / h,
                                           stiffness * rest, tau)
        return elastic[1], damped[1]

    def bend(t, xi, xj, xk):
        voronoi, natural = BENDING["voronoi_length"][0, t], BENDING["rest_curvature"][0, t]
        stiffness = BENDING["bend_stiffness"][0, t]
        strain, gradient, hessian = reference.bend_strain(xi, xj, xk, voronoi, natural)
        anchor = reference.bend_strain(*start[TRIPLETS[t]], voronoi, natural)[0]
        elastic = reference.bend_element(xi, xj, xk, voronoi, natural, stiffness)
        damped = reference.damping_element(strain, gradient, hessian, anchor, 1.0 / h,
                                           stiffness * voronoi, tau)
        return elastic[1], damped[1]

    def chain_gradients(elements, element):
        """(elastic, damping) gradients of the chain's elements, (8,) each."""
        return [reference_gradient(elements, moved,
                                   lambda *nodes, part=part: (None, element(*nodes)[part]))
                for part in (0, 1)]

    elastic, damped = (sum(pair) for pair in zip(chain_gradients(EDGES, stretch),
                                                  chain_gradients(TRIPLETS, bend)))
    assert np.abs(damped).max() > 1e-2 * np.abs(elastic).max()  # the damping is no rounding
    assert_close(residual, elastic + damped, REFERENCE_RTOL)


def test_linear_drag_assembles_the_reference_forces_and_its_own_exact_jacobian(taichi_cpu):
    """The linear drag on the toy chain (node 0 stands for the hub), its coefficients from its
    own `coefficients`, one implicit-Euler iterate (h = 1 ms) from the rest chain: the residual
    is minus the reference's rod and hub forces (`reference.linear_rod_drag_element`,
    `hub_linear_drag_element`), the Jacobian the central differences of the residual (the
    forces are linear in the positions: exact up to rounding)."""
    h, rod_coeff, hub_coeff = 1e-3, 40.0, 3.0
    rest_length = np.linalg.norm(REST[EDGES[:, 1]] - REST[EDGES[:, 0]], axis=1)
    coefficients = LinearDrag.coefficients(
        [StarParams(linear_drag=rod_coeff, hub_linear_drag=hub_coeff)],
        InstanceTopologies([SimpleNamespace(rest_length=rest_length)]), SimpleNamespace(edge_kind=TOY_EDGE_KIND))
    assert LinearDrag.configuration(coefficients) == ()
    terms, assembly = toy_system([LinearDrag], {"linear_drag": coefficients}, {"linear_drag": ()})
    term = terms["linear_drag"]
    load_field(assembly.previous, REST[None])
    positions = deformed()
    residual, jacobian = residual_and_jacobian(term, assembly, positions, 1.0 / h)
    forces = np.zeros(2 * N_NODES)
    for e, (i, j) in enumerate(EDGES):
        local = reference.linear_rod_drag_element(positions[i], positions[j], REST[i], REST[j], h,
                                                  rest_length[e], rod_coeff)[0]
        forces[2 * i:2 * i + 2] += local[:2]
        forces[2 * j:2 * j + 2] += local[2:]
    forces[:2] += reference.hub_linear_drag_element(positions[0], REST[0], h, hub_coeff)[0]
    assert_close(residual, -forces, REFERENCE_RTOL)
    numeric = central_jacobian(lambda q: residual_and_jacobian(term, assembly, q, 1.0 / h)[0],
                               positions, 1e-10)
    assert_close(jacobian, numeric, DIFFERENCE_RTOL)
    off = LinearDrag.coefficients([StarParams()],
                                  InstanceTopologies([SimpleNamespace(rest_length=rest_length)]),
                                  SimpleNamespace(edge_kind=TOY_EDGE_KIND))
    assert LinearDrag.configuration(off) is None  # off: compiled out


def test_wake_assembles_the_water_exchange_and_its_own_exact_jacobian(taichi_cpu):
    """The entrained water on the toy chain (node 0 stands for the hub), one implicit-Euler
    iterate (h = 1 ms) from the rest chain with the water at u_k: the hub's residual is
    −c_w·(u' − v), u' solved by hand from the water's own momentum balance
    m_w·(u' − u_k)/h = c_w·(v − u') with m_w = c_w·τ_w (the term eliminates u' in another form),
    no other node feels it; the Jacobian is the central differences of the residual (linear in
    the positions: exact up to rounding). Accepting the step commits u' and keeps u_k as the
    previous value."""
    h, coupling, exchange_time = 1e-3, 4.0, 0.02
    coefficients = Wake.coefficients(
        [StarParams(wake_coupling=coupling, wake_time=exchange_time)], None, None)
    assert Wake.configuration(coefficients) == ()
    terms, assembly = toy_system([Wake], {"wake": coefficients}, {"wake": ()})
    term = terms["wake"]
    water = np.array([2e-3, -1e-3])
    load_field(term.water_velocity, water[None])
    # read only by BDF2's offset with history, which this step has not: a value that would show
    load_field(term.water_previous, np.array([[5.0, 5.0]]))
    load_field(assembly.previous, REST[None])
    _begin_step(term, h)
    positions = deformed()
    residual, jacobian = residual_and_jacobian(term, assembly, positions, 1.0 / h)
    hub_velocity = (positions[0] - REST[0]) / h
    water_mass = coupling * exchange_time
    solved = (water_mass / h * water + coupling * hub_velocity) / (water_mass / h + coupling)
    expected = np.zeros(2 * N_NODES)
    expected[:2] = -coupling * (solved - hub_velocity)
    assert_close(residual, expected, REFERENCE_RTOL)
    numeric = central_jacobian(lambda q: residual_and_jacobian(term, assembly, q, 1.0 / h)[0],
                               positions, 1e-10)
    assert_close(jacobian, numeric, DIFFERENCE_RTOL)
    load_field(assembly.positions, positions[None])
    _accept_step(term, 1.0 / h)
    # 1e-12: u' by two algebraically equal closed forms, a few roundings apart
    np.testing.assert_allclose(term.water_velocity.to_numpy()[0], solved, rtol=1e-12)
    np.testing.assert_array_equal(term.water_previous.to_numpy()[0], water)
    assert Wake.configuration(Wake.coefficients([StarParams()], None, None)) is None


def _replica_pair_system(term_class, coefficients, replicated):
    """A toy system of three instances of the chain with `term_class` alone: an instance and
    its replica pair (`replicated`), else three independent instances. Built once for the
    calls of `_replica_pair_difference`, which load their own coefficients and states (a
    system per call compiled its kernels again: 6 s of the suite for the two drags)."""
    name = term_class.name
    three = {key: np.repeat(values[:1], 3, axis=0) for key, values in coefficients.items()}
    return toy_system([term_class], {name: three}, {name: ()}, capacity=3,
                      primal_count=1 if replicated else None)


def _replica_pair_difference(system, term_class, coefficients, instance_velocity, direction,
                             step):
    """Half the difference of the residuals of the replica pair (or the second and third
    independent instances) of `system` (`_replica_pair_system`), over `step`: the instance at
    `deformed()` positions with node velocities `instance_velocity` (N, 2) m/s (implicit
    Euler, h = 1 ms), the pair at the same positions from start states whose velocities are
    instance_velocity ± step·`direction`, with their coefficients at c·(1 ± step) (a relative
    direction of a parameter the term is linear in)."""
    h = 1e-3
    terms, assembly = system
    term = terms[term_class.name]
    for key, field in term.coefficient_fields().items():
        values = coefficients[key]
        load_field(field, np.stack([values[0], values[0] * (1 + step), values[0] * (1 - step)]))
    positions = deformed()
    velocities = np.stack([instance_velocity, instance_velocity + step * direction,
                           instance_velocity - step * direction])
    load_field(assembly.positions, np.stack([positions] * 3))
    load_field(assembly.previous, positions[None] - h * velocities)
    assembly.rhs.fill(0.0)  # the terms add to the residual and the blocks
    assembly.blocks.fill(0.0)
    _assemble_all(term, 1.0 / h, 3)
    rhs = assembly.rhs.to_numpy()
    return (rhs[1] - rhs[2]).ravel() / (2 * step)


DRAG_COEFFICIENTS = {
    RodDrag: {"drag_parallel_coeff": np.array([[0.006, 0.007, 0.0065]]),
              "drag_perpendicular_coeff": np.array([[0.6, 0.7, 0.65]])},
    CylinderDrag: {"cylinder_drag_coeff": np.array([150.0])}}
"""½ρ_f·Δl̄·C∥, ½ρ_f·Δl̄·C⊥ per edge (kg/m², edges ~1.3 mm, C∥ = 0.01, C⊥ = 1) and
½ρ_f·C_c·D_c of the hub (kg/m², C_c = 10, D_c = 3 cm)."""


@pytest.mark.parametrize("term_class", [RodDrag, CylinderDrag])
def test_a_replica_pair_differences_the_drags_derivative_exactly(taichi_cpu, term_class):
    """A replica takes the drag's first-order expansion about its instance's velocity
    (`Assembly.primal_instance`), so its pair's half difference is linear in the pair's offsets
    and the parameter's: the same for a step of 1e-2 and of 1e-5, also with the instance
    1e-12 m/s from the kink at rest, where the pair straddles it; away from the kink it equals
    the derivative of independent instances (the plain central difference at 1e-5). 1e-7: the
    pair's velocity offsets come back from positions ~1e-3 m and steps of 1e-3 s, ~1e-8
    relative of rounding at a step of 1e-5, and the plain difference's O(δ²) truncation is
    ~1e-10. The plain difference at 1e-2 is 1e-5 or more off, at the kink O(1): the check has
    teeth."""
    rng = np.random.default_rng(11)
    coefficients = DRAG_COEFFICIENTS[term_class]
    direction = 0.02 * rng.normal(size=REST.shape)
    moving = 0.03 * rng.normal(size=REST.shape)
    at_kink = 1e-12 * rng.normal(size=REST.shape)

    systems = {replicated: _replica_pair_system(term_class, coefficients, replicated)
               for replicated in (True, False)}

    def difference(velocity, step, replicated):
        return _replica_pair_difference(systems[replicated], term_class, coefficients,
                                        velocity, direction, step)

    for velocity in (moving, at_kink):
        assert_close(difference(velocity, 1e-2, True), difference(velocity, 1e-5, True), 1e-7)
    derivative = difference(moving, 1e-5, False)
    assert_close(difference(moving, 1e-2, True), derivative, 1e-7)
    assert np.abs(difference(moving, 1e-2, False) - derivative).max() \
        > 1e-5 * np.abs(derivative).max()
    exact = difference(at_kink, 1e-2, True)
    assert np.abs(difference(at_kink, 1e-2, False) - exact).max() > 1e-2 * np.abs(exact).max()


def _external_coefficients(term_class):
    """The toy chain's coefficients of an external term, every part of it switched on."""
    rest_length = np.linalg.norm(REST[EDGES[:, 1]] - REST[EDGES[:, 0]], axis=1)
    if term_class is LinearDrag:
        return LinearDrag.coefficients(
            [StarParams(linear_drag=40.0, hub_linear_drag=3.0)],
            InstanceTopologies([SimpleNamespace(rest_length=rest_length)]),
            SimpleNamespace(edge_kind=TOY_EDGE_KIND))
    if term_class is Wake:
        return Wake.coefficients([StarParams(wake_coupling=4.0, wake_time=0.02)], None, None)
    return DRAG_COEFFICIENTS[term_class]


@pytest.mark.parametrize("term_class", [RodDrag, CylinderDrag, LinearDrag, Wake])
def test_an_external_term_fills_only_the_diagonal_and_the_pairs_it_declares(taichi_cpu,
                                                                            term_class):
    """On the toy chain's dense slots, a moving chain (every velocity non-zero): the term's
    Jacobian blocks off the diagonal and off its declared node pairs (`configured_pairs`) are
    exactly zero. The engine's elimination plan and its tangent's rigid projector, whose first
    pass reads only those slots (`BatchEngine.external_slot_nodes`), rely on it; the jet, which
    needs the robot's spaces, is held to it in tests/model/test_engine.py."""
    terms, assembly = toy_system([term_class], {term_class.name: _external_coefficients(
        term_class)}, {term_class.name: ()})
    h = 1e-3
    velocities = 0.03 * np.random.default_rng(3).normal(size=REST.shape)
    positions = deformed()
    load_field(assembly.previous, (positions - h * velocities)[None])
    _, jacobian = residual_and_jacobian(terms[term_class.name], assembly, positions, 1.0 / h)
    declared = {frozenset(pair) for pair in term_class.configured_pairs(assembly.topology, ())}
    filled = {(i, j) for i in range(N_NODES) for j in range(N_NODES)
              if jacobian[2 * i:2 * i + 2, 2 * j:2 * j + 2].any()}
    assert filled, "nothing assembled: the check would be vacuous"
    assert {(i, j) for i, j in filled if i != j and frozenset((i, j)) not in declared} == set()
    # the declared pairs are filled, not only allowed (the drags on the edges; the hub terms
    # declare none)
    assert {frozenset((i, j)) for i, j in filled if i != j} == declared


@ti.kernel
def _scatter_triplet(assembly: ti.template(), slots: ti.template(), g: ti.types.ndarray(),
                     h: ti.types.ndarray(), jacobian: ti.i32):
    g1, g2 = ti.Vector([g[0, 0], g[0, 1]]), ti.Vector([g[1, 0], g[1, 1]])
    h11 = ti.Matrix([[h[0, 0, 0], h[0, 0, 1]], [h[0, 1, 0], h[0, 1, 1]]])
    h12 = ti.Matrix([[h[1, 0, 0], h[1, 0, 1]], [h[1, 1, 0], h[1, 1, 1]]])
    h22 = ti.Matrix([[h[2, 0, 0], h[2, 0, 1]], [h[2, 1, 0], h[2, 1, 1]]])
    assembly.scatter_triplet(0, slots, 1, 1, 2, 3, g1, g2, h11, h12, h22, jacobian)


@pytest.mark.parametrize("jacobian", [0, 1])
def test_a_triplet_scatters_the_sums_of_one_add_at_a_time_bit_for_bit(taichi_cpu, jacobian):
    """`scatter_triplet` loads an element's nine blocks and three residuals before it stores any
    (`Assembly.add_blocks`): the result must be, bit for bit, that of adding each block and
    residual on its own in the incidence's order (what the engine did before, and what its
    bits were checked against), onto a system that already holds other terms' values; without
    `jacobian` the blocks stay as they were, to the bit."""
    terms, assembly = toy_system([Bending], {"bending": BENDING}, {"bending": (False,)})
    rng = np.random.default_rng(11)
    rhs = rng.normal(size=(1, N_NODES, 2))
    blocks = rng.normal(size=(1, N_NODES * N_NODES, 2, 2))
    g, h = rng.normal(size=(2, 2)), rng.normal(size=(3, 2, 2))
    load_field(assembly.rhs, rhs)
    load_field(assembly.blocks, blocks)
    _scatter_triplet(assembly, terms["bending"].triplet_slot, g, h, jacobian)
    expected_rhs, expected_blocks = rhs[0].copy(), blocks[0].copy()
    (g1, g2), (h11, h12, h22), h21 = g, h, h[1].T
    for node, value in ((1, -g1), (2, g1), (2, -g2), (3, g2)):
        expected_rhs[node] = expected_rhs[node] + value
    values = [h11, h12 - h11, -h12, h21 - h11, h11 - h12 - h21 + h22, h12 - h22, -h21, h21 - h22,
              h22]
    nodes = TRIPLETS[1]
    for (a, c), value in zip([(a, c) for a in nodes for c in nodes], values):
        if jacobian:
            expected_blocks[assembly.slot(a, c)] = expected_blocks[assembly.slot(a, c)] + value
    np.testing.assert_array_equal(assembly.rhs.to_numpy()[0], expected_rhs)
    np.testing.assert_array_equal(assembly.blocks.to_numpy()[0], expected_blocks)
    assert not np.array_equal(expected_rhs, rhs[0])  # the scatter did add


def test_an_element_whose_nodes_repeat_is_refused_before_its_slot_table_is_built(taichi_cpu):
    """`add_blocks` stores a row's blocks after loading them all, so a row must not repeat a
    slot: a pair (2, 2) or a triplet (1, 2, 1) is refused naming it; distinct nodes pass."""
    slot = {(i, j): i * N_NODES + j for i in range(N_NODES) for j in range(N_NODES)}
    pair_rows = [[slot[i, i], slot[i, j], slot[j, i], slot[j, j]] for i, j in ((0, 1), (2, 2))]
    with pytest.raises(ValueError, match="pair 1 repeats a Jacobian slot"):
        distinct_rows(pair_rows, "pair")
    triplet_rows = [[slot[a, c] for a in nodes for c in nodes] for nodes in ((0, 1, 2), (1, 2, 1))]
    with pytest.raises(ValueError, match="triplet 1 repeats a Jacobian slot"):
        distinct_rows(triplet_rows, "triplet")
    assert distinct_rows(triplet_rows[:1], "triplet") == triplet_rows[:1]


def test_a_row_that_repeats_one_slot_once_is_refused():
    """`distinct_rows` refuses any repeated slot, also a single repeat in a longer row (a rule
    of two or more lived through the suite: a mutation audit, 2026-12-07)."""
    with pytest.raises(ValueError, match="pair 1 repeats a Jacobian slot"):
        distinct_rows([[0, 1, 2, 3], [4, 5, 5, 6]], "pair")
