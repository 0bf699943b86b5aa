"""Topology and rest shape of the star robot, in NumPy.

Node numbering: node 0 is the centre c; then, for each joint k = 0..7, a block of
1 + n_limb + (n_arc - 1) nodes: the joint J_k, its limb nodes from the joint outwards (the tip
last), and the interior nodes of actuator A_{k+1}'s arc from J_k towards J_{k+1}.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .gait import N_ACTUATORS
from .params import StarParams

CENTRE = 0
"""Node number of the hub (the central cylinder)."""
SPOKE, LIMB, ARC = 0, 1, 2
"""Edge kinds. Spokes (centre–joint) are stiff, massless and feel no drag."""
LIMB_BEND, JOINT_BEND, ARC_BEND = 0, 1, 2
"""Triplet kinds. Limb and joint triplets use E_limb; arc triplets use E and may be actuated."""


def edge_curvature(e1x, e1y, e2x, e2y, length1, length2, voronoi_length):
    """Signed κ = 2 (e1 × e2) / ((|e1||e2| + e1·e2) Δl), 1/m, of two consecutive edges given by
    their components and lengths (m; arrays that broadcast): the one formula of
    `discrete_curvature` and of the shape checks, which compute each edge once for the two
    nodes it joins."""
    return 2.0 * (e1x * e2y - e1y * e2x) / ((length1 * length2 + (e1x * e2x + e1y * e2y))
                                            * voronoi_length)


def discrete_curvature(x_prev, x_mid, x_next, voronoi_length):
    """Signed κ (`edge_curvature`), 1/m, at x_mid; arrays of shape (..., 2)."""
    e1 = x_mid - x_prev
    e2 = x_next - x_mid
    return edge_curvature(e1[..., 0], e1[..., 1], e2[..., 0], e2[..., 1],
                          np.linalg.norm(e1, axis=-1), np.linalg.norm(e2, axis=-1),
                          voronoi_length)


@dataclass(frozen=True)
class Topology:
    """The shared structure of a batch. Shapes: N nodes, E edges, T triplets; lengths in m."""

    rest_positions: np.ndarray
    """(N, 2) rest shape, m."""
    edges: np.ndarray
    """(E, 2) int32 node pairs."""
    edge_kind: np.ndarray
    """(E,) SPOKE / LIMB / ARC."""
    rest_length: np.ndarray
    """(E,) Δl̄, m."""
    triplets: np.ndarray
    """(T, 3) int32 (i, j, k): the bending angle at node j."""
    triplet_kind: np.ndarray
    """(T,) LIMB_BEND / JOINT_BEND / ARC_BEND."""
    triplet_actuator: np.ndarray
    """(T,) actuator index m - 1 (0..7) of arc triplets that the actuation drives; -1 otherwise."""
    joint_actuator: np.ndarray
    """(T,) for a joint triplet, the actuator index (0..7) whose arc end it clamps; -1 otherwise."""
    end_turning_length: np.ndarray
    """(T,) for a joint triplet, ±½ the rest length of the clamped arc's end edge, m, signed so
    that a change ΔK of the arc's natural curvature turns the joint's natural angle by
    end_turning_length·ΔK and the limb keeps its angle to the tangent of the arc's circle at
    the joint (the end chord lies half an edge's turning, ½Δl·K, inside that tangent); 0 for
    other triplets."""
    rest_curvature: np.ndarray
    """(T,) signed discrete rest curvature κ⁰, 1/m."""
    voronoi_length: np.ndarray
    """(T,) Δl_j = ½(|ē1| + |ē2|), m."""
    jet_quads: np.ndarray
    """(8, 4) int32 (J_k, tip_k, tip_{k+1}, J_{k+1}): inter-limb space of actuator A_{k+1}."""
    joints: np.ndarray
    """(8,) node of J_k."""
    tips: np.ndarray
    """(8,) node of limb k's tip."""
    lumped_length: np.ndarray
    """(N, 2) rest length lumped at each node from its arc edges [:, 0] and limb edges [:, 1]."""
    limbs: np.ndarray
    """(8, n_limb + 1) nodes of limb k from its joint J_k to its tip."""
    arcs: np.ndarray
    """(8, n_arc + 1) nodes of actuator A_{k+1}'s arc from J_k to J_{k+1}."""

    @property
    def n_nodes(self) -> int:
        return len(self.rest_positions)

    @property
    def n_edges(self) -> int:
        return len(self.edges)

    @property
    def n_triplets(self) -> int:
        return len(self.triplets)


def build_topology(params: StarParams) -> Topology:
    """Topology and rest shape for the geometric fields of `params` (n_arc, n_limb, the radii
    and the actuators' rest curvature)."""
    n_arc, n_limb = params.n_arc, params.n_limb
    block = 1 + n_limb + (n_arc - 1)
    joints = np.array([1 + k * block for k in range(N_ACTUATORS)])
    limb_nodes = [[joints[k] + 1 + i for i in range(n_limb)] for k in range(N_ACTUATORS)]
    arc_nodes = [[joints[k] + 1 + n_limb + i for i in range(n_arc - 1)] for k in range(N_ACTUATORS)]
    positions = np.zeros((1 + N_ACTUATORS * block, 2))

    joint_angle = np.radians(-22.5 + 45.0 * np.arange(N_ACTUATORS))
    radial = np.stack([np.cos(joint_angle), np.sin(joint_angle)], axis=1)
    positions[joints] = params.joint_radius * radial
    for k in range(N_ACTUATORS):
        radii = np.linspace(params.joint_radius, params.tip_radius, n_limb + 1)[1:]
        positions[limb_nodes[k]] = radii[:, None] * radial[k]
        positions[arc_nodes[k]] = _inward_arc(positions[joints[k]],
                                              positions[joints[(k + 1) % N_ACTUATORS]],
                                              params.actuator_profile.rest_curvature, n_arc)[1:-1]

    edges, edge_kind = [], []
    triplets, triplet_kind, triplet_actuator, joint_actuator = [], [], [], []
    clamped_end_edges = []
    for k in range(N_ACTUATORS):
        joint, next_joint = joints[k], joints[(k + 1) % N_ACTUATORS]
        limb = [joint] + limb_nodes[k]
        arc = [joint] + arc_nodes[k] + [next_joint]
        edges.append((0, joint))
        edge_kind.append(SPOKE)
        edges += list(zip(limb[:-1], limb[1:]))
        edge_kind += [LIMB] * n_limb
        edges += list(zip(arc[:-1], arc[1:]))
        edge_kind += [ARC] * n_arc
        triplets += [tuple(limb[i - 1:i + 2]) for i in range(1, n_limb)]
        triplet_kind += [LIMB_BEND] * (n_limb - 1)
        triplet_actuator += [-1] * (n_limb - 1)
        joint_actuator += [-1] * (n_limb - 1)
        clamped_end_edges += [None] * (n_limb - 1)
        incoming_arc_node = arc_nodes[(k - 1) % N_ACTUATORS][-1]
        triplets += [(incoming_arc_node, joint, limb[1]), (arc_nodes[k][0], joint, limb[1])]
        triplet_kind += [JOINT_BEND] * 2
        triplet_actuator += [-1] * 2
        # the incoming arc is traversed along its own direction, the outgoing one against it
        joint_actuator += [(k - 1) % N_ACTUATORS, k]
        clamped_end_edges += [(incoming_arc_node, joint, 1.0), (joint, arc_nodes[k][0], -1.0)]
        triplets += [tuple(arc[i - 1:i + 2]) for i in range(1, n_arc)]
        triplet_kind += [ARC_BEND] * (n_arc - 1)
        triplet_actuator += [k] * (n_arc - 1)
        joint_actuator += [-1] * (n_arc - 1)
        clamped_end_edges += [None] * (n_arc - 1)

    edges = np.array(edges, dtype=np.int32)
    edge_kind = np.array(edge_kind, dtype=np.int32)
    triplets = np.array(triplets, dtype=np.int32)
    rest_length = np.linalg.norm(positions[edges[:, 1]] - positions[edges[:, 0]], axis=1)
    voronoi = 0.5 * (np.linalg.norm(positions[triplets[:, 1]] - positions[triplets[:, 0]], axis=1)
                     + np.linalg.norm(positions[triplets[:, 2]] - positions[triplets[:, 1]], axis=1))
    rest_curvature = discrete_curvature(positions[triplets[:, 0]], positions[triplets[:, 1]],
                                        positions[triplets[:, 2]], voronoi)

    triplet_actuator = np.array(triplet_actuator, dtype=np.int32)
    arc_sign = np.sign(rest_curvature[triplet_actuator >= 0][0])
    # Walking along an arc of signed curvature c, an edge's chord points half the edge's turning,
    # ½Δl·c, behind the tangent at the edge's far end. A joint triplet walks the end edge into the
    # joint, with c = +arc_sign·K on the incoming arc and −arc_sign·K on the outgoing one (walked
    # backwards); its turning angle from that chord to the limb must grow by ½Δl·Δc to keep the
    # limb's angle to the tangent.
    end_turning = np.array([0.0 if end is None else end[2] * arc_sign * 0.5
                            * np.linalg.norm(positions[end[1]] - positions[end[0]])
                            for end in clamped_end_edges])

    lumped = np.zeros((len(positions), 2))
    for (a, b), kind, length in zip(edges, edge_kind, rest_length):
        if kind != SPOKE:
            column = 0 if kind == ARC else 1
            lumped[a, column] += 0.5 * length
            lumped[b, column] += 0.5 * length

    tips = np.array([limb_nodes[k][-1] for k in range(N_ACTUATORS)])
    jet_quads = np.array([(joints[k], tips[k], tips[(k + 1) % N_ACTUATORS],
                           joints[(k + 1) % N_ACTUATORS]) for k in range(N_ACTUATORS)],
                         dtype=np.int32)
    return Topology(
        rest_positions=positions, edges=edges, edge_kind=edge_kind, rest_length=rest_length,
        triplets=triplets, triplet_kind=np.array(triplet_kind, dtype=np.int32),
        triplet_actuator=triplet_actuator,
        joint_actuator=np.array(joint_actuator, dtype=np.int32), end_turning_length=end_turning,
        rest_curvature=rest_curvature, voronoi_length=voronoi, jet_quads=jet_quads,
        joints=joints, tips=tips, lumped_length=lumped,
        limbs=np.array([[joints[k]] + limb_nodes[k] for k in range(N_ACTUATORS)], dtype=np.int32),
        arcs=np.array([[joints[k]] + arc_nodes[k] + [joints[(k + 1) % N_ACTUATORS]]
                       for k in range(N_ACTUATORS)], dtype=np.int32))


def _inward_arc(start, end, curvature, n_edges):
    """(n_edges + 1, 2) points of the circular arc of `curvature` from start to end whose bulge
    points towards the origin (the minor arc, centre on the outer side of the chord)."""
    radius = 1.0 / curvature
    chord = end - start
    half_chord = 0.5 * np.linalg.norm(chord)
    midpoint = 0.5 * (start + end)
    outward = midpoint / np.linalg.norm(midpoint)
    # a joint_radius just under its bound makes the arc a half circle, radius = half_chord,
    # where rounding can leave the difference a few ulps below zero
    centre = midpoint + math.sqrt(max(radius ** 2 - half_chord ** 2, 0.0)) * outward
    angle_start = math.atan2(*(start - centre)[::-1])
    sweep = math.atan2(*(end - centre)[::-1]) - angle_start
    sweep = (sweep + math.pi) % (2 * math.pi) - math.pi
    angles = angle_start + sweep * np.linspace(0.0, 1.0, n_edges + 1)
    return centre + radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)
