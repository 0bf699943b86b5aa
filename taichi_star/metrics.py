"""Swimming metrics (design §3): centroid, speed, signed speed, heading."""

from __future__ import annotations

import numpy as np

from .gait import Gait

METERS_TO_MM = 1e3


def centroid(positions: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """Mass-weighted mean of node positions: positions (..., N, 2), mass (..., N) -> (..., 2)."""
    return (positions * mass[..., None]).sum(-2) / mass.sum(-1)[..., None]


def swimming_metrics(displacement_m: np.ndarray, duration_s: float, gaits) -> dict:
    """Per-instance metrics of centroid displacements (B, 2) in m over duration_s.

    Returns columns (each (B,)): displacement_x_mm, displacement_y_mm, speed_mm_s
    (|displacement|/duration), signed_speed_mm_s (projection on the gait's forward direction,
    NaN where that direction is undefined) and heading_deg (direction of the displacement,
    counter-clockwise from +x, the bisector of A1).
    """
    displacement_mm = np.asarray(displacement_m, dtype=np.float64) * METERS_TO_MM
    forward = [Gait.parse(g).forward for g in gaits]
    signed = np.array([np.nan if f is None else float(d @ f)
                       for d, f in zip(displacement_mm, forward)])
    return {
        "displacement_x_mm": displacement_mm[:, 0],
        "displacement_y_mm": displacement_mm[:, 1],
        "speed_mm_s": np.hypot(displacement_mm[:, 0], displacement_mm[:, 1]) / duration_s,
        "signed_speed_mm_s": signed / duration_s,
        "heading_deg": np.degrees(np.arctan2(displacement_mm[:, 1], displacement_mm[:, 0])),
    }
