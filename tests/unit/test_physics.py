"""Finite-difference checks of every Taichi element function (the term modules of
taichi_star.physics).

Central differences with step δ have truncation error O(δ²·f''') and rounding error
O(ε·|f|/δ); with δ = 1e-6 of the input's scale both are ~1e-10 relative in f64, so a relative
tolerance of 1e-6 on the largest entry is loose enough for rounding yet fails for any wrong term
(a missing or mis-signed term is O(1) relative).
"""

import numpy as np
import pytest
import taichi as ti

from taichi_star.physics import bending, cylinder_drag, jet, rod_drag, stretching

RTOL = 1e-6



@ti.kernel
def _stretch(edge: ti.types.ndarray(), rest: float, stiffness: float, target: float,
             out: ti.types.ndarray()):
    e = ti.Vector([edge[0], edge[1]])
    out[0] = stretching.stretch_energy(e, rest, stiffness, target)
    gradient, hessian = stretching.stretch_gradient_hessian(e, rest, stiffness, target)
    for a in ti.static(range(2)):
        out[1 + a] = gradient[a]
        for c in ti.static(range(2)):
            out[3 + 2 * a + c] = hessian[a, c]


@ti.kernel
def _bend(edges: ti.types.ndarray(), voronoi: float, natural: float, stiffness: float,
          out: ti.types.ndarray()):
    e1 = ti.Vector([edges[0], edges[1]])
    e2 = ti.Vector([edges[2], edges[3]])
    out[0] = bending.bend_energy(e1, e2, voronoi, natural, stiffness)
    g1, g2, h11, h12, h22 = bending.bend_gradient_hessian(e1, e2, voronoi, natural, stiffness)
    h21 = h12.transpose()
    for a in ti.static(range(2)):
        out[1 + a] = g1[a]
        out[3 + a] = g2[a]
        for c in ti.static(range(2)):
            out[5 + 4 * a + c] = h11[a, c]
            out[5 + 4 * a + 2 + c] = h12[a, c]
            out[5 + 4 * (2 + a) + c] = h21[a, c]
            out[5 + 4 * (2 + a) + 2 + c] = h22[a, c]


@ti.kernel
def _rod_drag(inputs: ti.types.ndarray(), parallel: float, perpendicular: float,
              out: ti.types.ndarray()):
    force, d_velocity, d_edge = rod_drag.rod_drag(ti.Vector([inputs[0], inputs[1]]), ti.Vector([inputs[2], inputs[3]]),
                                               parallel, perpendicular)
    for a in ti.static(range(2)):
        out[a] = force[a]
        for c in ti.static(range(2)):
            out[2 + 4 * a + c] = d_velocity[a, c]
            out[2 + 4 * a + 2 + c] = d_edge[a, c]


@ti.kernel
def _cylinder_drag(inputs: ti.types.ndarray(), coeff: float, out: ti.types.ndarray()):
    force, d_velocity = cylinder_drag.cylinder_drag(ti.Vector([inputs[0], inputs[1]]), coeff)
    for a in ti.static(range(2)):
        out[a] = force[a]
        for c in ti.static(range(2)):
            out[2 + 2 * a + c] = d_velocity[a, c]


@ti.kernel
def _jet(points: ti.types.ndarray(), old_area: float, dt: float, alpha: float, density: float,
         always: ti.i32, inflow: float, direction: ti.i32, out: ti.types.ndarray()):
    corners = [ti.Vector([points[2 * c], points[2 * c + 1]]) for c in ti.static(range(5))]
    # implicit Euler's rate of the area: gain 1/dt, no offset
    area_rate = (ti.abs(jet.quad_signed_area(corners[1], corners[2], corners[3], corners[4]))
                 - old_area) / dt
    force, d0, d1, d2, d3, d4, d_rate = jet.jet(corners[0], corners[1], corners[2], corners[3],
                                                corners[4], area_rate, 1.0 / dt, alpha, density,
                                                always, inflow, direction)
    for a in ti.static(range(2)):
        out[a] = force[a]
        out[22 + a] = d_rate[a]
        for c in ti.static(range(2)):
            out[2 + 10 * a + c] = d0[a, c]
            out[2 + 10 * a + 2 + c] = d1[a, c]
            out[2 + 10 * a + 4 + c] = d2[a, c]
            out[2 + 10 * a + 6 + c] = d3[a, c]
            out[2 + 10 * a + 8 + c] = d4[a, c]


