"""The physical robot's measurements, packaged with the library.

The data are the authors' public thesis recordings of the five gaits of the paper's Fig. 4
(see `taichi_star/data/SOURCE.md`); they are read from the installed package, never from outside
it. Camera axes are not robot axes: compare speeds and path shapes, not headings.

    >>> from taichi_star import experiment
    >>> float(experiment.experimental_speeds().loc["A1+A2", "speed_mm_s"])
    2.85
    >>> experiment.experimental_trajectory("A1+A3").head()  # doctest: +SKIP
    >>> experiment.experimental_cycle_speeds()  # doctest: +SKIP

(the trajectory's columns t_s, x_mm, y_mm, displacement_mm; the per-cycle mean, std and
n_cycles of each gait)

`compare_with_experiment(summary)` turns a `simulate(...).summary` of the paper gaits into the
Fig. 4c table (simulated vs measured speed, direction against the paper's).
"""

from __future__ import annotations

import functools
import math
from importlib import resources
from typing import Sequence

import numpy as np
import pandas as pd

from .checks import check_finite, check_flag, is_real
from .gait import canonical_gait

# every public name: docs/api.md documents the whole module
__all__ = ["PAPER_GAITS", "PAPER_DIRECTIONS", "EXPERIMENT_PERIOD_S", "MAX_PATH_CYCLES",
           "FIG4C_COLUMNS", "experimental_speeds", "experimental_speed", "experimental_trajectory",
           "cycle_speeds", "experimental_cycle_speeds", "direction_of", "compare_with_experiment",
           "WEIGHT_SCHEMES", "measurement_table", "relative_signed_errors", "objective_values"]

PAPER_GAITS = ("A1", "A1+A2", "A1+A3", "A1+A4", "A1+A3+A5")
"""The five gaits of the paper's Fig. 4, in its order."""

PAPER_DIRECTIONS = {"A1": "forward", "A1+A2": "forward", "A1+A3": "reverse",
                    "A1+A4": "reverse", "A1+A3+A5": "reverse"}
"""Swimming direction of each Fig. 4 gait as the paper's text states it (A1 and A1+A2 forward,
the others reverse). The paper does not define "forward"; this library takes it as the gait's
forward direction, the sum of its actuators' bisectors (`Gait.forward`), "reverse" against
it."""

EXPERIMENT_PERIOD_S = 3.15
"""Nominal actuation period of the physical robot's trials, s: the 150-ms heating pulse and
3-s rest they were programmed with. The tracks' strokes come a little slower, every
3.174–3.182 s (docs: Results, "the strokes in the tracks"); the per-cycle speeds cut windows
of this nominal period."""

MAX_PATH_CYCLES = 10 ** 6
"""The most cycles `cycle_speeds` cuts a path into (a few arrays of this many edges, 8 MB
each): the measured trials hold at most 19 cycles of 3.15 s, a simulated run of the step
counter's 2.1e9 steps 7e5 at 1 ms. A period smaller than the frame spacing is fine (the edges
are interpolated); a period of 1e-9 s, 2e9 cycles of a 2-s path, was a MemoryError."""

FIG4C_COLUMNS = ["gait", "sim_speed_mm_s", "sim_signed_speed_mm_s", "sim_direction",
                 "exp_speed_mm_s", "exp_cycle_speed_std_mm_s", "paper_direction", "direction_matches", "speed_ratio",
                 "status"]
"""Columns of the Fig. 4c table, in order."""


def _data_dir():
    return resources.files("taichi_star").joinpath("data", "experiment")


def _canonical(gait: str) -> str:
    return canonical_gait(gait)


def experimental_speeds() -> pd.DataFrame:
    """Measured net speeds of the five gaits, indexed by canonical gait name.

    Columns: frames (the tracked frames, the rows of the trajectory: A1+A3+A5's trial spans 8
    more, which the tracker lost), duration_s, net_displacement_mm, speed_mm_s (full trial: net
    displacement / duration), excerpt_duration_s, excerpt_speed_mm_s (the shorter excerpt the
    authors processed).
    """
    with _data_dir().joinpath("speeds.csv").open("r") as handle:
        return pd.read_csv(handle).set_index("gait")     # the file's gaits are canonical


def experimental_speed(gait: str, excerpt: bool = False) -> float:
    """Measured speed of one Fig. 4 gait in mm/s (full trial, or the authors' excerpt); NaN for a
    gait that was not measured. ValueError naming excerpt unless it is True or False."""
    excerpt = check_flag("excerpt", excerpt)
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


