"""Swimming metrics: centroid, body rotation, whole-run and cycle-window speeds; shape checks
(limb crossing, arc inversion, strain).

Conventions: the centroid is the mass-weighted mean of the node positions (added mass excluded);
"forward" is the unit sum of the fired actuators' bisectors; a signed speed is the displacement
projected on it; the heading (body rotation) is the mean rotation of the eight hub-to-joint
directions from their rest angles. Lengths in mm and times in s in every returned column.
"""

from __future__ import annotations

from typing import Dict, Optional, Sequence

import numpy as np
import pandas as pd

from .checks import check_finite, is_whole
from .gait import Gait
from .geometry import CENTRE, Topology, edge_curvature

# every public name: docs/api.md documents the whole module
__all__ = ["METERS_TO_MM", "HUB_NODE", "MAX_GOAL_MM", "SPEED_COLUMNS", "centroid", "rotate",
           "wrap_degrees", "body_rotation", "forward_directions", "swimming_metrics",
           "cycle_window_speeds",
           "SPEED_ERROR_FLOOR_MM_S", "speed_error", "observed_order", "richardson_limit",
           "STRAIN_LIMIT", "PARALLEL_TOLERANCE", "segments_cross", "CROSSING_SLICE", "BOX_MARGIN",
           "ORDINARY_SCALE", "limbs_cross", "arc_mean_curvature", "arcs_inverted", "edge_lengths",
           "edge_strain", "SHAPE_SLICE", "shape_checks"]

METERS_TO_MM = 1e3
HUB_NODE = CENTRE
"""Index of the hub (the central cylinder) among a shape's nodes:
`SimulationResult.shapes[..., HUB_NODE, :]` is its position, m."""
MAX_GOAL_MM = 1e3
"""Largest goal distance an environment's task or a plan may ask for, mm (a metre: ~100 body
lengths, tens of minutes of swimming)."""
SPEED_COLUMNS = ("displacement_x_mm", "displacement_y_mm", "speed_mm_s", "signed_speed_mm_s",
                 "travel_direction_deg")
"""Columns of `swimming_metrics`."""