def _call(kernel, inputs, n_out, *args):
    out = np.zeros(n_out)
    kernel(np.ascontiguousarray(inputs, dtype=np.float64), *args, out)
    return out


def _call_jet(points, *args):
    """`_call` of `_jet`: force (2,), its position derivatives (2, 10) and ∂f/∂Ṡ (2,)."""
    return _call(_jet, points, 24, *args)


def _central_jacobian(function, x, step):
    """d function / d x by central differences: (len(f(x)), len(x))."""
    columns = []
    for i in range(len(x)):
        forward, backward = x.copy(), x.copy()
        forward[i] += step
        backward[i] -= step
        columns.append((function(forward) - function(backward)) / (2 * step))
    return np.stack(columns, axis=1)


def _assert_close(analytic, numeric):
    scale = np.abs(numeric).max()
    assert scale > 0, "the finite difference is identically zero: the check would be vacuous"
    np.testing.assert_allclose(analytic, numeric, rtol=0, atol=RTOL * scale)


# rest length 1.3e-3: stretched and compressed; target strain 0 (elasticity) and the moving
# target of the material damping's pseudo-energy
@pytest.mark.parametrize("length", [0.9e-3, 1.25e-3, 1.7e-3])
@pytest.mark.parametrize("target", [0.0, 0.07])
def test_stretch_gradient_and_hessian(taichi_cpu, length, target):
    rng = np.random.default_rng(1)
    angle = rng.uniform(0, 2 * np.pi)
    edge = length * np.array([np.cos(angle), np.sin(angle)])
    args = (1.3e-3, 5e6 * 3.4e-3, target)
    evaluate = lambda e: _call(_stretch, e, 7, *args)  # noqa: E731
    out = evaluate(edge)
    step = 1e-6 * length
    _assert_close(out[1:3], _central_jacobian(lambda e: evaluate(e)[:1], edge, step)[0])
    _assert_close(out[3:].reshape(2, 2), _central_jacobian(lambda e: evaluate(e)[1:3], edge, step))


@pytest.mark.parametrize("natural", [0.0, -102.0, 40.0])
def test_bend_gradient_and_hessian(taichi_cpu, natural):
    rng = np.random.default_rng(2)
    for _ in range(3):
        edges = 1.3e-3 * rng.uniform(0.7, 1.3, 4) * np.array([1.0, 0.3, 0.9, -0.4]) \
            + 2e-4 * rng.standard_normal(4)
        args = (1.3e-3, natural, 5e6 * 3.4e-3 ** 3 / 12)
        evaluate = lambda e: _call(_bend, e, 21, *args)  # noqa: E731
        out = evaluate(edges)
        step = 1e-6 * 1.3e-3
        _assert_close(out[1:5], _central_jacobian(lambda e: evaluate(e)[:1], edges, step)[0])
        hessian = out[5:].reshape(4, 4)
        _assert_close(hessian, _central_jacobian(lambda e: evaluate(e)[1:5], edges, step))
        np.testing.assert_allclose(hessian, hessian.T, atol=1e-12 * np.abs(hessian).max())


def test_bend_energy_matches_discrete_curvature(taichi_cpu):
    """κ = 2 tan(φ/2)/Δl: a turn by φ between equal edges gives E = ½B(κ − κ⁰)²Δl."""
    phi, length, voronoi, stiffness = 0.3, 1e-3, 1e-3, 2.0
    edges = np.array([length, 0.0, length * np.cos(phi), length * np.sin(phi)])
    energy = _call(_bend, edges, 21, voronoi, 0.0, stiffness)[0]
    curvature = 2 * np.tan(phi / 2) / voronoi
    assert energy == pytest.approx(0.5 * stiffness * curvature ** 2 * voronoi, rel=1e-12)


@pytest.mark.parametrize("velocity", [(0.02, 0.01), (-0.03, 0.005), (0.001, -0.04)])
def test_rod_drag_jacobians(taichi_cpu, velocity):
    edge = np.array([1.1e-3, 0.6e-3])
    inputs = np.array([*velocity, *edge])
    coeffs = (0.5 * 1000 * 1.3e-3 * 0.01, 0.5 * 1000 * 1.3e-3 * 1.0)
    evaluate = lambda x: _call(_rod_drag, x, 10, *coeffs)  # noqa: E731
    out = evaluate(inputs)
    jacobian = _central_jacobian(lambda x: evaluate(x)[:2], inputs, 1e-8)
    _assert_close(out[2:].reshape(2, 4)[:, :2], jacobian[:, :2])
    _assert_close(out[2:].reshape(2, 4)[:, 2:], jacobian[:, 2:])
    # the drag depends on the edge's direction alone: lengthening the edge along itself changes
    # nothing, so ∂F/∂e·e vanishes (to round-off of its entries, ~1e-16 of their size)
    d_edge = out[2:].reshape(2, 4)[:, 2:]
    np.testing.assert_allclose(d_edge @ edge, 0.0, atol=1e-14 * np.abs(d_edge).max() * 1.3e-3)
    speed_squared = np.dot(velocity, velocity)
    # drag opposes motion: the force does negative work
    assert np.dot(out[:2], velocity) < 0 < speed_squared


