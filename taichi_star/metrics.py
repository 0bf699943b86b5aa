"""Swimming metrics: centroid, body rotation, whole-run and cycle-window speeds, shape checks.

Conventions: the centroid is the mass-weighted mean of the node positions (added mass excluded);
"forward" is the unit sum of the fired actuators' bisectors; a signed speed is the displacement
projected on it; the heading (body rotation) is the mean rotation of the eight hub-to-joint
directions from their rest angles. Lengths in mm and times in s in every returned column.
"""

from __future__ import annotations

from typing import Dict, Sequence

import numpy as np

from .gait import Gait

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


def body_rotation(positions: np.ndarray, rest_positions: np.ndarray, joints: np.ndarray,
                  hub: int = 0) -> np.ndarray:
    """Heading: rotation (rad, counter-clockwise, in (−π, π]) of the body from its rest
    orientation, the circular mean of the hub-to-joint directions' rotations. positions and
    rest_positions (..., N, 2); returns (...)."""
    now = positions[..., joints, :] - positions[..., hub:hub + 1, :]
    rest = rest_positions[..., joints, :] - rest_positions[..., hub:hub + 1, :]
    turn = (np.arctan2(now[..., 1], now[..., 0]) - np.arctan2(rest[..., 1], rest[..., 0]))
    # summed joint by joint, not by a reduction whose order depends on the batch's shape: an
    # instance's heading must not depend on its neighbours to the last bit
    sine, cosine = np.sin(turn), np.cos(turn)
    sine_sum, cosine_sum = sine[..., 0], cosine[..., 0]
    for joint in range(1, len(joints)):
        sine_sum = sine_sum + sine[..., joint]
        cosine_sum = cosine_sum + cosine[..., joint]
    return np.arctan2(sine_sum, cosine_sum)


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