def centroid(positions: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """Mass-weighted mean of node positions: positions (..., N, 2), mass (..., N) (leading axes
    that broadcast against the positions') -> (..., 2). ValueError naming both shapes where
    they do not fit."""
    positions, mass = np.asarray(positions), np.asarray(mass)
    try:
        fits = (positions.ndim >= 2 and positions.shape[-1] == 2 and mass.ndim >= 1
                and mass.shape[-1] == positions.shape[-2]
                and np.broadcast_shapes(positions.shape[:-1], mass.shape) == positions.shape[:-1])
    except ValueError:
        fits = False
    if not fits:
        raise ValueError(f"positions must be (..., N, 2) and mass (..., N), got positions "
                         f"{positions.shape} and mass {mass.shape}")
    return (positions * mass[..., None]).sum(-2) / mass.sum(-1)[..., None]


def rotate(vectors: np.ndarray, angle_rad) -> np.ndarray:
    """(..., 2) vectors turned counter-clockwise by angle_rad (rad; a scalar or an array that
    broadcasts against the vectors' leading axes). ValueError where the vectors' last axis is
    not 2 (a third component was dropped: an audit)."""
    vectors = np.asarray(vectors)
    if vectors.ndim < 1 or vectors.shape[-1] != 2:
        raise ValueError(f"vectors must be (..., 2), got shape {vectors.shape}")
    cos, sin = np.cos(angle_rad), np.sin(angle_rad)
    return np.stack([cos * vectors[..., 0] - sin * vectors[..., 1],
                     sin * vectors[..., 0] + cos * vectors[..., 1]], axis=-1)


def wrap_degrees(angle, include_180: bool = False):
    """Angles (deg, any shape) wrapped to [-180, 180) (+180 and every odd multiple go to -180),
    or with `include_180` to (-180, 180] (they go to +180: the gaits table's directions, where
    a gait travelling straight back reads 180); NaN and ±inf give NaN. ValueError for angles
    that are not real numbers."""
    angle = np.asarray(angle)
    if angle.dtype.kind not in "biuf":
        raise ValueError(f"angle must be real numbers (deg), got {angle.dtype} values")
    with np.errstate(invalid="ignore"):  # ±inf % 360 is NaN, as documented, not a warning
        wrapped = (angle + 180.0) % 360.0 - 180.0
    # (x + 180) % 360 rounds to 360 for an x a hair below -180 (-180.00000000000003 gave +180;
    # an audit, 2026-12)
    wrapped = np.where(wrapped >= 180.0, wrapped - 360.0, wrapped)
    return np.where(wrapped == -180.0, 180.0, wrapped) if include_180 else wrapped


def body_rotation(positions: np.ndarray, rest_positions: np.ndarray, joints: np.ndarray,
                  hub: int = 0) -> np.ndarray:
    """Heading: rotation (rad, counter-clockwise, in (−π, π]) of the body from its rest
    orientation, the circular mean of the hub-to-joint directions' rotations. positions and
    rest_positions (..., N, 2); returns (...)."""
    now = positions[..., joints, :] - positions[..., hub:hub + 1, :]
    rest = rest_positions[..., joints, :] - rest_positions[..., hub:hub + 1, :]
    turn = (np.arctan2(now[..., 1], now[..., 0]) - np.arctan2(rest[..., 1], rest[..., 0]))
    heading = np.arctan2(_ordered_sum(np.sin(turn)), _ordered_sum(np.cos(turn)))
    # arctan2(−0.0, x < 0) is −π, outside (−π, π]: a body turned by half a turn read −π or π
    # by the sign of a zero (an audit, 2026-12)
    return np.where(heading == -np.pi, np.pi, heading)


def _ordered_sum(values: np.ndarray) -> np.ndarray:
    """Sum over the last axis in index order: NumPy's reductions sum in an order that depends on
    the array's shape, so an instance's metrics would change in the last bit with the size of
    its batch."""
    total = values[..., 0].copy()
    for k in range(1, values.shape[-1]):
        total += values[..., k]
    return total


def forward_directions(gaits: Sequence[str]) -> np.ndarray:
    """(B, 2) forward unit vectors of the gaits, NaN where undefined."""
    # once per distinct gait: a batch of thousands names a few
    by_gait = {}
    for gait in set(gaits):
        forward = Gait.parse(gait).forward
        by_gait[gait] = (np.nan, np.nan) if forward is None else forward
    return np.array([by_gait[gait] for gait in gaits], dtype=np.float64).reshape(-1, 2)


def swimming_metrics(displacement_m: np.ndarray, duration_s, gaits: Sequence[str]) -> Dict[str, np.ndarray]:
    """Per-instance metrics of centroid displacements (B, 2) m over duration_s (scalar or (B,)).

    Returns `SPEED_COLUMNS`, each (B,): displacement_x_mm, displacement_y_mm, speed_mm_s
    (|displacement|/duration), signed_speed_mm_s (projection on the gait's forward direction,
    NaN where that is undefined) and travel_direction_deg (direction of the displacement,
    counter-clockwise from +x, the bisector of A1)."""
    displacement_mm = np.asarray(displacement_m, dtype=np.float64) * METERS_TO_MM
    signed = (displacement_mm * forward_directions(gaits)).sum(axis=1)
    return {
        "displacement_x_mm": displacement_mm[:, 0],
        "displacement_y_mm": displacement_mm[:, 1],
        "speed_mm_s": np.hypot(displacement_mm[:, 0], displacement_mm[:, 1]) / duration_s,
        "signed_speed_mm_s": signed / duration_s,
        "travel_direction_deg": np.degrees(np.arctan2(displacement_mm[:, 1], displacement_mm[:, 0])),
    }


def cycle_window_speeds(boundary_centroids_m: np.ndarray, periods: np.ndarray, gaits: Sequence[str],
                        first_cycle: int) -> Dict[str, np.ndarray]:
    """Speeds over the cycles [first_cycle, last) from the centroids at the cycle boundaries.

    boundary_centroids_m: (B, C + 1, 2) centroid at t = 0, T, ..., C·T (m; NaN where not
    recorded); periods (B,) s. `last` is each instance's last recorded boundary. Returns
    steady_speed_mm_s and steady_signed_speed_mm_s (B,), NaN where fewer than one cycle after
    first_cycle was recorded. ValueError for a first_cycle that is not a whole number >= 0 (-1
    counted from the end, a speed of 0: an audit)."""
    if not is_whole(first_cycle) or first_cycle < 0:
        raise ValueError(f"first_cycle must be a whole number >= 0, got {first_cycle!r}")
    first_cycle = int(first_cycle)
    batch, n_boundaries = boundary_centroids_m.shape[:2]
    recorded = np.isfinite(boundary_centroids_m).all(axis=2)
    last = np.where(recorded.any(axis=1), n_boundaries - 1 - np.argmax(recorded[:, ::-1], axis=1), -1)
    usable = (last > first_cycle) & (first_cycle < n_boundaries)
    if first_cycle < n_boundaries:
        usable &= recorded[:, first_cycle]
    speed = np.full(batch, np.nan)
    signed = np.full(batch, np.nan)
    if usable.any():
        rows = np.flatnonzero(usable)
        delta = (boundary_centroids_m[rows, last[rows]] - boundary_centroids_m[rows, first_cycle]) * METERS_TO_MM
        span = (last[rows] - first_cycle) * np.asarray(periods, dtype=np.float64)[rows]
        speed[rows] = np.hypot(delta[:, 0], delta[:, 1]) / span
        signed[rows] = (delta * forward_directions([gaits[r] for r in rows])).sum(axis=1) / span
    return {"steady_speed_mm_s": speed, "steady_signed_speed_mm_s": signed}


# --------------------------------------------------------------------------- errors, extrapolation

SPEED_ERROR_FLOOR_MM_S = 0.5
"""Smallest speed scale of `speed_error`, mm/s (the design's §3): a relative error against a
near-zero reference would be a ratio of round-off."""


def speed_error(speed_mm_s, reference_mm_s, floor_mm_s: float = SPEED_ERROR_FLOOR_MM_S):
    """|v − v_ref| / max(|v_ref|, floor), speeds in mm/s (arrays broadcast; NaN stays NaN).
    The default floor is the design's 0.5 mm/s; floor_mm_s = 0 gives the plain relative error
    |v − v_ref| / |v_ref|. ValueError for a negative or non-finite floor."""
    check_finite("floor_mm_s", floor_mm_s, 0.0, lowest_included=True)
    reference = np.asarray(reference_mm_s, dtype=np.float64)
    return np.abs(np.asarray(speed_mm_s, dtype=np.float64) - reference) / np.maximum(
        np.abs(reference), floor_mm_s)


def observed_order(coarse_change, fine_change, refinement: float = 2.0):
    """Observed order of convergence of a ladder refined by `refinement` per level, from the
    change between its two coarser levels and the change between its two finer ones (arrays
    broadcast): log(coarse_change / fine_change) / log(refinement). NaN where the changes
    differ in sign or one is zero (no monotone convergence to read an order from). ValueError
    for a refinement that is not a number > 1."""
    _check_refinement(refinement)
    coarse_change = np.asarray(coarse_change, dtype=np.float64)
    fine_change = np.asarray(fine_change, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        order = np.log(coarse_change / fine_change) / np.log(refinement)
    return np.where(coarse_change * fine_change > 0, order, np.nan)


def richardson_limit(middle, fine, order, refinement: float = 2.0):
    """Richardson extrapolation of a quantity computed on two levels refined by `refinement`,
    its error ∝ (level size)^order: v_f + (v_f − v_m) / (refinement^order − 1) (arrays
    broadcast). NaN where the order is NaN or not > 0: a ladder whose changes grow diverges,
    and the formula put its "limit" on the far side of both levels (order −2) or at infinity
    (order 0; an audit, 2026-12). ValueError for a refinement that is not a number > 1."""
    _check_refinement(refinement)
    fine = np.asarray(fine, dtype=np.float64)
    order = np.asarray(order, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        limit = fine + (fine - np.asarray(middle, dtype=np.float64)) / (
            refinement ** order - 1.0)
    return np.where(order > 0, limit, np.nan)


def _check_refinement(refinement):
    """ValueError unless the refinement per level is a finite number > 1 (1 gave inf, 0.5 a
    negative order)."""
    check_finite("refinement", refinement, 1.0)


# --------------------------------------------------------------------------- shape checks

STRAIN_LIMIT = 0.5
"""|ε| above this is not sane: the linear stretching energy is a small-strain model."""
PARALLEL_TOLERANCE = 1e-9
"""Segments whose directions differ by less than ~1e-9 rad are treated as parallel: the
intersection parameters of (near-)parallel segments are rounding noise (opposite limbs of a
symmetric shape are collinear, and a plain orientation test finds them 'crossing' by rounding)."""


def _cross(a, b):
    """2-D cross product a × b over the last axis."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _norm(dx, dy):
    """|(dx, dy)|: np.linalg.norm over a last axis of two, bitwise (NumPy's is the square root
    of the sum of the squares; np.hypot rounds differently), on separate component arrays,
    which is several times faster than on (..., 2) vectors."""
    return np.sqrt(dx * dx + dy * dy)


def segments_cross(p, q, r, s) -> np.ndarray:
    """Segments p–q and r–s (arrays (..., 2)) -> (...) bool: they cross. Non-parallel segments
    cross where both intersection parameters lie strictly inside (0, 1) (touching at an end is
    not counted); (near-)parallel ones where they are collinear (distance ≤ 1e-9 of their
    length) and their extents along the line overlap with positive length."""
    d1, d2, offset = np.broadcast_arrays(q - p, s - r, r - p)
    length1 = _norm(d1[..., 0], d1[..., 1])
    denominator = _cross(d1, d2)
    offset_across = _cross(offset, d1)
    parallel = ~(np.abs(denominator)
                 > PARALLEL_TOLERANCE * (length1 * _norm(d2[..., 0], d2[..., 1])))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = _cross(offset, d2) / denominator
        u = offset_across / denominator
        crossing = np.asarray((t > 0) & (t < 1) & (u > 0) & (u < 1))
        if parallel.any():
            # (near-)parallel pairs are rare: the collinear overlap test runs on those alone
            length, direction = length1[parallel], d1[parallel]
            along_r = (offset[parallel] * direction).sum(-1) / length
            along_s = (np.broadcast_to(s - p, d1.shape)[parallel] * direction).sum(-1) / length
            low, high = np.minimum(along_r, along_s), np.maximum(along_r, along_s)
            overlap = np.minimum(high, length) - np.maximum(low, 0.0)
            crossing[parallel] = ((np.abs(offset_across[parallel]) / length
                                   <= PARALLEL_TOLERANCE * length) & (overlap > 0))
    return crossing


CROSSING_SLICE = 896
"""Limb pairs per slice of `limbs_cross`'s exact test (as many as 32 shapes have): its pairwise
temporaries (L² segment pairs per limb pair) then stay in cache; measured 1.4× faster than one
pass over the 114,688 limb pairs of 4,096 shapes."""
BOX_MARGIN = 1e-4
"""Margin of `limbs_cross`'s bounding-box prefilter, in units of the shape's limb extent E
(width + height of the box around all its limbs): the limb pairs whose boxes lie further apart
are not tested. Rounding lets `segments_cross` find a crossing only between segments that come
within ~1e-6 E of each other, a hundredth of this margin: its cross products err by
~2.2e-16 |a||b|, and a non-parallel pair has |d1 × d2| > 1e-9 |d1||d2|, so its intersection
parameters err by ~2.2e-7 (1 + |r − p| / |d1|), a distance of ~2.2e-7 (|d1| + |r − p|)
≤ 4.4e-7 E along each segment; a (near-)parallel pair lies within ~2e-9 E."""
ORDINARY_SCALE = (1e-145, 1e140)
"""Shortest limb segment and limb extent, m, between which `BOX_MARGIN` holds: below, the
products of `segments_cross` lose their relative precision by underflow (~1e-308); above, they
overflow. Every limb pair of a shape outside these, or not finite, takes the exact test."""


def _limb_boxes_apart(points: np.ndarray, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """points (S, 8, L+1, 2) limb nodes -> (S, pairs) bool: the axis-aligned bounding boxes of
    limbs first[k] and second[k] lie more than `BOX_MARGIN` apart, so that none of their
    segments cross (`segments_cross`). False for every pair of a shape that is not finite or
    outside `ORDINARY_SCALE`."""
    # inf − inf and the squares of huge or tiny lengths: such shapes take the exact test anyway
    with np.errstate(all="ignore"):
        x, y = points[..., 0], points[..., 1]
        low_x, high_x, low_y, high_y = x.min(-1), x.max(-1), y.min(-1), y.max(-1)  # (S, 8)
        extent = (high_x.max(-1) - low_x.min(-1)) + (high_y.max(-1) - low_y.min(-1))
        dx, dy = np.diff(x, axis=-1), np.diff(y, axis=-1)
        shortest = np.sqrt((dx * dx + dy * dy).min(axis=(-2, -1)))
        ordinary = (shortest >= ORDINARY_SCALE[0]) & (extent <= ORDINARY_SCALE[1])
        # NaN boxes and the infinite margin compare False: the pair is tested
        margin = np.where(ordinary, BOX_MARGIN * extent, np.inf)[:, None]
        # the gaps as differences: rounded by at most 1.1e-16 of themselves, whatever the
        # coordinates' offset from the origin
        return ((low_x[:, second] - high_x[:, first] > margin)
                | (low_x[:, first] - high_x[:, second] > margin)
                | (low_y[:, second] - high_y[:, first] > margin)
                | (low_y[:, first] - high_y[:, second] > margin))


def limbs_cross(positions: np.ndarray, topology: Topology) -> np.ndarray:
    """positions (..., N, 2) -> (...) bool: a segment of one limb (`Topology.limbs`) crosses a
    segment of another (`segments_cross`)."""
    positions = np.asarray(positions)
    shapes = positions.reshape(-1, *positions.shape[-2:])
    points = shapes[:, topology.limbs, :]                       # (S, 8, L+1, 2)
    first, second = np.triu_indices(len(topology.limbs), k=1)
    # most limb pairs of a shape never come near each other: only those whose boxes do take
    # the exact test, which is elementwise, so the result is that of testing every pair
    near_shape, near_pair = np.nonzero(~_limb_boxes_apart(points, first, second))
    crossed = np.zeros(len(shapes), dtype=bool)
    for begin in range(0, len(near_shape), CROSSING_SLICE):
        shape = near_shape[begin:begin + CROSSING_SLICE]
        pair = near_pair[begin:begin + CROSSING_SLICE]
        one, other = points[shape, first[pair]], points[shape, second[pair]]  # (n, L+1, 2)
        # (n, L, 1, 2) against (n, 1, L, 2)
        hit = segments_cross(one[:, :-1, None, :], one[:, 1:, None, :],
                             other[:, None, :-1, :], other[:, None, 1:, :])
        crossed[shape[hit.any(axis=(-2, -1))]] = True
    return crossed.reshape(positions.shape[:-2])


def arc_mean_curvature(positions: np.ndarray, topology: Topology) -> np.ndarray:
    """positions (..., N, 2) -> (..., 8): each actuator arc's (`Topology.arcs`) mean signed
    curvature Σ κ_i Δl_i / Σ Δl_i over its interior nodes, 1/m (its total turning over its
    length), Δl_i the rest Voronoi lengths."""
    arcs = topology.arcs
    rest = topology.rest_positions[arcs]                    # (8, n_arc + 1, 2)
    edge = np.linalg.norm(np.diff(rest, axis=1), axis=-1)   # (8, n_arc)
    voronoi = 0.5 * (edge[:, :-1] + edge[:, 1:])            # (8, n_arc - 1)
    # κ on the component arrays, each edge's difference and length computed once for the two
    # nodes it joins (several times faster than `discrete_curvature` per node, the same bits).
    # The sum over the nodes below adds in an order that follows κ's memory layout: gathered as
    # positions[..., arcs, 0], the nodes (and so κ) have the layout that positions[..., arcs, :]
    # gives, and the same bits.
    dx = np.diff(positions[..., arcs, 0], axis=-1)         # (..., 8, n_arc)
    dy = np.diff(positions[..., arcs, 1], axis=-1)
    length = _norm(dx, dy)
    kappa = edge_curvature(dx[..., :-1], dy[..., :-1], dx[..., 1:], dy[..., 1:],
                           length[..., :-1], length[..., 1:], voronoi)
    return (kappa * voronoi).sum(-1) / voronoi.sum(-1)


def arcs_inverted(positions: np.ndarray, topology: Topology) -> np.ndarray:
    """positions (..., N, 2) -> (...) bool: some arc's mean curvature has the opposite sign to
    its rest value (or is not finite)."""
    rest = np.sign(arc_mean_curvature(topology.rest_positions, topology))
    return (~(arc_mean_curvature(positions, topology) * rest > 0)).any(axis=-1)


def edge_lengths(positions: np.ndarray, topology: Topology) -> np.ndarray:
    """positions (..., N, 2) m -> (..., E) m: the length of every edge."""
    edges = topology.edges
    x, y = positions[..., 0], positions[..., 1]
    return _norm(x[..., edges[:, 1]] - x[..., edges[:, 0]],
                 y[..., edges[:, 1]] - y[..., edges[:, 0]])


def edge_strain(positions: np.ndarray, topology: Topology,
                rest_positions: Optional[np.ndarray] = None) -> np.ndarray:
    """positions (..., N, 2) -> (..., E): ε = |x_j − x_i| / Δl̄ − 1 of every edge; Δl̄ from
    `rest_positions` ((B, N, 2), one rest shape per instance of a batch whose geometry differs)
    or else the topology's rest lengths."""
    rest = topology.rest_length if rest_positions is None else edge_lengths(rest_positions, topology)
    return edge_lengths(positions, topology) / rest - 1.0


SHAPE_SLICE = 48
"""Instances per slice of `shape_checks` (at least 2): the temporaries of its strain, crossing
and inversion checks then stay in cache; measured the fastest of 16 to 128 on the accurate
preset (433 nodes), 1.3× faster than 128."""


def _record_checks(record: np.ndarray, topology: Topology, rest_positions):
    """One record (B, N, 2) m of `shape_checks` (rest_positions (B, N, 2) m or None) -> four
    (B,) arrays: finite; max |ε| over the edges (NaN where not finite); limbs cross and arc
    inverted, each False where not finite."""
    batch = len(record)
    valid = np.empty(batch, dtype=bool)
    strain = np.empty(batch)
    crossed = np.zeros(batch, dtype=bool)
    inverted = np.empty(batch, dtype=bool)
    # NumPy sums each arc's curvatures (`arc_mean_curvature`) in an order that follows their
    # memory layout, which differs for a batch of one instance: a lone last instance joins the
    # slice before it, so that every instance's sums are those of the whole record, bitwise
    ends = list(range(SHAPE_SLICE, batch, SHAPE_SLICE))
    if ends and batch - ends[-1] == 1:
        ends.pop()
    for begin, end in zip([0] + ends, ends + [batch]):
        part = slice(begin, end)
        shape = record[part]
        rest = None if rest_positions is None else rest_positions[part]
        valid[part] = ok = np.isfinite(shape).all(axis=(1, 2))
        strain[part] = np.abs(edge_strain(shape, topology, rest)).max(axis=-1)
        # a shape that is not finite has its crossing masked: its NaN limb boxes would send
        # every limb pair to the exact test
        crossed[part][ok] = limbs_cross(shape[ok], topology)
        inverted[part] = arcs_inverted(shape, topology) & ok
    return valid, strain, crossed, inverted


def shape_checks(shapes: np.ndarray, topology: Topology,
                 rest_positions: Optional[np.ndarray] = None) -> pd.DataFrame:
    """Sanity of recorded shapes: shapes (R, B, N, 2) m, R records of B instances (the last
    record is taken as the final shape; NaN records, e.g. after a failure, are skipped), strains
    against each instance's rest shape `rest_positions` (B, N, 2) m when the instances' geometry
    differs (default: the topology's) -> one row per instance:

    - max_strain: max |ε| over all edges and finite records (`edge_strain`), max_strain_final on
      the final shape;
    - limbs_cross: two limbs cross in some record (`limbs_cross`), limbs_cross_final;
    - arc_inverted: an arc's mean curvature changed sign in some record (`arcs_inverted`; the
      actuation only lowers |κ⁰|, never through zero), arc_inverted_final;
    - finite: every record finite;
    - sane: finite, no crossing, no inversion and max_strain ≤ STRAIN_LIMIT.
    """
    shapes = np.asarray(shapes, dtype=np.float64)
    if shapes.ndim != 4 or not len(shapes):
        raise ValueError(f"shapes must be (R, B, N, 2) with at least one record, got shape "
                         f"{shapes.shape}")
    batch = shapes.shape[1]
    if rest_positions is not None:
        rest_positions = np.broadcast_to(rest_positions, shapes.shape[1:])
    finite = np.ones(batch, dtype=bool)
    strain_max = np.full(batch, -np.inf)
    cross_any = np.zeros(batch, dtype=bool)
    inverted_any = np.zeros(batch, dtype=bool)
    for record in shapes:
        valid, strain, crossed, inverted = _record_checks(record, topology, rest_positions)
        finite &= valid
        strain_max = np.where(valid, np.fmax(strain_max, strain), strain_max)
        cross_any |= crossed
        inverted_any |= inverted
    # the final shape is the last record: its checks are the loop's last
    table = pd.DataFrame({
        "max_strain": np.where(np.isfinite(strain_max), strain_max, np.nan),
        "max_strain_final": strain,
        "limbs_cross": cross_any,
        "limbs_cross_final": crossed,
        "arc_inverted": inverted_any,
        "arc_inverted_final": inverted,
        "finite": finite,
    })
    table["sane"] = (finite & ~table["limbs_cross"] & ~table["arc_inverted"]
                     & (table["max_strain"] <= STRAIN_LIMIT))
    return table