def test_cylinder_drag_jacobian(taichi_cpu):
    inputs = np.array([0.013, -0.021])
    evaluate = lambda x: _call(_cylinder_drag, x, 6, 150.0)  # noqa: E731
    out = evaluate(inputs)
    _assert_close(out[2:].reshape(2, 2), _central_jacobian(lambda x: evaluate(x)[:2], inputs, 1e-9))
    assert np.allclose(_call(_cylinder_drag, np.zeros(2), 6, 150.0), 0.0)


def _jet_points():
    # centre, joint k, tip k, tip k+1, joint k+1 of a slightly deformed star
    return np.array([0.001, -0.0005, 0.0222, -0.0092, 0.048, -0.0199, 0.0481, 0.0201,
                     0.0221, 0.0091])


def _quad_area(points):
    """S = ½|(x3 − x1) × (x4 − x2)| of the quad in `_jet_points` layout, m²."""
    x1, x2, x3, x4 = points[2:4], points[4:6], points[6:8], points[8:10]
    diagonal13, diagonal24 = x3 - x1, x4 - x2
    return 0.5 * abs(diagonal13[0] * diagonal24[1] - diagonal13[1] * diagonal24[0])


@pytest.mark.parametrize("always", [0, 1])
def test_jet_jacobian(taichi_cpu, always):
    points = _jet_points()
    x2, x3 = points[4:6], points[6:8]
    area = _quad_area(points)
    old_area = area * 1.001  # shrinking: the jet is on in both modes
    args = (old_area, 1e-3, 0.8, 1000.0, always, 0.0, jet.HUB_DIRECTION)
    evaluate = lambda x: _call_jet(x, *args)[:22]  # noqa: E731
    out = evaluate(points)
    jacobian = _central_jacobian(lambda x: evaluate(x)[:2], points, 1e-9)
    _assert_close(out[2:].reshape(2, 10), jacobian)
    rate = (area - old_area) / 1e-3
    expected = 1000.0 / np.linalg.norm(x2 - x3) * (0.8 * rate) ** 2
    assert np.linalg.norm(out[:2]) == pytest.approx(expected, rel=1e-12)
    reach = 0.5 * (x2 + x3) - points[:2]
    assert np.dot(out[:2], reach) < 0, "the jet pushes the centre away from the opening"


def test_jet_contract_mode_is_off_while_expanding(taichi_cpu):
    points = _jet_points()
    area = _quad_area(points)
    expanding = (area * 0.999, 1e-3, 0.8, 1000.0)
    assert np.all(_call_jet(points, *expanding, 0, 0.0, jet.HUB_DIRECTION) == 0.0)
    assert np.linalg.norm(_call_jet(points, *expanding, 1, 0.0, jet.HUB_DIRECTION)[:2]) > 0.0


def test_the_inflow_is_even_in_its_coefficient(taichi_cpu):
    """While a space opens the inflow pulls with α_in²: a sensitivities' replica about a small
    α_in may lie below 0, and its force must be the same there, not switched off (it was, at
    `inflow > 0`: the pair about α_in = 1e-6 gave 2.06 times the derivative: a review,
    2026-12). Exactly the same bits: the strength is α_in·α_in."""
    points = _jet_points()
    opening = (_quad_area(points) * 0.999, 1e-3, 0.8, 1000.0, 0)
    positive = _call_jet(points, *opening, 0.3, jet.HUB_DIRECTION)
    assert np.linalg.norm(positive[:2]) > 0.0
    np.testing.assert_array_equal(_call_jet(points, *opening, -0.3, jet.HUB_DIRECTION), positive)
    assert np.all(_call_jet(points, *opening, 0.0, jet.HUB_DIRECTION) == 0.0)


