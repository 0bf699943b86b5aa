"""Swimming metrics: centroid, body rotation, whole-run and cycle-window speeds; shape checks
(limb crossing, arc inversion, strain).

Conventions: the centroid is the mass-weighted mean of the node positions (added mass excluded);
"forward" is the unit sum of the fired actuators' bisectors; a signed speed is the displacement
projected on it; the heading (body rotation) is the mean rotation of the eight hub-to-joint
directions from their rest angles. Lengths in mm and times in s in every returned column.
"""

from __future__ import annotations

import math
from typing import Dict, Optional, Sequence

import numpy as np
import pandas as pd

from .gait import Gait
from .geometry import Topology, discrete_curvature

METERS_TO_MM = 1e3
SPEED_COLUMNS = ("displacement_x_mm", "displacement_y_mm", "speed_mm_s", "signed_speed_mm_s",
                 "travel_direction_deg")
"""Columns of `swimming_metrics`."""


def centroid(positions: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """Mass-weighted mean of node positions: positions (..., N, 2), mass (..., N) -> (..., 2)."""
    return (positions * mass[..., None]).sum(-2) / mass.sum(-1)[..., None]


def rotate(vectors: np.ndarray, angle_rad) -> np.ndarray:
    """(..., 2) vectors turned counter-clockwise by angle_rad (rad; a scalar or an array that
    broadcasts against the vectors' leading axes)."""
    cos, sin = np.cos(angle_rad), np.sin(angle_rad)
    return np.stack([cos * vectors[..., 0] - sin * vectors[..., 1],
                     sin * vectors[..., 0] + cos * vectors[..., 1]], axis=-1)


def wrap_degrees(angle):
    """Angles (deg) wrapped to [-180, 180)."""
    return (np.asarray(angle) + 180.0) % 360.0 - 180.0


def body_rotation(positions: np.ndarray, rest_positions: np.ndarray, joints: np.ndarray,
                  hub: int = 0) -> np.ndarray:
    """Heading: rotation (rad, counter-clockwise, in (−π, π]) of the body from its rest
    orientation, the circular mean of the hub-to-joint directions' rotations. positions and
    rest_positions (..., N, 2); returns (...)."""
    now = positions[..., joints, :] - positions[..., hub:hub + 1, :]
    rest = rest_positions[..., joints, :] - rest_positions[..., hub:hub + 1, :]
    turn = (np.arctan2(now[..., 1], now[..., 0]) - np.arctan2(rest[..., 1], rest[..., 0]))
    return np.arctan2(_ordered_sum(np.sin(turn)), _ordered_sum(np.cos(turn)))


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
    return np.array([Gait.parse(g).forward if Gait.parse(g).forward is not None
                     else (np.nan, np.nan) for g in gaits], dtype=np.float64)


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
    first_cycle was recorded."""
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
    if not (math.isfinite(floor_mm_s) and floor_mm_s >= 0):
        raise ValueError(f"floor_mm_s must be a finite number >= 0, got {floor_mm_s!r}")
    reference = np.asarray(reference_mm_s, dtype=np.float64)
    return np.abs(np.asarray(speed_mm_s, dtype=np.float64) - reference) / np.maximum(
        np.abs(reference), floor_mm_s)


def observed_order(coarse_change, fine_change, refinement: float = 2.0):
    """Observed order of convergence of a ladder refined by `refinement` per level, from the
    change between its two coarser levels and the change between its two finer ones (arrays
    broadcast): log(coarse_change / fine_change) / log(refinement). NaN where the changes
    differ in sign or one is zero (no monotone convergence to read an order from)."""
    coarse_change = np.asarray(coarse_change, dtype=np.float64)
    fine_change = np.asarray(fine_change, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        order = np.log(coarse_change / fine_change) / np.log(refinement)
    return np.where(coarse_change * fine_change > 0, order, np.nan)


def richardson_limit(middle, fine, order, refinement: float = 2.0):
    """Richardson extrapolation of a quantity computed on two levels refined by `refinement`,
    its error ∝ (level size)^order: v_f + (v_f − v_m) / (refinement^order − 1) (arrays
    broadcast; NaN where the order is NaN)."""
    fine = np.asarray(fine, dtype=np.float64)
    return fine + (fine - np.asarray(middle, dtype=np.float64)) / (refinement ** np.asarray(
        order, dtype=np.float64) - 1.0)


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


def segments_cross(p, q, r, s) -> np.ndarray:
    """Segments p–q and r–s (arrays (..., 2)) -> (...) bool: they cross. Non-parallel segments
    cross where both intersection parameters lie strictly inside (0, 1) (touching at an end is
    not counted); (near-)parallel ones where they are collinear (distance ≤ 1e-9 of their
    length) and their extents along the line overlap with positive length."""
    d1, d2, offset = np.broadcast_arrays(q - p, s - r, r - p)
    length1 = np.linalg.norm(d1, axis=-1)
    denominator = _cross(d1, d2)
    offset_across = _cross(offset, d1)
    parallel = ~(np.abs(denominator) > PARALLEL_TOLERANCE * (length1 * np.linalg.norm(d2, axis=-1)))
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


CROSSING_SLICE = 32
"""Shapes per slice of `limbs_cross`: its pairwise temporaries (28 limb pairs × L² segment
pairs each) then stay in cache; measured 4.7× faster than one pass over 4,096 shapes."""


def limbs_cross(positions: np.ndarray, topology: Topology) -> np.ndarray:
    """positions (..., N, 2) -> (...) bool: a segment of one limb (`Topology.limbs`) crosses a
    segment of another (`segments_cross`)."""
    positions = np.asarray(positions)
    shapes = positions.reshape(-1, *positions.shape[-2:])
    first, second = np.triu_indices(len(topology.limbs), k=1)
    crossed = np.empty(len(shapes), dtype=bool)
    # in slices of shapes whose pairwise temporaries stay in cache: the same values, faster
    for begin in range(0, len(shapes), CROSSING_SLICE):
        points = shapes[begin:begin + CROSSING_SLICE, topology.limbs, :]  # (b, 8, L+1, 2)
        start, end = points[..., :-1, :], points[..., 1:, :]              # (b, 8, L, 2)
        # (b, pairs, L, 1, 2) against (b, pairs, 1, L, 2)
        hit = segments_cross(start[..., first, :, None, :], end[..., first, :, None, :],
                             start[..., second, None, :, :], end[..., second, None, :, :])
        crossed[begin:begin + CROSSING_SLICE] = hit.any(axis=(-3, -2, -1))
    return crossed.reshape(positions.shape[:-2])


def arc_mean_curvature(positions: np.ndarray, topology: Topology) -> np.ndarray:
    """positions (..., N, 2) -> (..., 8): each actuator arc's (`Topology.arcs`) mean signed
    curvature Σ κ_i Δl_i / Σ Δl_i over its interior nodes, 1/m (its total turning over its
    length), Δl_i the rest Voronoi lengths."""
    arcs = topology.arcs
    rest = topology.rest_positions[arcs]                    # (8, n_arc + 1, 2)
    edge = np.linalg.norm(np.diff(rest, axis=1), axis=-1)   # (8, n_arc)
    voronoi = 0.5 * (edge[:, :-1] + edge[:, 1:])            # (8, n_arc - 1)
    points = positions[..., arcs, :]
    kappa = discrete_curvature(points[..., :-2, :], points[..., 1:-1, :], points[..., 2:, :],
                               voronoi)
    return (kappa * voronoi).sum(-1) / voronoi.sum(-1)


def arcs_inverted(positions: np.ndarray, topology: Topology) -> np.ndarray:
    """positions (..., N, 2) -> (...) bool: some arc's mean curvature has the opposite sign to
    its rest value (or is not finite)."""
    rest = np.sign(arc_mean_curvature(topology.rest_positions, topology))
    return (~(arc_mean_curvature(positions, topology) * rest > 0)).any(axis=-1)


def edge_lengths(positions: np.ndarray, topology: Topology) -> np.ndarray:
    """positions (..., N, 2) m -> (..., E) m: the length of every edge."""
    edges = topology.edges
    return np.linalg.norm(positions[..., edges[:, 1], :] - positions[..., edges[:, 0], :],
                          axis=-1)


def edge_strain(positions: np.ndarray, topology: Topology,
                rest_positions: Optional[np.ndarray] = None) -> np.ndarray:
    """positions (..., N, 2) -> (..., E): ε = |x_j − x_i| / Δl̄ − 1 of every edge; Δl̄ from
    `rest_positions` ((B, N, 2), one rest shape per instance of a batch whose geometry differs)
    or else the topology's rest lengths."""
    rest = topology.rest_length if rest_positions is None else edge_lengths(rest_positions, topology)
    return edge_lengths(positions, topology) / rest - 1.0


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
    n_records, batch = shapes.shape[:2]
    finite = np.isfinite(shapes).all(axis=(0, 2, 3))
    strain_max = np.full(batch, -np.inf)
    cross_any = np.zeros(batch, dtype=bool)
    inverted_any = np.zeros(batch, dtype=bool)
    # one record at a time keeps the pairwise segment test small
    for record in shapes:
        valid = np.isfinite(record).all(axis=(1, 2))
        strain = np.abs(edge_strain(record, topology, rest_positions)).max(axis=-1)
        strain_max = np.where(valid, np.fmax(strain_max, strain), strain_max)
        cross_any |= limbs_cross(record, topology) & valid
        inverted_any |= arcs_inverted(record, topology) & valid
    final = shapes[-1]
    final_valid = np.isfinite(final).all(axis=(1, 2))
    table = pd.DataFrame({
        "max_strain": np.where(np.isfinite(strain_max), strain_max, np.nan),
        "max_strain_final": np.abs(edge_strain(final, topology, rest_positions)).max(axis=-1),
        "limbs_cross": cross_any,
        "limbs_cross_final": limbs_cross(final, topology) & final_valid,
        "arc_inverted": inverted_any,
        "arc_inverted_final": arcs_inverted(final, topology) & final_valid,
        "finite": finite,
    })
    table["sane"] = (finite & ~table["limbs_cross"] & ~table["arc_inverted"]
                     & (table["max_strain"] <= STRAIN_LIMIT))
    return table
