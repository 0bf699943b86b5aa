"""The rest shape and the tables of `geometry.build_topology`, checked node by node against
what the robot is (a hub, eight straight limbs on rays 45° apart, eight circular arcs of the
actuators' rest curvature bulging inwards from joint to joint), each table recomputed here by
loops over its own definition rather than by the module's array expressions."""

import math

import numpy as np
import pytest

from taichi_star import StarParams
from taichi_star.geometry import (ARC, ARC_BEND, CENTRE, JOINT_BEND, LIMB, LIMB_BEND, SPOKE,
                                  build_topology)

SHAPES = [StarParams(), StarParams(n_arc=3, n_limb=2, joint_radius=0.02, tip_radius=0.06)]


@pytest.fixture(params=SHAPES, ids=["paper", "coarse"])
def shape(request):
    return request.param, build_topology(request.param)


def test_counts_of_nodes_edges_and_triplets(shape):
    params, topology = shape
    n_arc, n_limb = params.n_arc, params.n_limb
    assert topology.n_nodes == 1 + 8 * (n_limb + n_arc)      # hub; per actuator J, limb, arc
    # the count the studies read without building a topology (convergence's table)
    assert params.n_nodes == topology.n_nodes == len(topology.rest_positions)
    assert StarParams.node_count(np.array([n_arc, 2 * n_arc]), n_limb).tolist() == [
        topology.n_nodes, topology.n_nodes + 8 * n_arc]
    assert topology.n_edges == 8 * (1 + n_limb + n_arc)      # spoke, limb edges, arc edges
    assert topology.n_triplets == 8 * ((n_limb - 1) + 2 + (n_arc - 1))
    assert np.bincount(topology.edge_kind, minlength=3).tolist() == [8, 8 * n_limb, 8 * n_arc]
    assert np.bincount(topology.triplet_kind, minlength=3).tolist() == [
        8 * (n_limb - 1), 16, 8 * (n_arc - 1)]
    assert topology.limbs.shape == (8, n_limb + 1) and topology.arcs.shape == (8, n_arc + 1)


def test_joints_and_limbs_lie_on_rays_45_degrees_apart(shape):
    """Joint J_k at the joint radius on the ray at −22.5° + 45°·k, its limb's nodes equally
    spaced along that ray out to the tip radius (1e-15 m: a few roundings of cos, sin)."""
    params, topology = shape
    positions = topology.rest_positions
    np.testing.assert_array_equal(positions[CENTRE], [0.0, 0.0])
    for k in range(8):
        angle = math.radians(-22.5 + 45.0 * k)
        ray = np.array([math.cos(angle), math.sin(angle)])
        limb = topology.limbs[k]
        assert limb[0] == topology.joints[k] and limb[-1] == topology.tips[k]
        radii = params.joint_radius + (params.tip_radius - params.joint_radius) * np.arange(
            params.n_limb + 1) / params.n_limb
        np.testing.assert_allclose(positions[limb], radii[:, None] * ray, rtol=0, atol=1e-15)