def cycle_speeds(t_s: np.ndarray, x_mm: np.ndarray, y_mm: np.ndarray,
                 period_s: float = EXPERIMENT_PERIOD_S) -> np.ndarray:
    """Speed of each complete cycle of a tracked path, mm/s: shape (n_cycles,).

    Cycles are cut as windows of one period from the first sample: [kT, (k+1)T) for
    k = 0 .. floor((t_end − t_0)/T) − 1 (the incomplete tail is dropped). The position at a window
    edge is linearly interpolated between the two video frames around it (frames are 1/59.94 s
    apart, under 1 % of a period). A cycle's speed is |p((k+1)T) − p(kT)| / T: a magnitude,
    because camera axes are not robot axes. The phase of the actuation within a window does not
    matter for a steadily repeating stroke whose period is T; the measured trials' strokes come
    every 3.174–3.182 s against the nominal 3.15 s (`EXPERIMENT_PERIOD_S`), so their windows
    drift through the stroke by about 0.03 s a cycle."""
    t_s, x_mm, y_mm = (np.asarray(a, dtype=np.float64) for a in (t_s, x_mm, y_mm))
    if not (len(t_s) == len(x_mm) == len(y_mm)) or len(t_s) < 2 or np.any(np.diff(t_s) <= 0):
        raise ValueError("cycle_speeds needs equal-length t, x, y with t strictly increasing")
    # a NaN passes the test above (it compares False) and gave NaN speeds
    if not (t_s.ndim == x_mm.ndim == y_mm.ndim == 1) \
            or not all(np.isfinite(a).all() for a in (t_s, x_mm, y_mm)):
        raise ValueError("cycle_speeds needs finite 1-D t, x, y")
    _check_period(period_s)
    # a path of exactly n periods (up to the rounding of its time stamps) has n cycles
    duration = t_s[-1] - t_s[0]
    with np.errstate(over="ignore"):                    # inf for a subnormal period
        estimate = np.floor(duration / period_s + 1e-9)
    if not estimate <= MAX_PATH_CYCLES:
        raise ValueError(f"period_s = {period_s!r} s cuts the {duration:g}-s path into "
                         f"{estimate:.3g} cycles; the limit is {MAX_PATH_CYCLES} cycles "
                         f"(MAX_PATH_CYCLES): a period_s >= {duration / MAX_PATH_CYCLES:.3g} s "
                         f"for this path")
    n_cycles = int(estimate)
    edges = t_s[0] + period_s * np.arange(n_cycles + 1)
    x_edges, y_edges = np.interp(edges, t_s, x_mm), np.interp(edges, t_s, y_mm)
    return np.hypot(np.diff(x_edges), np.diff(y_edges)) / period_s


def _check_period(period_s):
    """ValueError naming period_s unless it is a finite real number > 0 (s)."""
    check_finite("period_s", period_s, 0.0, unit=" s")


def experimental_cycle_speeds(period_s: float = EXPERIMENT_PERIOD_S) -> pd.DataFrame:
    """Per-cycle speeds of each measured gait (`cycle_speeds` of its trajectory), indexed by
    gait in `PAPER_GAITS` order.

    Columns: n_cycles, cycle_speed_mean_mm_s, cycle_speed_std_mm_s (sample standard deviation,
    ddof = 1), cycle_speed_min_mm_s, cycle_speed_max_mm_s. The spread is that of the cycles of
    one trial: it includes the robot's speed-up from rest over the first cycles and any slow-down
    at the end (A1+A3 stops for its last 3.3 s: its last cycle reads 0.10 mm/s, and its spread
    is 1.31 mm/s with that cycle, 0.98 without), and is used as the measurement's uncertainty.
    It is not divided by √n: successive cycles of one trial are strongly correlated (a trend, not noise).
    By the triangle inequality the mean per-cycle speed is at least the net speed over the same
    whole cycles; it exceeds the full-trial speed when the path wanders sideways (A1, slow).
    ValueError naming period_s unless every trial holds at least two whole periods (the
    spread needs two cycles)."""
    _check_period(period_s)
    return _cycle_speed_table(float(period_s)).copy()


