"""The physical robot's measurements, packaged with the library (design §4).

The data are the authors' public thesis recordings of the five gaits of the paper's Fig. 4
(see `taichi_star/data/SOURCE.md`); they are read from the installed package, never from outside
it. Camera axes are not robot axes: compare speeds and path shapes, not headings.

    >>> from taichi_star import experiment
    >>> experiment.experimental_speeds().loc["A1+A2", "speed_mm_s"]
    2.85
    >>> experiment.experimental_trajectory("A1+A3").head()      # t_s, x_mm, y_mm

`compare_with_experiment(summary)` turns a `simulate(...).summary` of the paper gaits into the
Fig. 4c table (simulated vs measured speed, direction against the paper's).
"""

from __future__ import annotations

import math
from importlib import resources

import numpy as np
import pandas as pd

from .gait import canonical_gait

PAPER_GAITS = ("A1", "A1+A2", "A1+A3", "A1+A4", "A1+A3+A5")
"""The five gaits of the paper's Fig. 4, in its order."""

PAPER_DIRECTIONS = {"A1": "forward", "A1+A2": "forward", "A1+A3": "reverse",
                    "A1+A4": "reverse", "A1+A3+A5": "reverse"}
"""Swimming direction of each Fig. 4 gait stated in the paper's text (design §4): "forward" is
along the gait's forward direction (the sum of its actuators' bisectors), "reverse" against it."""

FIG4C_COLUMNS = ["gait", "sim_speed_mm_s", "sim_signed_speed_mm_s", "sim_direction",
                 "exp_speed_mm_s", "paper_direction", "direction_matches", "speed_ratio",
                 "status"]
"""Columns of the Fig. 4c table, in order."""


def _data_dir():
    return resources.files("taichi_star").joinpath("data", "experiment")


def _canonical(gait: str) -> str:
    return canonical_gait(gait)


def experimental_speeds() -> pd.DataFrame:
    """Measured net speeds of the five gaits, indexed by canonical gait name.

    Columns: frames, duration_s, net_displacement_mm, speed_mm_s (full trial: net displacement /
    duration), excerpt_duration_s, excerpt_speed_mm_s (the shorter excerpt the authors processed).
    """
    with _data_dir().joinpath("speeds.csv").open("r") as handle:
        table = pd.read_csv(handle)
    table["gait"] = [_canonical(g) for g in table["gait"]]
    return table.set_index("gait")


def experimental_speed(gait: str, excerpt: bool = False) -> float:
    """Measured speed of one Fig. 4 gait in mm/s (full trial, or the authors' excerpt); NaN for a
    gait that was not measured."""
    table = experimental_speeds()
    gait = _canonical(gait)
    if gait not in table.index:
        return math.nan
    return float(table.loc[gait, "excerpt_speed_mm_s" if excerpt else "speed_mm_s"])


def experimental_trajectory(gait: str) -> pd.DataFrame:
    """The tracked centroid of the physical robot for one Fig. 4 gait: columns t_s, x_mm, y_mm
    (camera axes, starting at the origin at t = 0) and displacement_mm = distance from the start.

    Raises ValueError for a gait that was not measured (only `PAPER_GAITS` were).
    """
    gait = _canonical(gait)
    if gait not in PAPER_GAITS:
        raise ValueError(f"no experimental trajectory for gait {gait!r}; measured gaits: "
                         f"{', '.join(PAPER_GAITS)}")
    name = gait.replace("+", "_") + "_trajectory.csv"
    with _data_dir().joinpath(name).open("r") as handle:
        table = pd.read_csv(handle)
    table["displacement_mm"] = np.hypot(table["x_mm"], table["y_mm"])
    return table


def direction_of(signed_speed: float) -> str:
    """"forward" (> 0), "reverse" (< 0), or "undefined" (zero, NaN: no forward direction)."""
    if signed_speed is None or not math.isfinite(signed_speed) or signed_speed == 0.0:
        return "undefined"
    return "forward" if signed_speed > 0 else "reverse"


def compare_with_experiment(summary: pd.DataFrame,
                            speed_column: str = "speed_mm_s",
                            signed_column: str = "signed_speed_mm_s") -> pd.DataFrame:
    """The Fig. 4c table from a `simulate(...).summary` (one row per gait, any order; gaits that
    were not measured get NaN experimental speed and "unknown" paper direction).

    Columns `FIG4C_COLUMNS`: sim_direction from the sign of the signed speed, direction_matches
    against `PAPER_DIRECTIONS`, speed_ratio = sim_speed / exp_speed, status of the simulation.
    Speeds of instances whose status is not "ok" are reported as NaN, never as numbers.
    """
    speeds = experimental_speeds()
    rows = []
    for _, row in summary.iterrows():
        gait = _canonical(row["gait"])
        ok = row.get("status", "ok") == "ok"
        sim_speed = float(row[speed_column]) if ok else math.nan
        sim_signed = float(row[signed_column]) if ok else math.nan
        exp_speed = float(speeds.loc[gait, "speed_mm_s"]) if gait in speeds.index else math.nan
        sim_direction = direction_of(sim_signed)
        paper_direction = PAPER_DIRECTIONS.get(gait, "unknown")
        rows.append({
            "gait": gait,
            "sim_speed_mm_s": sim_speed,
            "sim_signed_speed_mm_s": sim_signed,
            "sim_direction": sim_direction,
            "exp_speed_mm_s": exp_speed,
            "paper_direction": paper_direction,
            "direction_matches": bool(sim_direction == paper_direction),
            "speed_ratio": sim_speed / exp_speed if exp_speed else math.nan,
            "status": row.get("status", "ok"),
        })
    return pd.DataFrame(rows, columns=FIG4C_COLUMNS)