def test_arcs_are_circles_of_the_rest_curvature_bulging_inwards(shape):
    """Each arc runs from J_k to J_{k+1} through points equally spaced on one circle of radius
    1/K̄(0), whose centre lies outside the chord (the arc bulges towards the hub)."""
    params, topology = shape
    positions, radius = topology.rest_positions, 1.0 / params.actuator_profile.rest_curvature
    for k in range(8):
        arc = topology.arcs[k]
        assert arc[0] == topology.joints[k] and arc[-1] == topology.joints[(k + 1) % 8]
        points = positions[arc]
        chords = np.linalg.norm(np.diff(points, axis=0), axis=1)
        np.testing.assert_allclose(chords, chords[0], rtol=1e-12)
        # the circle through the first, middle and last points: its radius and centre
        a, b, c = points[0], points[len(points) // 2], points[-1]
        d = 2 * (a[0] * (b[1] - c[1]) + b[0] * (c[1] - a[1]) + c[0] * (a[1] - b[1]))
        centre = np.array([
            (a @ a * (b[1] - c[1]) + b @ b * (c[1] - a[1]) + c @ c * (a[1] - b[1])) / d,
            (a @ a * (c[0] - b[0]) + b @ b * (a[0] - c[0]) + c @ c * (b[0] - a[0])) / d])
        np.testing.assert_allclose(np.linalg.norm(points - centre, axis=1), radius, rtol=1e-9)
        chord_middle = 0.5 * (points[0] + points[-1])
        assert np.linalg.norm(centre) > np.linalg.norm(chord_middle)      # centre outside
        assert np.linalg.norm(b) < np.linalg.norm(chord_middle)          # the bulge inwards


def test_edges_join_the_nodes_of_each_part_in_order(shape):
    _, topology = shape
    expected = []
    for k in range(8):
        limb, arc = topology.limbs[k], topology.arcs[k]
        expected.append(((CENTRE, topology.joints[k]), SPOKE))
        expected += [((limb[i], limb[i + 1]), LIMB) for i in range(len(limb) - 1)]
        expected += [((arc[i], arc[i + 1]), ARC) for i in range(len(arc) - 1)]
    assert [tuple(edge) for edge in topology.edges.tolist()] == [e for e, _ in expected]
    assert topology.edge_kind.tolist() == [kind for _, kind in expected]
    for (a, b), length in zip(topology.edges, topology.rest_length):
        assert length == pytest.approx(math.dist(topology.rest_positions[a],
                                                 topology.rest_positions[b]), rel=1e-15)


def test_triplets_their_actuators_and_voronoi_lengths(shape):
    """Limb triplets bend the limb's inner nodes (no actuator); two joint triplets per joint
    join the limb's first edge to the incoming arc (A_k, index k − 1) and to the outgoing one
    (index k); arc triplets bend the arc's inner nodes under their actuator. A triplet's
    Voronoi length is half its two edges."""
    _, topology = shape
    positions = topology.rest_positions
    by_node = {}
    for t, (i, j, k) in enumerate(topology.triplets):
        kind = topology.triplet_kind[t]
        half = 0.5 * (math.dist(positions[i], positions[j]) + math.dist(positions[j], positions[k]))
        assert topology.voronoi_length[t] == pytest.approx(half, rel=1e-15)
        by_node.setdefault(j, []).append((kind, topology.triplet_actuator[t],
                                          topology.joint_actuator[t], i, k))
    for m in range(8):
        limb, arc, joint = topology.limbs[m], topology.arcs[m], topology.joints[m]
        for node in limb[1:-1]:
            assert by_node[node] == [(LIMB_BEND, -1, -1, limb[list(limb).index(node) - 1],
                                      limb[list(limb).index(node) + 1])]
        for node in arc[1:-1]:
            (kind, actuator, clamp, _, _), = by_node[node]
            assert (kind, actuator, clamp) == (ARC_BEND, m, -1)
        incoming = topology.arcs[(m - 1) % 8][-2]
        assert by_node[joint] == [(JOINT_BEND, -1, (m - 1) % 8, incoming, limb[1]),
                                  (JOINT_BEND, -1, m, arc[1], limb[1])]


def test_curvatures_and_the_joints_end_turning(shape):
    """Limbs are straight (κ⁰ = 0); every arc triplet has one curvature, of one sign; a joint
    triplet turns by ±½ the rest length of its arc's end edge: + (the arc's sign) for the
    incoming arc, walked along, − for the outgoing one, walked backwards; 0 for the others."""
    _, topology = shape
    kinds, curvature = topology.triplet_kind, topology.rest_curvature
    np.testing.assert_allclose(curvature[kinds == LIMB_BEND], 0.0, atol=1e-9)
    arc_curvature = curvature[kinds == ARC_BEND]
    np.testing.assert_allclose(arc_curvature, arc_curvature[0], rtol=1e-9)
    sign = math.copysign(1.0, arc_curvature[0])
    positions = topology.rest_positions
    for t, (i, j, k) in enumerate(topology.triplets):
        if kinds[t] != JOINT_BEND:
            assert topology.end_turning_length[t] == 0.0
            continue
        incoming = topology.joint_actuator[t] == (list(topology.joints).index(j) - 1) % 8
        expected = (1.0 if incoming else -1.0) * sign * 0.5 * math.dist(positions[i], positions[j])
        assert topology.end_turning_length[t] == pytest.approx(expected, rel=1e-15)


def test_lumped_lengths_and_jet_spaces(shape):
    """Each node carries half of each arc edge and each limb edge it ends (spokes: nothing), so
    the columns sum to the arcs' and the limbs' total lengths; the space of actuator A_{k+1}
    is bounded by J_k, limb k's tip, limb k+1's tip and J_{k+1}."""
    _, topology = shape
    lumped = np.zeros_like(topology.lumped_length)
    for (a, b), kind, length in zip(topology.edges, topology.edge_kind, topology.rest_length):
        if kind in (ARC, LIMB):
            lumped[[a, b], 0 if kind == ARC else 1] += 0.5 * length
    np.testing.assert_allclose(topology.lumped_length, lumped, rtol=1e-15)
    for column, kind in ((0, ARC), (1, LIMB)):
        assert topology.lumped_length[:, column].sum() == pytest.approx(
            topology.rest_length[topology.edge_kind == kind].sum(), rel=1e-14)
    for k in range(8):
        assert topology.jet_quads[k].tolist() == [
            topology.joints[k], topology.tips[k], topology.tips[(k + 1) % 8],
            topology.joints[(k + 1) % 8]]


def test_index_tables_are_int32_as_the_engine_takes_them(shape):
    """The engine copies these into int32 Taichi fields; another integer width would be cast
    (or refused) on the way."""
    _, topology = shape
    for name in ("edges", "edge_kind", "triplets", "triplet_kind", "triplet_actuator",
                 "joint_actuator", "jet_quads", "limbs", "arcs"):
        assert getattr(topology, name).dtype == np.int32, name