@functools.lru_cache(maxsize=4)
def _cycle_speed_table(period_s: float) -> pd.DataFrame:
    # cached: the Fig. 4c table of every calibration candidate needs the error bars
    paths = {gait: experimental_trajectory(gait) for gait in PAPER_GAITS}
    durations = {gait: path["t_s"].iloc[-1] - path["t_s"].iloc[0] for gait, path in paths.items()}
    shortest = min(durations, key=durations.get)
    if period_s > durations[shortest] / 2:
        raise ValueError(f"period_s must be in (0, {durations[shortest] / 2:g}] s (two whole "
                         f"cycles of the shortest trial, {shortest}'s {durations[shortest]:g} s, "
                         f"for the spread), got {period_s!r}")
    rows = []
    for gait, path in paths.items():
        speeds = cycle_speeds(path["t_s"], path["x_mm"], path["y_mm"], period_s)
        rows.append({"gait": gait, "n_cycles": len(speeds),
                     "cycle_speed_mean_mm_s": float(np.mean(speeds)),
                     "cycle_speed_std_mm_s": float(np.std(speeds, ddof=1)),
                     "cycle_speed_min_mm_s": float(np.min(speeds)),
                     "cycle_speed_max_mm_s": float(np.max(speeds))})
    return pd.DataFrame(rows).set_index("gait")


def direction_of(signed_speed: float) -> str:
    """"forward" (> 0), "reverse" (< 0), or "undefined" (zero, NaN, None: no forward
    direction). ValueError naming signed_speed for anything but a real number or None."""
    if signed_speed is not None and not is_real(signed_speed):
        raise ValueError(f"signed_speed must be a real number (mm/s) or None, got "
                         f"{signed_speed!r}")
    if signed_speed is None or not math.isfinite(signed_speed) or signed_speed == 0.0:
        return "undefined"
    return "forward" if signed_speed > 0 else "reverse"


def compare_with_experiment(summary: pd.DataFrame,
                            speed_column: str = "speed_mm_s",
                            signed_column: str = "signed_speed_mm_s") -> pd.DataFrame:
    """The Fig. 4c table from a `simulate(...).summary` (one row per gait, any order; gaits that
    were not measured get NaN experimental speed and "unknown" paper direction).

    Columns `FIG4C_COLUMNS`: sim_direction from the sign of the signed speed, direction_matches
    against `PAPER_DIRECTIONS`, exp_cycle_speed_std_mm_s = the spread of the measured per-cycle
    speeds (`experimental_cycle_speeds`, the error bar), speed_ratio = sim_speed / exp_speed,
    status of the simulation.
    Speeds of instances whose status is not "ok" are reported as NaN, never as numbers; their
    sim_direction is "undefined" and direction_matches False (so a count of the directions
    that match counts them as not matching: filter on status first). ValueError naming the
    argument for a column summary lacks, and the column and gait for a speed that is no
    number.
    """
    if not isinstance(summary, pd.DataFrame):
        raise ValueError(f"summary must be a simulate(...).summary table, got "
                         f"{type(summary).__name__}")
    missing = [column for column in ("gait", speed_column, signed_column)
               if column not in summary.columns]
    if missing:
        # an argument given another name than its default is named; a default column missing
        # is the summary's fault
        given_names = {speed_column: "speed_column", signed_column: "signed_column"}
        name = given_names.get(missing[0]) if missing[0] not in (
            "speed_mm_s", "signed_speed_mm_s") else None
        given = f"{name} = {missing[0]!r} is not a column of summary" if name else \
            f"summary has no column {missing[0]!r}"
        raise ValueError(f"{given} (a simulate(...).summary has gait, speed_mm_s and "
                         f"signed_speed_mm_s)")
    speeds = experimental_speeds()
    spread = experimental_cycle_speeds()["cycle_speed_std_mm_s"]
    rows = []
    for _, row in summary.iterrows():
        try:
            gait = _canonical(row["gait"])
        except ValueError as error:
            raise ValueError(f"summary: {error}") from None
        ok = row.get("status", "ok") == "ok"
        sim_speed, sim_signed = (_speed(row, column, gait) if ok else math.nan
                                 for column in (speed_column, signed_column))
        exp_speed = float(speeds.loc[gait, "speed_mm_s"]) if gait in speeds.index else math.nan
        sim_direction = direction_of(sim_signed)
        paper_direction = PAPER_DIRECTIONS.get(gait, "unknown")
        rows.append({
            "gait": gait,
            "sim_speed_mm_s": sim_speed,
            "sim_signed_speed_mm_s": sim_signed,
            "sim_direction": sim_direction,
            "exp_speed_mm_s": exp_speed,
            "exp_cycle_speed_std_mm_s": float(spread[gait]) if gait in spread.index else math.nan,
            "paper_direction": paper_direction,
            "direction_matches": bool(sim_direction == paper_direction),
            "speed_ratio": sim_speed / exp_speed if exp_speed else math.nan,
            "status": row.get("status", "ok"),
        })
    return pd.DataFrame(rows, columns=FIG4C_COLUMNS)