def _expected_direction(points, kind):
    """The jet's unit direction written out from the definitions (docs/model.md)."""
    centre, x1, x2, x3, x4 = points.reshape(5, 2)
    if kind == jet.HUB_DIRECTION:
        vector = 0.5 * (x2 + x3) - centre
    elif kind == jet.NORMAL_DIRECTION:
        opening = x3 - x2
        vector = np.array([opening[1], -opening[0]])  # the normal on the side away from the hub
        assert np.dot(vector, 0.5 * (x2 + x3) - centre) > 0
    else:
        vector = (x2 - x1) / np.linalg.norm(x2 - x1) + (x3 - x4) / np.linalg.norm(x3 - x4)
    return vector / np.linalg.norm(vector)


@pytest.mark.parametrize("kind", [jet.HUB_DIRECTION, jet.NORMAL_DIRECTION, jet.BISECTOR_DIRECTION])
@pytest.mark.parametrize("shrink", [1.001, 0.999])
def test_jet_and_inflow_directions_values_and_jacobians(taichi_cpu, kind, shrink):
    """Each direction, while the space closes (the jet, along −t) and while it opens (the
    inflow α_in = 0.5, along +t, contract mode): the force is ∓(ρ_f/L)(αṠ)²·t with t from its
    definition, and the derivatives by the positions and by Ṡ match central differences."""
    points = _jet_points()
    area = _quad_area(points)
    old_area = area * shrink
    args = (old_area, 1e-3, 0.8, 1000.0, 0, 0.5, kind)
    evaluate = lambda x: _call_jet(x, *args)[:22]  # noqa: E731
    out = evaluate(points)
    _assert_close(out[2:].reshape(2, 10), _central_jacobian(lambda x: evaluate(x)[:2], points, 1e-9))
    # Ṡ = (S − S_old)/dt, so ∂f/∂Ṡ = −dt·∂f/∂S_old; f is quadratic in Ṡ (on one side of 0,
    # which a step of 1e-6·S_old does not cross: Ṡ is ±1e-3·S/dt), so the difference is exact
    # up to rounding
    by_old_area = _central_jacobian(lambda old: _call_jet(points, old[0], *args[1:])[:2],
                                    np.array([old_area]), 1e-6 * old_area)[:, 0]
    _assert_close(_call_jet(points, *args)[22:], -1e-3 * by_old_area)
    rate = (area - old_area) / 1e-3
    ratio, sense = (0.8, -1.0) if rate < 0 else (0.5, 1.0)
    expected = sense * 1000.0 / np.linalg.norm(points[4:6] - points[6:8]) * (ratio * rate) ** 2 \
        * _expected_direction(points, kind)
    np.testing.assert_allclose(out[:2], expected, rtol=1e-12)


def test_inflow_is_off_while_closing_and_zero_inflow_changes_nothing(taichi_cpu):
    """α_in acts only while the space opens: closing, the force is the jet's to the last bit;
    opening with α_in = 0, nothing (as without the option)."""
    points = _jet_points()
    area = _quad_area(points)
    closing = (area * 1.001, 1e-3, 0.8, 1000.0, 0)
    np.testing.assert_array_equal(_call_jet(points, *closing, 0.7, jet.HUB_DIRECTION),
                                  _call_jet(points, *closing, 0.0, jet.HUB_DIRECTION))
    opening = (area * 0.999, 1e-3, 0.8, 1000.0, 0, 0.0, jet.BISECTOR_DIRECTION)
    assert np.all(_call_jet(points, *opening) == 0.0)


def test_the_three_directions_coincide_in_the_rest_shape(taichi_cpu):
    """At rest the limbs are radial and the opening's midpoint lies on the space's bisector, so
    hub, normal and bisector all give the radial unit vector through the midpoint."""
    from taichi_star.geometry import build_topology
    from taichi_star.params import StarParams

    topology = build_topology(StarParams())
    quad = topology.jet_quads[3]
    points = np.concatenate([topology.rest_positions[0], topology.rest_positions[quad].reshape(-1)])
    area = _quad_area(points)
    forces = [_call_jet(points, area * 1.001, 1e-3, 0.8, 1000.0, 0, 0.0, kind)[:2]
              for kind in (jet.HUB_DIRECTION, jet.NORMAL_DIRECTION, jet.BISECTOR_DIRECTION)]
    # the rest shape is built by rounding cosines: the directions agree to ~1e-15
    np.testing.assert_allclose(forces[1], forces[0], rtol=1e-12, atol=1e-12 * np.abs(forces[0]).max())
    np.testing.assert_allclose(forces[2], forces[0], rtol=1e-12, atol=1e-12 * np.abs(forces[0]).max())