def _speed(row, column: str, gait: str) -> float:
    """The row's `column` as a float, mm/s; ValueError naming the column and the gait for a
    cell that is no number (NumPy's "could not convert string to float" named neither)."""
    try:
        return float(row[column])
    except (TypeError, ValueError):
        raise ValueError(f"summary: {column} of gait {gait} is {row[column]!r}, not a "
                         f"number") from None


WEIGHT_SCHEMES = ("experimental", "uniform")
"""How `measurement_table` weighs the gaits: by their measured speed over its per-cycle spread,
squared ("experimental"), or equally ("uniform")."""


def measurement_table(gaits: Sequence[str] = PAPER_GAITS,
                      weights: str = "experimental") -> pd.DataFrame:
    """What the objective compares with, indexed by gait: exp_speed_mm_s (full trial),
    paper_sign (+1 forward, −1 reverse), target_signed_mm_s = sign × speed, cycle_std_mm_s
    (spread of the per-cycle speeds), weight (mean 1 over `gaits`)."""
    if weights not in WEIGHT_SCHEMES:
        raise ValueError(f"weights must be one of {list(WEIGHT_SCHEMES)}, got {weights!r}")
    if isinstance(gaits, str):  # its letters were taken for gaits ('A' was not measured)
        raise ValueError(f"gaits must be a list of gait names, got the text {gaits!r}")
    # any spelling the other functions take ("a2+a1"), by its canonical name
    gaits = [_canonical(g) for g in gaits]
    if not gaits:
        raise ValueError("gaits: empty gait list")
    unknown = [g for g in gaits if g not in PAPER_GAITS]
    if unknown:
        raise ValueError(f"gaits: {unknown[0]!r} was not measured; measured: {list(PAPER_GAITS)}")
    speed = experimental_speeds().loc[gaits, "speed_mm_s"].to_numpy(dtype=float)
    spread = experimental_cycle_speeds().loc[gaits, "cycle_speed_std_mm_s"].to_numpy(dtype=float)
    sign = np.array([1.0 if PAPER_DIRECTIONS[g] == "forward" else -1.0 for g in gaits])
    raw = (speed / spread) ** 2 if weights == "experimental" else np.ones(len(gaits))
    return pd.DataFrame({"exp_speed_mm_s": speed, "paper_sign": sign,
                         "target_signed_mm_s": sign * speed, "cycle_std_mm_s": spread,
                         "weight": raw / raw.mean()}, index=pd.Index(gaits, name="gait"))


def relative_signed_errors(signed_speeds, measurements: pd.DataFrame) -> np.ndarray:
    """(u_g − s_g v_g) / v_g for simulated signed speeds (..., G) in mm/s, G = the rows of
    `measurements` in order; ValueError unless the speeds' last axis is G long (one speed was
    spread over every gait by broadcasting: a mutation audit, 2026-12)."""
    # a number alone is the speed of a table of one gait
    signed_speeds = np.atleast_1d(np.asarray(signed_speeds, dtype=np.float64))
    gaits = list(measurements.index)
    if signed_speeds.shape[-1] != len(gaits):
        raise ValueError(f"signed_speeds must hold one speed per gait of measurements along "
                         f"its last axis ({len(gaits)}: {', '.join(map(str, gaits))}), got "
                         f"shape {signed_speeds.shape}")
    target = measurements["target_signed_mm_s"].to_numpy()
    return (signed_speeds - target) / measurements["exp_speed_mm_s"].to_numpy()


def objective_values(signed_speeds, measurements: pd.DataFrame) -> np.ndarray:
    """Weighted mean squared relative signed error, one value per point: signed speeds (P, G)
    -> (P,); inf for a point with any non-finite speed (a failed simulation) (the calibration
    objective of `python -m studies calibrate`).

    For gait g with measured full-trial speed v_g > 0 and the paper's direction s_g = ±1, the
    relative signed error of a simulated signed speed u_g is r_g = (u_g − s_g v_g) / v_g, so
    r_g = 0 at the measurement and r_g ≤ −1 (forward gait) or ≥ +1 (reverse gait) whenever the
    direction is wrong. The objective is the weighted mean of r_g² over the gaits, with weights
    w_g ∝ (v_g / σ_g)² normalised to mean 1, σ_g the spread of the measured per-cycle speeds
    (`experimental_cycle_speeds`): the squared error in units of the measurement's own
    relative spread. `weights="uniform"` gives every gait weight 1."""
    errors = np.atleast_2d(relative_signed_errors(signed_speeds, measurements))
    weights = measurements["weight"].to_numpy()
    values = (errors ** 2 * weights).sum(axis=1) / weights.sum()
    return np.where(np.isfinite(values), values, np.inf)
