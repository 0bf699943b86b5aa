"""The trajectory objective: a simulated robot against the measured one, cycle by cycle.

The net speeds of the paper's gaits are five numbers; the recordings hold the whole path at
59.94 frames/s, 7–19 cycles per gait: the surge during each heating pulse and the glide through
the coast. This module compares those paths with simulated ones.

Per cycle k of a path, the *cycle curve* is the distance travelled from the cycle's start,
d_k(τ) = |p(t_k + τ) − p(t_k)| at τ = T/M, 2T/M, ..., T (M = `samples` per cycle; τ = 0, where
every curve is 0, is left out; d_k(T) is the cycle's chord). Distances, not coordinates: camera
axes are not robot axes, so headings are never compared.

- The simulation starts from rest with a pulse at t = 0: its cycle k starts at (k − 1)·T.
- The video does not start at a pulse: a trial's pulses fire at φ + (k − 1)·T with an unknown
  phase φ ∈ [0, T] (both ends: φ = T is φ = 0 on the window a cycle later), a nuisance
  parameter fitted per trial (`align_phase`): the φ that minimises
  the squared difference between the measured and simulated cycle curves over the cycle
  window, found on a grid of `PHASE_GRID` phases (about two per video frame), then refined by
  golden-section search in the grid cells on either side of each of the grid's
  `PHASE_VALLEYS` lowest local minima.
- Residuals are in units of the measurement's own spread across cycles: σ = the root mean
  over τ of the variance of the measured d_k(τ) across the window's cycles (ddof = 1), at least
  `DISPLACEMENT_FLOOR_MM` (the tracking noise; the floor alone for a one-cycle window).
- Direction: Δ = the simulated net displacement over the window projected on the gait's forward
  axis (mm) must have the paper's sign s (+1 forward, −1 reverse); the direction residual
  ρ = max(0, −s·Δ) / σ is the wrong-way travel in the same units, so a robot that swims the
  right distance the wrong way pays (Δ/σ)², far more than any error of the curve's shape.

A trial's objective is mean_k,τ ((d_sim − d_meas)/σ)² + ρ², and `trajectory_objective` is the
mean over the gaits. The cycle window (`cycles`, 1-based, inclusive) is an argument: the paper's
window is `TRAINING_CYCLES` = cycles 1–3; `VALIDATION_CYCLES` (4–6) is held back for validation
(with the phase fitted on the training window). Nothing after the window's last cycle is read.

    >>> from taichi_star import StarParams, identification, simulate
    >>> trials = identification.measured_trials()                 # the five paper gaits
    >>> params = [StarParams(gait=g) for g in trials]
    >>> result = simulate(params, 3 * 3.15, record_interval_s=0.01)
    >>> runs = identification.result_runs(result, params)       # None for a failed robot
    >>> table = identification.trajectory_objective(dict(zip(trials, runs)), trials)
    >>> identification.objective_of(table)      # ≈ 60 for the paper's model on cycles 1-3

Gradient (`objective_and_gradient`): with `simulate(..., sensitivities=names)` the records carry
dx/dθ and dy/dθ, and the objective's gradient follows by the chain rule, exact for the scheme up
to the sensitivities' own accuracy:

- a record interpolated linearly onto the τ grid has as derivative the same interpolation of
  the records' derivatives (`path_derivative`);
- a distance d = |Δp| has dd = Δp·dΔp / |Δp| (`distance_derivative`; 0 where Δp = 0, where d
  has no derivative and 0 is a subgradient);
- ρ = max(0, −sΔ)/σ has dρ = −s·dΔ/σ where −sΔ > 0 and 0 where −sΔ ≤ 0 (the left derivative
  at the kink: the direction already right);
- the phase φ per trial is re-fitted at every θ, and it moves with θ. It minimises the curve
  misfit M = Σ(d_sim − d_meas)², so its own derivative drops out (envelope theorem) of every
  term proportional to that misfit; what remains is ∂J/∂φ·dφ/dθ through σ(φ) (the measured
  spread at the phase) and ρ/σ (`phase_motion`). The implicit function theorem on ∂M/∂φ = 0
  gives dφ/dθ = −(∂²M/∂φ∂θ)/(∂²M/∂φ²), with ∂²M/∂φ∂θ = −2 Σ (∂d_sim/∂θ)·(∂d_meas/∂φ): the
  φ-derivatives are of the measured data alone (central differences with step
  `PHASE_STEP_S`, within one linear piece of the interpolated video track), the θ-derivatives
  those of the records. The term is zero, and left out, when σ is at its floor
  `DISPLACEMENT_FLOOR_MM` (always on a one-cycle window), when the phase is given (held), at
  the edge of its range (0 or `latest_phase`), where the bound holds it, and where the fitted
  phase sits at a kink of the interpolated track (`PHASE_KINK_RATIO`; on the measured trials
  the fitted phase often lies on a frame time). There the re-fitted objective is in general
  differentiable from one side only (the phase stays on the kink for θ moved one way and
  slides off it the other way), and the gradient returned is that of the phase held, the
  side where it stays: an audit (2026-12, with the earlier phase search) measured the paper
  model's A1 α derivative on cycles 1–3 2.2 % off the central difference there and within
  2·10⁻⁴ of the one-sided one. On the synthetic
  three-cycle window of tests/unit/test_identification_gradient.py it is 14–40 % of the
  gradient, which then equals central differences of the re-fitted objective.

The objective is a sum of squares, and `objective_residuals` gives it in that form: the
residuals r (every gait's curve residuals and ρ, scaled so that Σ r² is the objective) and
their Jacobian J from the same record derivatives, at the fitted phases held, for a
Gauss-Newton or trust-region least-squares fit (`scipy.optimize.least_squares(fun, x0,
jac=...)`; holding the nuisance parameters in the Jacobian is Kaufman's form of variable
projection); the gradient above is 2·Jᵀr plus `phase_motion`, which is zero on a one-cycle
window.

What the data determine, locally, from r and J at a fitted point: `parameter_uncertainty`
(each parameter's Gauss-Newton standard error, or "not identifiable"), `prediction_uncertainty`
(the same for any prediction y(θ) with its gradient), `gait_predictions` (every gait's speed
with the fit on every measured gait and on all but one: a linearised leave-one-gait-out).
Which trial to measure next: a trial's rows of J depend on the simulated path and its spread
alone (`trial_rows`), so a trial not yet made can be taken as made, its rows below J and its
residuals scattering as the fit's own (`added_jacobian`, `gait_predictions`' `added`):
`trial_design` and `parameter_design` score sets of candidate trials by what the fits would
then determine.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass
from typing import Mapping, Optional, Sequence, Tuple

import numpy as np
import pandas as pd

from .checks import check_finite, check_flag, is_finite_real, is_real, is_whole, shown
from .experiment import EXPERIMENT_PERIOD_S, PAPER_DIRECTIONS, PAPER_GAITS, experimental_trajectory
from .gait import Gait

# every public name: docs/api.md documents the whole module
__all__ = ["TRAINING_CYCLES", "VALIDATION_CYCLES", "SAMPLES_PER_CYCLE", "MAX_CYCLE",
           "MAX_SAMPLES_PER_CYCLE", "PHASE_GRID", "PHASE_VALLEYS", "DISPLACEMENT_FLOOR_MM",
           "PHASE_STEP_S", "PHASE_KINK_RATIO", "GOLDEN_ITERATIONS", "UNCERTAINTY_RCOND",
           "UNCERTAINTY_SHARE", "UNCERTAINTY_COLUMNS", "TRIAL_COLUMNS", "CentroidPath", "Trial",
           "SimulatedRun", "TrialFit", "measured_trial", "check_window", "check_samples",
           "tau_grid", "cycle_curves", "latest_phase", "align_phase", "trial_fit",
           "trajectory_objective", "objective_of", "measured_trials", "simulated_runs",
           "result_runs", "distance_derivative", "path_derivative", "residual_count",
           "trial_residuals", "objective_residuals", "trial_phase_motion",
           "objective_and_gradient", "phase_motion", "parameter_uncertainty", "record_derivatives",
           "PredictionUncertainty", "prediction_uncertainty", "PREDICTION_COLUMNS", "window_speed",
           "gait_predictions", "trial_rows", "DESIGN_COLUMNS", "MAX_DESIGN_SETS",
           "trial_design", "parameter_design", "DESIGN_SUMMARY_COLUMNS", "design_summary",
           "design_set_count",
           "STROKE_WINDOW_S", "STROKE_TOLERANCE_S", "STROKE_ONSET_SHARE",
           "STROKE_MIN_JUMP_RATIO", "Strokes", "window_moves", "circular_difference", "strokes",
           "stroke_aligned_phase"]

TRAINING_CYCLES = (1, 3)
"""The fit window, cycles 1–3 of every trial (the paper's three cycles from rest)."""
VALIDATION_CYCLES = (4, 6)
"""The validation window: cycles the fit never sees (every measured trial has at least 6)."""
SAMPLES_PER_CYCLE = 64
"""Points of a cycle curve (every T/64 ≈ 49 ms: the 150-ms surge gets three)."""
MAX_CYCLE = 1000
"""The last cycle a window (`check_window`) may reach: 50 times the longest measured trial
(A1's 19 cycles of 3.15 s); a window is compared with a trial that covers it, and a window
of 10**12 cycles allocated terabytes before failing."""
MAX_SAMPLES_PER_CYCLE = 1024
"""The most points of a cycle curve (`samples`): 5 times the video frames of a 3.15-s cycle
(59.94 frames/s: 189; between frames the track is linear, so more points add nothing). With
`MAX_CYCLE` a window's curves hold at most ~1e6 points (16 MB), a phase fit seconds."""
PHASE_GRID = 384
"""Phases of the grid search of `align_phase`, about two per video frame of the paper's period
(59.94 frames/s × 3.15 s = 189 frames): the misfit ripples from frame to frame, and a grid of
64 (until 2026-12) missed valleys narrower than its cells (an audit: the `identified` preset's
A1 on cycles 1–3 fitted 2.3 % above its best phase, 0.81 s away). Over 160 windows of the
measured tracks fitted to one another, the 64-point search was up to 19 % above the best of
20,001 phases, one of 192 points up to 1.9 %, this one at most 0.09 % (about 20 ms a fit)."""
PHASE_VALLEYS = 4
"""The lowest local minima of the phase grid that `align_phase` refines, the best of them
returned: the valley of the best grid point is not always the deepest."""
DISPLACEMENT_FLOOR_MM = 0.05
"""Smallest spread σ, mm: the centroid tracking jitters by a few hundredths of a millimetre
from frame to frame (the median frame-to-frame speed change of the recordings is 2–2.7 mm/s,
i.e. ≈ 0.04 mm per frame)."""
PHASE_STEP_S = 1e-6
"""Step of the central differences in the phase (`phase_motion`), s: far inside one video
frame (16.7 ms; the track is linear between frames), so the differences are exact for most
curve samples; their rounding, ~1e-16·M/h², was 4e-8 of ∂²M/∂φ² on the measured A1+A3
track (tests/unit/test_identification_gradient.py)."""
PHASE_KINK_RATIO = 10.0
"""The second step of the kink test, PHASE_KINK_RATIO × PHASE_STEP_S: where the misfit's
curvature at the small step exceeds twice that at the large one (a kink gives 1/h: ten times;
a smooth piece the same value), the fitted phase sits at a kink of the interpolated track
(a frame time of a cycle's reference point pulls every sample of that cycle at once), where it
stays as θ moves: it has no motion."""
GOLDEN_ITERATIONS = 40
"""Golden-section steps of the phase refinement: the bracket of two grid cells shrinks by
0.618^40 ≈ 4e-9 of itself."""

UNCERTAINTY_RCOND = 1e-5
"""`parameter_uncertainty`: singular values of the relative Jacobian at most this fraction of
its largest are not resolved. The sensitivities are held to 1e-5 relative, and an error δJ
moves every singular value by at most ‖δJ‖ (Weyl), so a direction that weak cannot be told from
one the data do not see at all (an exact invariance of the model gives ~1e-9 here)."""
UNCERTAINTY_SHARE = 1e-2
"""`parameter_uncertainty`: a parameter is identifiable when its share of the unresolved
directions (the norm of its components along them) is at most this: a step along any of them
moves it by at most 1 % of the step."""
UNCERTAINTY_COLUMNS = ["parameter", "value", "standard_error", "relative_standard_error",
                       "identifiable", "unresolved_share", "most_correlated_with",
                       "correlation", "rank", "condition_number", "residual_dof"]
"""Columns of `parameter_uncertainty`'s table, one row per parameter."""

TRIAL_COLUMNS = ["gait", "first_cycle", "last_cycle", "phase_s", "sigma_mm",
                 "trajectory_error", "direction_residual", "objective", "sim_net_signed_mm",
                 "meas_net_mm", "sim_speed_mm_s", "meas_speed_mm_s", "direction_matches"]
"""Columns of `trajectory_objective`'s table, one row per gait: the window, the fitted phase
(s), σ (mm), mean squared curve residual, direction residual ρ, the gait's objective, the
simulated net displacement over the window along the forward axis (mm) and the measured net
displacement's magnitude (mm), both speeds over the window (mm/s; the simulated one signed), and
whether the simulated direction is the paper's."""


@dataclass(frozen=True)
class CentroidPath:
    """A tracked or simulated centroid path: times t_s (n,) s strictly increasing, positions
    x_mm, y_mm (n,) mm, the actuation period (s). For a simulation the pulses fire at
    0, T, 2T, ...; for a measurement at an unknown phase."""

    t_s: np.ndarray
    x_mm: np.ndarray
    y_mm: np.ndarray
    period_s: float

    def __post_init__(self):
        arrays = [np.asarray(getattr(self, name), dtype=np.float64)
                  for name in ("t_s", "x_mm", "y_mm")]
        if not (arrays[0].ndim == 1 and len(arrays[0]) >= 2
                and all(a.shape == arrays[0].shape for a in arrays)):
            raise ValueError("t_s, x_mm and y_mm must be 1-D arrays of one length >= 2")
        if np.any(np.diff(arrays[0]) <= 0) or not all(np.isfinite(a).all() for a in arrays):
            raise ValueError("t_s must be strictly increasing and t_s, x_mm, y_mm finite")
        check_finite("period_s", self.period_s, 0.0)
        for name, array in zip(("t_s", "x_mm", "y_mm"), arrays):
            object.__setattr__(self, name, array)

    def position(self, t_s) -> np.ndarray:
        """Positions (..., 2) mm at times (...) s, linear between samples."""
        return np.stack([np.interp(t_s, self.t_s, self.x_mm),
                         np.interp(t_s, self.t_s, self.y_mm)], axis=-1)


@dataclass(frozen=True)
class Trial:
    """A measured trial: its gait (canonical name), its path and the paper's direction sign
    (+1 forward, −1 reverse). The path starts at t = 0 s, the time its phases are counted from
    (a track starting later was compared from 0 all the same, and refused only as too short;
    an audit, 2026-12): ValueError otherwise."""

    gait: str
    path: CentroidPath
    paper_sign: float

    def __post_init__(self):
        if not isinstance(self.path, CentroidPath):
            raise ValueError(f"path must be a CentroidPath, got {type(self.path).__name__}")
        if self.path.t_s[0] != 0.0:
            raise ValueError(f"the {self.gait} trial's path must start at t = 0 s (its phases "
                             f"count from there), got t_s[0] = {self.path.t_s[0]:g} s")


@dataclass(frozen=True)
class SimulatedRun:
    """A simulated trial: its gait, its path (pulses at 0, T, ...) and the gait's forward unit
    vector in the simulation's axes."""

    gait: str
    path: CentroidPath
    forward: Tuple[float, float]


@dataclass(frozen=True)
class TrialFit:
    """The comparison of one simulated trial with the measured one (see `TRIAL_COLUMNS`)."""

    gait: str
    first_cycle: int
    last_cycle: int
    phase_s: float
    sigma_mm: float
    trajectory_error: float
    direction_residual: float
    objective: float
    sim_net_signed_mm: float
    meas_net_mm: float
    sim_speed_mm_s: float
    meas_speed_mm_s: float
    direction_matches: bool


def measured_trial(gait: str, period_s: float = EXPERIMENT_PERIOD_S) -> Trial:
    """The recorded trial of one of the paper's gaits (`experiment.experimental_trajectory`)."""
    table = experimental_trajectory(gait)
    name = Gait.parse(gait).name
    return Trial(name, CentroidPath(table["t_s"].to_numpy(), table["x_mm"].to_numpy(),
                            table["y_mm"].to_numpy(), period_s),
                 1.0 if PAPER_DIRECTIONS[name] == "forward" else -1.0)


def check_window(cycles) -> Tuple[int, int]:
    """(first, last) 1-based inclusive cycle numbers, 1 ≤ first ≤ last ≤ `MAX_CYCLE`;
    ValueError naming `cycles` otherwise."""
    try:
        first, last = cycles
    except (TypeError, ValueError):
        raise ValueError(f"cycles must be a pair (first, last) of cycle numbers, got "
                         f"{cycles!r}") from None
    if not all(is_whole(c) for c in (first, last)) or not 1 <= first <= last <= MAX_CYCLE:
        raise ValueError(f"cycles must be integers with 1 <= first <= last <= {MAX_CYCLE} "
                         f"(MAX_CYCLE), got {cycles!r}")
    return int(first), int(last)


def check_samples(samples) -> int:
    """`samples` (points per cycle curve) as an int; ValueError naming it unless it is an
    integer in [1, `MAX_SAMPLES_PER_CYCLE`]."""
    if not is_whole(samples) or not 1 <= samples <= MAX_SAMPLES_PER_CYCLE:
        raise ValueError(f"samples must be an integer in [1, {MAX_SAMPLES_PER_CYCLE}] "
                         f"(MAX_SAMPLES_PER_CYCLE), got {samples!r}")
    return int(samples)


def tau_grid(period_s: float, samples: int = SAMPLES_PER_CYCLE) -> np.ndarray:
    """τ = T/M, 2T/M, ..., T (s), T = period_s (a finite number > 0), M = samples
    (`check_samples`)."""
    check_finite("period_s", period_s, 0.0, unit=" s")
    samples = check_samples(samples)
    return period_s * np.arange(1, samples + 1) / samples


def cycle_curves(path: CentroidPath, start_s: float, cycles, samples: int = SAMPLES_PER_CYCLE
                 ) -> np.ndarray:
    """Cycle curves (n_cycles, samples) mm of the cycles `cycles` = (first, last) of a path
    whose first cycle starts at start_s: cycle k spans [start + (k−1)T, start + kT]. ValueError
    when the path does not cover the window."""
    first, last = check_window(cycles)
    starts = start_s + path.period_s * np.arange(first - 1, last)
    end = starts[-1] + path.period_s
    if starts[0] < path.t_s[0] or end > path.t_s[-1] * (1 + 1e-12):
        raise ValueError(f"cycles {first}-{last} from {start_s:g} s need the path over "
                         f"[{starts[0]:g}, {end:g}] s; it covers [{path.t_s[0]:g}, "
                         f"{path.t_s[-1]:g}] s")
    origin = path.position(starts)                                    # (n, 2)
    points = path.position(starts[:, None] + tau_grid(path.period_s, samples)[None, :])
    return np.hypot(*np.moveaxis(points - origin[:, None, :], -1, 0))


def latest_phase(trial: Trial, cycles) -> float:
    """The latest phase (s) at which the trial still covers the window: min(T, t_end − last·T)
    (the phase search runs over [0, that))."""
    _, last = check_window(cycles)
    latest = min(trial.path.period_s, trial.path.t_s[-1] - last * trial.path.period_s)
    if latest < 0:
        raise ValueError(f"the {trial.gait} trial ({trial.path.t_s[-1]:g} s) is shorter than "
                         f"cycles up to {last}")
    return latest


def _misfit(simulated_curves: np.ndarray, trial: Trial, phase_s, cycles, samples) -> float:
    """Sum of squared differences (mm²) between simulated and measured cycle curves at one
    phase."""
    return float(((cycle_curves(trial.path, phase_s, cycles, samples) - simulated_curves) ** 2
                  ).sum())


def align_phase(simulated_curves: np.ndarray, trial: Trial, cycles=TRAINING_CYCLES,
                samples: int = SAMPLES_PER_CYCLE, grid: int = PHASE_GRID) -> float:
    """The trial's pulse phase φ (s) in [0, `latest_phase`] minimising the squared difference
    between its cycle curves and `simulated_curves` (n_cycles, samples) over `cycles`: the
    `PHASE_VALLEYS` lowest local minima of a grid of `grid` phases, each refined by
    golden-section search over the grid cells on either side of it (the misfit is smooth in φ
    between video frames: linear interpolation of the path), the best of them (or of the grid)
    returned.

    Still a search, not a proof: a valley narrower than a grid cell, or deeper than the
    refined ones but higher on the grid, can be missed (`PHASE_GRID` gives the figures: at
    most 0.09 % above the best of 20,001 phases over 160 windows, the earlier 64-point search
    with one refinement up to 19 %)."""
    latest = latest_phase(trial, cycles)
    if not latest > 0:
        return 0.0
    phases = np.linspace(0.0, latest, grid, endpoint=False)
    misfits = np.array([_misfit(simulated_curves, trial, phase, cycles, samples)
                        for phase in phases])
    # the grid's local minima (an end where its one neighbour is not lower; a plateau once)
    minima = np.flatnonzero(np.r_[True, misfits[1:] < misfits[:-1]]
                            & np.r_[misfits[:-1] <= misfits[1:], True])
    step = latest / grid
    best = int(np.argmin(misfits))
    best_phase, best_misfit = phases[best], misfits[best]
    for index in minima[np.argsort(misfits[minima], kind="stable")][:PHASE_VALLEYS]:
        phase, misfit = _refined_phase(simulated_curves, trial, cycles, samples,
                                       max(0.0, phases[index] - step),
                                       min(latest, phases[index] + step))
        # a grid point itself where no refinement beats it (an exact match on the grid)
        if misfit < best_misfit:
            best_phase, best_misfit = phase, misfit
    return float(best_phase)


def _refined_phase(simulated_curves: np.ndarray, trial: Trial, cycles, samples, low: float,
                   high: float) -> Tuple[float, float]:
    """(phase s, misfit mm²) of a golden-section search of `GOLDEN_ITERATIONS` steps for the
    misfit's minimum over [low, high] s."""
    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    a, b = high - ratio * (high - low), low + ratio * (high - low)
    fa = _misfit(simulated_curves, trial, a, cycles, samples)
    fb = _misfit(simulated_curves, trial, b, cycles, samples)
    for _ in range(GOLDEN_ITERATIONS):
        if fa <= fb:
            high, b, fb = b, a, fa
            a = high - ratio * (high - low)
            fa = _misfit(simulated_curves, trial, a, cycles, samples)
        else:
            low, a, fa = a, b, fb
            b = low + ratio * (high - low)
            fb = _misfit(simulated_curves, trial, b, cycles, samples)
    return (float(a), fa) if fa <= fb else (float(b), fb)


def trial_fit(simulated: SimulatedRun, trial: Trial, cycles=TRAINING_CYCLES,
              samples: int = SAMPLES_PER_CYCLE, phase_s: Optional[float] = None) -> TrialFit:
    """Compare one simulated trial with the measured one over the cycle window (module
    docstring). `phase_s`: the trial's phase, fitted here when None (`align_phase`); give the
    phase fitted on the training window to validate on later cycles. ValueError for gaits that
    differ or a window the simulation or the trial does not cover. Each path's cycles are its
    own period's: a simulation at another period than the trial's (a fitted period) is compared
    sample for sample on the cycle's fraction, its curves' shape, not at equal times."""
    first, last = check_window(cycles)
    samples = check_samples(samples)
    if not isinstance(simulated, SimulatedRun):
        raise ValueError(f"simulated must be a SimulatedRun, got {type(simulated).__name__}")
    if not isinstance(trial, Trial):
        raise ValueError(f"trial must be a Trial (measured_trial), got {type(trial).__name__}")
    if Gait.parse(simulated.gait).name != trial.gait:
        raise ValueError(f"simulated gait {simulated.gait!r} is not the trial's {trial.gait!r}")
    sim_curves = cycle_curves(simulated.path, 0.0, (first, last), samples)
    if phase_s is None:
        phase_s = align_phase(sim_curves, trial, (first, last), samples)
    elif not (is_finite_real(phase_s) and 0.0 <= phase_s <= latest_phase(trial, cycles)):
        raise ValueError(f"phase_s must be in [0, {latest_phase(trial, cycles):g}] s, got "
                         f"{shown(phase_s)}")
    measured = cycle_curves(trial.path, phase_s, (first, last), samples)
    spread = (math.sqrt(float(np.mean(np.var(measured, axis=0, ddof=1))))
              if len(measured) > 1 else 0.0)
    sigma = max(spread, DISPLACEMENT_FLOOR_MM)
    error = float(np.mean(((sim_curves - measured) / sigma) ** 2))
    period, meas_period = simulated.path.period_s, trial.path.period_s
    sim_net, _ = _net_displacement(simulated, None, (first, last))
    meas_ends = trial.path.position(phase_s + np.array([first - 1, last]) * meas_period)
    meas_net = float(np.hypot(*(meas_ends[1] - meas_ends[0])))
    rho = max(0.0, -trial.paper_sign * sim_net) / sigma
    n_cycles = last - first + 1
    return TrialFit(trial.gait, first, last, float(phase_s), sigma, error, rho, error + rho ** 2,
                    sim_net, meas_net, sim_net / (n_cycles * period),
                    meas_net / (n_cycles * meas_period),
                    bool(np.sign(sim_net) == trial.paper_sign))


def trajectory_objective(simulated: Mapping[str, SimulatedRun], trials: Mapping[str, Trial],
                         cycles=TRAINING_CYCLES, samples: int = SAMPLES_PER_CYCLE,
                         phases: Optional[Mapping[str, float]] = None) -> pd.DataFrame:
    """`trial_fit` of every gait of `simulated` against its trial: one row per gait
    (`TRIAL_COLUMNS`); the objective of the whole set is the mean of the `objective` column
    (`objective_of`). `phases`: gait -> phase (s) to use instead of fitting it. A failed run
    (None, as `result_runs` gives it) scores an objective of inf, its other numbers NaN (it
    was a ValueError about its type)."""
    first, last = check_window(cycles)
    rows = []
    for gait, run in simulated.items():
        if gait not in trials:
            raise ValueError(f"no measured trial for gait {gait!r}; trials: {', '.join(trials)}")
        if phases is not None and gait not in phases:
            raise ValueError(f"phases has no phase for gait {gait!r}; phases: "
                             f"{', '.join(phases)}")
        if run is None:
            rows.append({**dict.fromkeys(TRIAL_COLUMNS, math.nan), "gait": gait,
                         "first_cycle": first, "last_cycle": last, "objective": math.inf,
                         "direction_matches": False})
            continue
        phase = None if phases is None else phases[gait]
        rows.append(dataclasses.asdict(trial_fit(run, trials[gait], cycles, samples, phase)))
    return pd.DataFrame(rows, columns=TRIAL_COLUMNS)


def objective_of(table: pd.DataFrame) -> float:
    """The set's objective: the mean of the gaits' objectives (inf if any is not finite: a
    NaN among finite ones was skipped by the mean until 2026-12)."""
    value = float(table["objective"].mean(skipna=False))
    return value if math.isfinite(value) else math.inf


def measured_trials(gaits: Sequence[str] = PAPER_GAITS,
                    period_s: float = EXPERIMENT_PERIOD_S) -> dict:
    """{gait: `measured_trial`} of the gaits."""
    return {Gait.parse(g).name: measured_trial(g, period_s) for g in gaits}


def simulated_runs(trajectory: pd.DataFrame, gaits: Sequence[str],
                   periods_s: Sequence[float]) -> list:
    """`SimulatedRun`s from a batch's recorded trajectory (columns instance, t_s, x_mm, y_mm;
    instance b = position b of `gaits` and `periods_s`); None for an instance with a non-finite
    record (a failed simulation)."""
    runs = []
    groups = dict(tuple(trajectory.groupby("instance", sort=True)))
    for b, (gait, period) in enumerate(zip(gaits, periods_s)):
        part = groups.get(b)
        forward = Gait.parse(gait).forward
        if part is None or forward is None or not np.isfinite(
                part[["t_s", "x_mm", "y_mm"]].to_numpy()).all():
            runs.append(None)
            continue
        runs.append(SimulatedRun(Gait.parse(gait).name,
                                 CentroidPath(part["t_s"].to_numpy(), part["x_mm"].to_numpy(),
                                      part["y_mm"].to_numpy(), float(period)),
                                 (float(forward[0]), float(forward[1]))))
    return runs


def result_runs(result, params: Sequence) -> list:
    """`simulated_runs` of a simulation's result (`simulate`'s or `run_batch`'s: its
    `trajectory` and `summary`) for the models `params` it ran (instance b = params[b]), None
    also where an instance's status is not "ok" (a flagged instance's records can be finite)."""
    runs = simulated_runs(result.trajectory, [p.gait for p in params], [p.period for p in params])
    ok = result.summary["status"].to_numpy() == "ok"
    return [run if good else None for run, good in zip(runs, ok)]


# --------------------------------------------------------------------------- strokes

STROKE_WINDOW_S = 0.1
"""Window of `strokes`, s: six video frames, under the heating pulse (0.15 s), over which the
measured robot jumps by 2.5–2.7 mm at the strokes of A1+A2 and A1+A4 against ~0.5 mm at other
times (`results/strokes.csv`)."""
STROKE_TOLERANCE_S = 0.2
"""A cycle's stroke within this of the path's stroke phase (circularly, ≤) is consistent with
it, and within this of the strokes' line on it (`strokes`): a third of a heating-and-recovery
surge, well inside the 3.15-s period."""


STROKE_ONSET_SHARE = 0.5
"""`strokes`' default onset_share: a period's stroke starts at the first window whose move
rises halfway from the path's typical move to the period's farthest move. Read at its farthest
move instead, A1+A2's first two strokes came ~0.25 s late (a second surge after the first, in a
noisy start), which tilted its line to a period of 3.128 s where its onsets give 3.178 s
(results/strokes.csv; an audit, 2026-12-05, read 3.176 s at a fixed 1.2-mm threshold). Each
period's own farthest move, not the strokes' median, sets its onset: a simulation from rest
strokes more weakly in its first cycle, whose moves may not reach the later cycles' onset. At
0.4 or 0.6 instead the measured periods move by at most 3 ms but A1+A3's, by about 11 ms
(results/strokes.csv's pulse_period_low/high_onset_s)."""

STROKE_MIN_JUMP_RATIO = 1.2
"""A period has a stroke only where its farthest move is at least this many times the path's
typical move (≥): else its halfway point lies in the noise, whose first crossing comes early
in every period and lines up as strokes that are not there (a drift with a 1-µm jitter read as
periodic in nearly every draw: an audit, 2026-12-05). Such a jitter's periods reach 1.06–1.10,
the measured tracks' 2.1–6.5. A simulation has no such noise: its readings take every stroke
(`strokes(..., min_jump_ratio=1)` in `stroke_aligned_phase` and the strokes study), its first
from rest too, whose ratio is 1.06–1.54 (the identified and paper presets)."""


@dataclass(frozen=True)
class Strokes:
    """The strokes of a path (`strokes`): per whole period k (from the path's first time t₀, over
    [t₀ + kT, t₀ + (k+1)T)), the window start at which the stroke begins: the first window in
    the period that moves at least its onset within `window_s` where the window before it
    moved less (the moves rise to it there), NaN for a period where none does or whose
    farthest move does not stand out (`strokes`' min_jump_ratio).

    phase_s: their circular mean over the periods with a stroke, in [0, T) from t₀, s;
    cycle_phases_s (K,): each period's, s (NaN: no stroke); cycles K; consistent_cycles: those
    within `STROKE_TOLERANCE_S` of phase_s (circularly, ≤); jump_mm: the median over the
    periods of the farthest move within a window, mm; typical_mm: the median move within a
    window over the whole path, mm (how far the robot goes in `window_s` anyway);
    cycle_onsets_mm (K,): each period's onset, typical_mm + onset_share (`strokes`) × (the
    period's farthest move − typical_mm), mm; stroke_times_s (K,): where each period's stroke
    begins on the path's clock (the window start, one of the path's sample times), s (NaN: no
    stroke).

    The strokes' line: drift_s, how much later each period's stroke comes than the one before,
    s per period (the Theil–Sen slope of the periods' phases unwrapped from stroke to stroke; 0
    for one stroke), and line_phase_s, its phase in period 0, in [0, T) (the median of the
    unwrapped phases less the drift's share); on_line_cycles: the strokes within
    `STROKE_TOLERANCE_S` of it (circularly, ≤). `periodic`: more than half the periods' strokes
    are, and the pulses come every T + drift_s; where not (strokes scattered over the period,
    or missing), drift_s and line_phase_s are NaN: no period to read (and phase_s too where no
    period has a stroke)."""

    phase_s: float
    cycle_phases_s: np.ndarray
    cycles: int
    consistent_cycles: int
    jump_mm: float
    typical_mm: float
    drift_s: float
    line_phase_s: float
    on_line_cycles: int
    period_s: float
    """T, the period the path was read with, s."""
    cycle_onsets_mm: np.ndarray
    stroke_times_s: np.ndarray

    @property
    def periodic(self) -> bool:
        """Whether more than half the strokes lie on their line (see the class docstring)."""
        return 2 * self.on_line_cycles > self.cycles

    def line_phases(self, periods) -> np.ndarray:
        """The line's phase (s, in [0, T)) at period indices `periods` (from 0); NaN where the
        strokes are not `periodic`."""
        return (self.line_phase_s + self.drift_s * np.asarray(periods, dtype=float)
                ) % self.period_s


def window_moves(path: CentroidPath, window_s: float) -> Tuple[np.ndarray, np.ndarray]:
    """(times (n,) s, moves (n,) mm): how far the path goes between each sample time t and
    t + window_s (linear between samples), for every sample at least a window before its
    end."""
    times = path.t_s[path.t_s <= path.t_s[-1] - window_s]
    return times, np.linalg.norm(path.position(times + window_s) - path.position(times),
                                 axis=-1)


def circular_difference(later, earlier, period: float):
    """later − earlier (s, arrays or numbers) on a circle of `period`, in (−period/2,
    period/2]."""
    gap = np.mod(np.subtract(later, earlier) + period / 2, period) - period / 2
    return np.where(gap == -period / 2, period / 2, gap)


def strokes(path: CentroidPath, window_s: float = STROKE_WINDOW_S,
            tolerance_s: float = STROKE_TOLERANCE_S, from_rest: bool = False,
            min_jump_ratio: float = STROKE_MIN_JUMP_RATIO,
            onset_share: float = STROKE_ONSET_SHARE) -> Strokes:
    """When a path's stroke begins in each period (`Strokes`): a model-free reading of when a
    measured trial's pulses fire, which the video does not record (`align_phase` fits the phase
    to a simulation instead). The moves are taken between every sample time t and t + window_s
    (linear between samples); a stroke begins at the first window start of its period whose
    move rises to the period's onset (≥, from below it at the sample before), `onset_share` of
    the way from the typical move to the period's farthest (`STROKE_ONSET_SHARE`, halfway;
    `Strokes.cycle_onsets_mm`), in a period whose farthest is at least `min_jump_ratio` times
    the typical move (≥; `STROKE_MIN_JUMP_RATIO`; 1 takes every period's). The path's first
    window rises to it only `from_rest` (a simulation from rest: nothing moved before it); a
    track's does not (what moved before it is not known). ValueError for a window outside
    (0, T/2], a tolerance outside [0, T/2], a `from_rest` that is not a flag, a
    `min_jump_ratio` not a finite number ≥ 1, an `onset_share` outside (0, 1), a path shorter
    than one period and one window, or one with a gap between samples longer than the window
    (a period's farthest move would be read across it)."""
    period = path.period_s
    # is_finite_real: math.isfinite(10**400) raised an OverflowError (an audit, 2026-12)
    if not (is_finite_real(window_s) and 0 < window_s <= period / 2):
        raise ValueError(f"window_s must be in (0, {period / 2:g}] s (half the period), got "
                         f"{shown(window_s)}")
    if not (is_finite_real(tolerance_s) and 0 <= tolerance_s <= period / 2):
        raise ValueError(f"tolerance_s must be in [0, {period / 2:g}] s (half the period), got "
                         f"{shown(tolerance_s)}")
    from_rest = check_flag("from_rest", from_rest)
    check_finite("min_jump_ratio", min_jump_ratio, 1.0, lowest_included=True)
    if not (is_real(onset_share) and 0 < onset_share < 1):
        raise ValueError(f"onset_share must be in (0, 1), got {onset_share!r}")
    start = path.t_s[0]
    # a path that ends a window after a period's end covers that period (the floor of the
    # quotient, rounded just below the whole number, was one short: an audit, 2026-12-05)
    cycles = math.floor((path.t_s[-1] - window_s - start) / period + 1e-9)
    if cycles < 1:
        raise ValueError(f"the path covers {path.t_s[-1] - start:g} s: strokes needs at least "
                         f"one period and one window ({period + window_s:g} s)")
    gaps = np.diff(path.t_s)
    if gaps.max() > window_s * (1 + 1e-9):  # a gap of the window itself, rounded, is read
        at = int(np.argmax(gaps))
        raise ValueError(f"path has a gap of {gaps[at]:g} s after t = {path.t_s[at]:g} s, "
                         f"longer than window_s = {window_s:g} s: its moves there are not "
                         f"measured")
    times, moves = window_moves(path, window_s)
    cycle_of = np.floor((times - start) / period).astype(np.int64)
    inside = [np.flatnonzero(cycle_of == cycle) for cycle in range(cycles)]
    jumps = np.array([moves[window].max() for window in inside])
    typical = float(np.median(moves))
    onsets = typical + onset_share * (jumps - typical)
    before = np.concatenate([[0.0 if from_rest else math.inf], moves[:-1]])
    stroke_times = np.full(cycles, math.nan)
    for cycle, window in enumerate(inside):
        # a stroke begins where the moves rise to the onset: a period that opens on a stroke
        # begun in the one before is not one of its own
        reaching = window[(moves[window] >= onsets[cycle]) & (before[window] < onsets[cycle])]
        if reaching.size and jumps[cycle] >= min_jump_ratio * typical:
            stroke_times[cycle] = times[reaching[0]]
    phases = stroke_times - start - period * np.arange(cycles)
    stroked = np.flatnonzero(np.isfinite(phases))
    if not stroked.size:  # one period that opens on its stroke (its moves never rise)
        return Strokes(math.nan, phases, cycles, 0, float(np.median(jumps)), typical, math.nan,
                       math.nan, 0, period, onsets, stroke_times)
    read = phases[stroked]
    phase = _circular_mean(read, period)
    apart = np.abs(circular_difference(read, phase, period))
    steps = circular_difference(read[1:], read[:-1], period)
    unwrapped = read[0] + np.concatenate([[0.0], np.cumsum(steps)])
    first, second = np.triu_indices(stroked.size, k=1)  # every pair of strokes, first < second
    drift = float(np.median((unwrapped[second] - unwrapped[first])
                            / (stroked[second] - stroked[first]))) if stroked.size > 1 else 0.0
    line = float(np.median(unwrapped - drift * stroked))
    off_line = np.abs(circular_difference(read, line + drift * stroked, period))
    on_line = int(np.sum(off_line <= tolerance_s))
    if 2 * on_line <= cycles:
        drift = line = math.nan
    return Strokes(phase, phases, cycles, int(np.sum(apart <= tolerance_s)),
                   float(np.median(jumps)), typical, drift,
                   line % period if math.isfinite(line) else line, on_line, period, onsets,
                   stroke_times)


def _circular_mean(phases: np.ndarray, period: float) -> float:
    """The circular mean of phases (s) on a circle of `period`, in [0, period)."""
    turns = np.exp(2j * np.pi * np.asarray(phases) / period)
    return float(np.angle(turns.mean()) % (2 * np.pi) * period / (2 * np.pi)) % period


def stroke_aligned_phase(simulated: SimulatedRun, trial: Trial, cycles=TRAINING_CYCLES,
                         measured: Optional[Strokes] = None,
                         window_s: float = STROKE_WINDOW_S) -> float:
    """The trial's phase (s) that puts the simulation's strokes on the measured ones over the
    cycle window, for `trajectory_objective(..., phases=...)` instead of fitting it: the
    circular mean of the measured strokes' line (`Strokes.line_phases`: robust to a stroke
    read off elsewhere, and drifting as the pulses do) over the window's periods, minus the
    circular mean of the simulated strokes of the window's cycles (`strokes` from rest, read
    over the run through the window's last cycle and one window more, which the simulation
    must cover: it may run longer, the phase does not depend on it; a cycle without a stroke
    is left out of the mean), in [0, T). The window's periods are the track's periods
    first−1..last−1
    (from its start), or first..last where the strokes come earlier in the period than the
    simulated lag (cycle k then starts just before the track's period k ends). `measured`:
    the trial's `strokes`, if already taken. ValueError where the trial's strokes are not
    `periodic` (no phase to hold) or end before the window, or where the simulation ends
    before the window's last cycle or has no stroke in it. A model-free constraint where the
    fitted phase can slide a model's strokes onto other moments of the cycle (results: the
    strokes in the tracks); the period stays the trial's."""
    first, last = check_window(cycles)
    measured = strokes(trial.path, window_s) if measured is None else measured
    if not measured.periodic:
        raise ValueError(f"{trial.gait}: its strokes do not lie on one period "
                         f"({measured.on_line_cycles} of {measured.cycles} within "
                         f"{STROKE_TOLERANCE_S:g} s of their line): no phase to hold")
    if measured.cycles < last + 1:
        raise ValueError(f"{trial.gait}: the track's strokes cover {measured.cycles} periods, "
                         f"the window ends at cycle {last} (one period more is needed)")
    period = trial.path.period_s
    # the simulated strokes of the window's own cycles, read over the run through them alone:
    # read over the whole run, a window's phase moved with how long the run went on past it
    # (its typical move, and so its onsets, do), and a fit's tables (cycles 1-6) scored its
    # training window 0.89-2.78x the error the fit (cycles 1-3) had minimised
    path = simulated.path
    through = np.searchsorted(path.t_s, path.t_s[0] + last * path.period_s + window_s,
                              side="right") + 1
    if through < path.t_s.size:  # up to the first sample past the last cycle's window
        path = CentroidPath(path.t_s[:through], path.x_mm[:through], path.y_mm[:through],
                            path.period_s)
    simulated_strokes = strokes(path, window_s, from_rest=True, min_jump_ratio=1.0)
    if simulated_strokes.cycles < last:
        raise ValueError(f"{trial.gait}: the simulation's strokes cover "
                         f"{simulated_strokes.cycles} periods, the window ends at cycle {last}")
    window_strokes = simulated_strokes.cycle_phases_s[first - 1:last]
    window_strokes = window_strokes[np.isfinite(window_strokes)]
    if not window_strokes.size:
        raise ValueError(f"{trial.gait}: the simulation has no stroke in cycles {first}-{last} "
                         f"(no window's move rises to halfway up its cycle's farthest): no lag "
                         f"to hold the phase by")
    lag = _circular_mean(window_strokes, simulated.path.period_s)
    phase = _circular_mean(measured.line_phases(range(first - 1, last)), period) - lag
    if phase < 0:
        phase = _circular_mean(measured.line_phases(range(first, last + 1)), period) - lag
    # in [0, T) <= latest_phase: the track covers one period past the window's last
    return float(phase % period)


# --------------------------------------------------------------------------- gradient

def distance_derivative(delta_mm: np.ndarray, delta_derivative: np.ndarray) -> np.ndarray:
    """Derivative of |Δp| from Δp (..., 2) and its derivatives (..., 2, P): Δp·dΔp/|Δp|, shape
    (..., P); 0 where |Δp| = 0 (the norm has no derivative there)."""
    delta_mm = np.asarray(delta_mm, dtype=np.float64)
    norm = np.hypot(delta_mm[..., 0], delta_mm[..., 1])
    safe = np.where(norm > 0, norm, 1.0)
    unit = np.where((norm > 0)[..., None], delta_mm / safe[..., None], 0.0)
    return np.einsum("...c,...cp->...p", unit, np.asarray(delta_derivative, dtype=np.float64))


def path_derivative(path: CentroidPath, derivative_xy: np.ndarray, t_s) -> np.ndarray:
    """Derivatives (..., 2, P) of `path.position(t_s)` from the records' derivatives
    derivative_xy (n, 2, P): the same linear interpolation in time (the record times do not
    depend on the parameters)."""
    t_s = np.asarray(t_s, dtype=np.float64)
    n, _, count = derivative_xy.shape
    flat = derivative_xy.reshape(n, 2 * count)
    values = np.stack([np.interp(t_s, path.t_s, flat[:, j]) for j in range(2 * count)], axis=-1)
    return values.reshape(t_s.shape + (2, count))


def _window_times(start_s: float, period_s: float, cycles, samples: int):
    first, last = check_window(cycles)
    starts = start_s + period_s * np.arange(first - 1, last)
    return starts, starts[:, None] + tau_grid(period_s, samples)[None, :]


def _curve_derivative(path: CentroidPath, derivative_xy, cycles, samples) -> np.ndarray:
    """d(cycle curves)/dθ (n_cycles, samples, P) of a simulated path (cycle k from (k−1)T)."""
    starts, times = _window_times(0.0, path.period_s, cycles, samples)
    delta = path.position(times) - path.position(starts)[:, None, :]
    derivative = (path_derivative(path, derivative_xy, times)
                  - path_derivative(path, derivative_xy, starts)[:, None, :, :])
    return distance_derivative(delta, derivative)


def _window_ends(path: CentroidPath, cycles) -> np.ndarray:
    """The start and end (2,) s of the cycle window on a simulated path (its cycle k from
    (k − 1)T). ValueError when the path does not cover the window."""
    first, last = check_window(cycles)
    times = np.array([first - 1, last]) * path.period_s
    if times[0] < path.t_s[0] or times[1] > path.t_s[-1] * (1 + 1e-12):
        # as `cycle_curves`: the interpolation would hold the path's last point silently
        raise ValueError(f"cycles {first}-{last} need the simulated path over [{times[0]:g}, "
                         f"{times[1]:g}] s; it covers [{path.t_s[0]:g}, {path.t_s[-1]:g}] s")
    return times


def _net_displacement(simulated: SimulatedRun, derivative_xy: Optional[np.ndarray], cycles
                      ) -> Tuple[float, Optional[np.ndarray]]:
    """A simulated run's net displacement over the cycle window along its gait's forward
    axis (mm; `TrialFit.sim_net_signed_mm`) and its derivative (P,) from the records'
    derivatives derivative_xy (n_records, 2, P; None: no derivative, None returned).
    ValueError when the path does not cover the window."""
    path, forward = simulated.path, np.asarray(simulated.forward)
    times = _window_ends(path, cycles)
    positions = path.position(times)
    net = float(np.dot(positions[1] - positions[0], forward))
    if derivative_xy is None:
        return net, None
    ends = path_derivative(path, derivative_xy, times)
    return net, np.einsum("c,cp->p", forward, ends[1] - ends[0])


def residual_count(gaits: int, cycles=TRAINING_CYCLES, samples: int = SAMPLES_PER_CYCLE) -> int:
    """The number of residuals of `objective_residuals` for `gaits` gaits on the window
    `cycles`: per gait its cycles × samples curve residuals and ρ. ValueError naming gaits
    unless it is an integer >= 1, or naming cycles or samples (`check_window`,
    `check_samples`)."""
    if not is_whole(gaits) or gaits < 1:
        raise ValueError(f"gaits must be an integer >= 1 (the number of gaits), got {gaits!r}")
    first, last = check_window(cycles)
    samples = check_samples(samples)
    return int(gaits) * ((last - first + 1) * samples + 1)


def _checked_derivative(simulated: SimulatedRun, derivative_xy) -> np.ndarray:
    """derivative_xy as float64 (n_records, 2, P), or ValueError naming its shape."""
    derivative_xy = np.asarray(derivative_xy, dtype=np.float64)
    if derivative_xy.ndim != 3 or derivative_xy.shape[:2] != (len(simulated.path.t_s), 2):
        raise ValueError(f"derivative_xy must have shape ({len(simulated.path.t_s)}, 2, P), got "
                         f"{derivative_xy.shape}")
    return derivative_xy


def trial_rows(simulated: SimulatedRun, derivative_xy: np.ndarray, sigma_mm: float,
               cycles=TRAINING_CYCLES, samples: int = SAMPLES_PER_CYCLE) -> np.ndarray:
    """The curve rows (cycles × samples, P) of `trial_residuals`' Jacobian for a trial of this
    simulated run whose spread is σ = sigma_mm (mm): d(cycle curves)/dθ / (σ·√(cycles·samples)),
    from the records' derivatives derivative_xy (n_records, 2, P). They depend on the simulated
    path and σ alone (the measured curves do not move with θ), so they also say what a trial not
    yet measured would add to a fit, given the spread expected of it (`gait_predictions`'
    `added`). ValueError unless sigma_mm is a finite number of mm at least
    `DISPLACEMENT_FLOOR_MM` (where `trial_fit` floors a measured trial's spread), or naming
    derivative_xy's shape."""
    _check_sigma(sigma_mm, "sigma_mm")
    derivative_xy = _checked_derivative(simulated, derivative_xy)
    first, last = check_window(cycles)
    samples = check_samples(samples)
    curve_derivative = _curve_derivative(simulated.path, derivative_xy, (first, last), samples)
    size = (last - first + 1) * samples
    return (curve_derivative * (1.0 / (sigma_mm * math.sqrt(size)))).reshape(size, -1)


def _check_sigma(value, name: str):
    """ValueError naming `name` unless value is a finite number >= DISPLACEMENT_FLOOR_MM."""
    if not (is_finite_real(value) and value >= DISPLACEMENT_FLOOR_MM):
        raise ValueError(f"{name} must be a finite number of mm >= DISPLACEMENT_FLOOR_MM = "
                         f"{DISPLACEMENT_FLOOR_MM} (the tracking noise, where a measured "
                         f"trial's spread is floored), got {shown(value)}")


def trial_residuals(simulated: SimulatedRun, derivative_xy: np.ndarray, trial: Trial,
                    cycles=TRAINING_CYCLES, samples: int = SAMPLES_PER_CYCLE,
                    phase_s: Optional[float] = None
                    ) -> Tuple[TrialFit, np.ndarray, np.ndarray]:
    """`trial_fit` of one simulated trial and its objective as a sum of squares: residuals
    (R,) with Σ r² = the trial's objective, R = cycles × samples + 1 (the curve residuals
    (d_sim − d_meas)/(σ·√(cycles·samples)) cycle by cycle, then ρ), and their Jacobian (R, P)
    with respect to the P parameters whose record derivatives are derivative_xy
    (n_records, 2, P): column 0 d x_mm/dθ, column 1 d y_mm/dθ (module docstring, "Gradient";
    ρ's row is 0 where −sΔ ≤ 0). With `phase_s` given the phase is held (its derivative
    is 0). The form a Gauss-Newton or trust-region least-squares method takes."""
    derivative_xy = _checked_derivative(simulated, derivative_xy)
    fit = trial_fit(simulated, trial, cycles, samples, phase_s)
    first, last = check_window(cycles)
    sim_curves = cycle_curves(simulated.path, 0.0, (first, last), samples)
    measured = cycle_curves(trial.path, fit.phase_s, (first, last), samples)
    scale = 1.0 / (fit.sigma_mm * math.sqrt(sim_curves.size))
    _, net_derivative = _net_displacement(simulated, derivative_xy, (first, last))
    wrong_way = -trial.paper_sign * fit.sim_net_signed_mm > 0
    direction_row = (-trial.paper_sign * net_derivative / fit.sigma_mm if wrong_way
                     else np.zeros_like(net_derivative))
    residuals = np.append(((sim_curves - measured) * scale).ravel(), fit.direction_residual)
    jacobian = np.vstack([trial_rows(simulated, derivative_xy, fit.sigma_mm, (first, last),
                                     samples), direction_row[None, :]])
    return fit, residuals, jacobian


def objective_residuals(simulated: Mapping[str, SimulatedRun],
                        derivatives: Mapping[str, np.ndarray], trials: Mapping[str, Trial],
                        cycles=TRAINING_CYCLES, samples: int = SAMPLES_PER_CYCLE,
                        phases: Optional[Mapping[str, float]] = None
                        ) -> Tuple[np.ndarray, np.ndarray, pd.DataFrame]:
    """The set's objective as a sum of squares: every gait's `trial_residuals` over √(gaits),
    stacked (Σ r² = `objective_of` of the table, the mean of the gaits' objectives), their
    Jacobian (R, P) and the per-gait table. derivatives: gait -> (n_records, 2, P) record
    derivatives of that gait's run (`record_derivatives`). ValueError for a failed run (None,
    as `result_runs` gives it), which has no derivative (`trajectory_objective` scores it inf;
    here it was an AttributeError: a mutation audit, 2026-12)."""
    rows, residuals, jacobians = [], [], []
    for gait, run in simulated.items():
        if gait not in trials:
            raise ValueError(f"no measured trial for gait {gait!r}; trials: {', '.join(trials)}")
        if run is None:
            raise ValueError(f"simulated[{gait!r}] is None (a failed run): it has no "
                             f"residuals or gradient; trajectory_objective scores it inf")
        fit, residual, jacobian = trial_residuals(
            run, gait_entry(derivatives, gait, "derivatives"), trials[gait], cycles, samples,
            None if phases is None else gait_entry(phases, gait, "phases"))
        rows.append(dataclasses.asdict(fit))
        residuals.append(residual)
        jacobians.append(jacobian)
    scale = 1.0 / math.sqrt(len(residuals))
    return (np.concatenate(residuals) * scale, np.vstack(jacobians) * scale,
            pd.DataFrame(rows, columns=TRIAL_COLUMNS))


def trial_phase_motion(simulated: SimulatedRun, derivative_xy: np.ndarray, trial: Trial,
                       fit: TrialFit, cycles=TRAINING_CYCLES,
                       samples: int = SAMPLES_PER_CYCLE) -> np.ndarray:
    """The part of the trial objective's gradient (P,) that comes from its fitted phase moving
    with θ: ∂J/∂φ · dφ/dθ (module docstring, "Gradient"); `fit` is the trial's `trial_fit` with
    the phase fitted. Zero when σ is at its floor, at the phase's bounds, at a kink of the
    measured track (`PHASE_KINK_RATIO`), or where the misfit is not convex in the phase."""
    step, wide = PHASE_STEP_S, PHASE_STEP_S * PHASE_KINK_RATIO
    phase, count = fit.phase_s, np.asarray(derivative_xy).shape[-1]
    if (fit.sigma_mm <= DISPLACEMENT_FLOOR_MM or phase - wide < 0.0
            or phase + wide > latest_phase(trial, cycles)):
        return np.zeros(count)
    first, last = check_window(cycles)
    sim_curves = cycle_curves(simulated.path, 0.0, (first, last), samples)

    def misfit(at):
        return _misfit(sim_curves, trial, at, (first, last), samples)

    centre = misfit(phase)
    curvature, wide_curvature = ((misfit(phase + h) - 2.0 * centre + misfit(phase - h)) / h ** 2
                                 for h in (step, wide))
    if curvature <= 0.0 or curvature > 2.0 * wide_curvature:
        return np.zeros(count)
    below, above = (cycle_curves(trial.path, phase + sign * step, (first, last), samples)
                    for sign in (-1.0, 1.0))
    curve_derivative = _curve_derivative(simulated.path, np.asarray(derivative_xy, np.float64),
                                         (first, last), samples)
    mixed = -2.0 * np.einsum("cs,csp->p", (above - below) / (2.0 * step), curve_derivative)
    objective = [trial_fit(simulated, trial, cycles, samples, phase + sign * step).objective
                 for sign in (-1.0, 1.0)]
    return (objective[1] - objective[0]) / (2.0 * step) * (-mixed / curvature)


def objective_and_gradient(simulated: Mapping[str, SimulatedRun],
                           derivatives: Mapping[str, np.ndarray], trials: Mapping[str, Trial],
                           cycles=TRAINING_CYCLES, samples: int = SAMPLES_PER_CYCLE,
                           phases: Optional[Mapping[str, float]] = None
                           ) -> Tuple[float, np.ndarray, pd.DataFrame]:
    """The set's objective (`objective_of` of `trajectory_objective`), its gradient (P,) with
    respect to the P parameters, and the per-gait table. The gradient is 2·Jᵀr of
    `objective_residuals` (same arguments) plus, for phases fitted here, `phase_motion`: that
    of the objective with the phases re-fitted at every θ."""
    residuals, jacobian, table = objective_residuals(simulated, derivatives, trials, cycles,
                                                     samples, phases)
    gradient = 2.0 * jacobian.T @ residuals
    if phases is None:
        gradient = gradient + phase_motion(simulated, derivatives, trials, table, cycles,
                                           samples)
    return objective_of(table), gradient, table


def gait_entry(per_gait: Mapping[str, object], gait: str, name: str):
    """`per_gait[gait]`, or a ValueError naming `name` and the gaits it holds (a KeyError of
    the gait alone named neither: an audit, 2026-12)."""
    if gait not in per_gait:
        raise ValueError(f"{name} has no entry for gait {gait!r}; {name}: "
                         f"{', '.join(per_gait) or 'none'}")
    return per_gait[gait]


def phase_motion(simulated: Mapping[str, SimulatedRun], derivatives: Mapping[str, np.ndarray],
                 trials: Mapping[str, Trial], table: pd.DataFrame, cycles=TRAINING_CYCLES,
                 samples: int = SAMPLES_PER_CYCLE) -> np.ndarray:
    """The set's `trial_phase_motion`s (P,), averaged as the objective averages the gaits;
    `table`: the per-gait table of `objective_residuals` with the phases fitted there."""
    fits = {row["gait"]: TrialFit(**row) for row in table.to_dict("records")}
    motions = [trial_phase_motion(run, gait_entry(derivatives, gait, "derivatives"),
                                  trials[gait], fits[Gait.parse(gait).name], cycles, samples)
               for gait, run in simulated.items()]
    return np.mean(motions, axis=0)


@dataclass(frozen=True)
class _LocalFit:
    """A least-squares fit's Jacobian split by its singular values (`_local_fit`): J's, or,
    with rows of trials not yet made, those of J with them below it."""

    scale: np.ndarray        # (P,) |value|, or 1 where the value is 0: the relative units
    singular: np.ndarray     # (P,) singular values of (J; A)·diag(scale), largest first
    directions: np.ndarray   # (P, P) their right singular vectors, one per row
    kept: np.ndarray         # (P,) whether each direction is resolved
    variance: float          # s² = Σr² / (R − rank of the fit's own Jacobian)
    dof: int                 # R − rank of the fit's own Jacobian

    @property
    def rank(self) -> int:
        """The resolved directions."""
        return int(self.kept.sum())


def _split(relative: np.ndarray, count: int):
    """Singular values (count,), largest first, and right singular vectors (count, count; one
    per row) of a relative Jacobian (rows, count); fewer rows than columns are padded with
    zeros, rows that cannot see the directions beyond them."""
    if len(relative) < count:
        relative = np.vstack([relative, np.zeros((count - len(relative), count))])
    _, singular, directions = np.linalg.svd(relative, full_matrices=False)
    return singular, directions


def _local_fit(residuals, jacobian, values, count: int, rcond: float, share: float,
               added_jacobian=None) -> _LocalFit:
    """Check a fit's residuals (R,), Jacobian (R, P) and values (P,) for `count` = P
    parameters, and split J·diag(|value|) by its singular values (`parameter_uncertainty`).
    With `added_jacobian` (A, P), the split is of J with those rows below it, while s² and the
    residual degrees of freedom stay the fit's own."""
    residuals = np.asarray(residuals, dtype=np.float64)
    jacobian = np.asarray(jacobian, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    if not count or residuals.ndim != 1 or jacobian.shape != (len(residuals), count) \
            or values.shape != (count,):
        raise ValueError(f"residuals (R,), jacobian (R, P) and values (P,) must match the "
                         f"{count} parameters (at least one); got {residuals.shape}, "
                         f"{jacobian.shape} and {values.shape}")
    if not (np.isfinite(residuals).all() and np.isfinite(jacobian).all()
            and np.isfinite(values).all()):
        raise ValueError("residuals, jacobian and values must be finite")
    for label, number in (("rcond", rcond), ("share", share)):
        if not 0.0 < number < 1.0:
            raise ValueError(f"{label} must be in (0, 1), got {number!r}")
    if added_jacobian is not None:
        added_jacobian = np.asarray(added_jacobian, dtype=np.float64)
        if added_jacobian.ndim != 2 or added_jacobian.shape[1] != count:
            raise ValueError(f"added_jacobian must have shape (A, {count}), one column per "
                             f"parameter, got {added_jacobian.shape}")
        if not np.isfinite(added_jacobian).all():
            raise ValueError("added_jacobian must be finite")
    scale = np.where(values != 0.0, np.abs(values), 1.0)
    relative = jacobian * scale
    singular, directions = _split(relative, count)
    cut = rcond * singular[0]
    kept = singular > cut                        # none when J = 0: 0 > 0 is false
    rank = int(kept.sum())
    dof = len(residuals) - rank
    if dof <= 0:
        raise ValueError(f"{len(residuals)} residuals for {rank} resolved directions: no "
                         f"residual degree of freedom to estimate their scatter")
    variance = float(residuals @ residuals) / dof
    if added_jacobian is not None and len(added_jacobian):
        # the cut stays the fit's own: rows below J only raise its singular values (each of
        # (J; A) is at least J's), so a trial taken as made never lowers the rank, however much
        # its rows weigh (the resolved directions can still turn where one of J's singular
        # values lies near the cut); above the stacked matrix's rounding (NumPy's rank
        # tolerance), so that rows added to a J of zeros resolve only what they see
        stacked = np.vstack([relative, added_jacobian * scale])
        singular, directions = _split(stacked, count)
        rounding = singular[0] * max(stacked.shape) * np.finfo(np.float64).eps
        kept = singular > max(cut, rounding)
    return _LocalFit(scale, singular, directions, kept, variance, dof)


def parameter_uncertainty(residuals: np.ndarray, jacobian: np.ndarray, names: Sequence[str],
                          values: Sequence[float], rcond: float = UNCERTAINTY_RCOND,
                          share: float = UNCERTAINTY_SHARE,
                          added_jacobian: Optional[np.ndarray] = None) -> pd.DataFrame:
    """How well a least-squares fit's data determine its parameters, locally: from the
    residuals r (R,) at the fitted point and their Jacobian J (R, P) with respect to the
    parameters' values (per unit of each; `objective_residuals` gives both), one row per
    parameter (`UNCERTAINTY_COLUMNS`).

    The relative Jacobian J·diag(|value|) (value 0: its own unit) is split by its singular
    values; those at most `rcond` × the largest are directions the data do not resolve
    (`UNCERTAINTY_RCOND`). A parameter whose components along them have a norm
    (`unresolved_share`) above `share` is not `identifiable`: its standard error is inf and its
    correlations NaN. For the rest, the Gauss-Newton (Fisher) covariance s²·(JᵀJ)⁺ on the
    resolved directions, s² = Σr² / (R − rank): `standard_error` (the value's units) and
    `relative_standard_error` (of |value|), and the largest correlation with another
    identifiable parameter (`most_correlated_with`, `correlation`, signed). `rank` (resolved
    directions), `condition_number` (largest / smallest singular value of the relative
    Jacobian, inf when one is zero) and `residual_dof` (R − rank) describe the whole fit. The
    standard errors take the residuals as independent with one variance; samples of one
    measured curve are correlated, so they are lower bounds, while the rank, the conditioning
    and the correlations do not depend on that.

    `added_jacobian` (A, P): rows of trials not yet measured (`trial_rows`, in the units of
    J), as if they were in the fit, their residuals scattering as the fit's own do: the
    split, `rank` and `condition_number` are then of J with those rows below it (the cut
    between resolved and not still `rcond` × J's own largest singular value, so that rows
    added never lower the rank, and at least the stacked matrix's rounding), while s² and
    `residual_dof` stay the fit's (R − the rank of J alone). What a fit would determine after
    those trials, before they are made.

    ValueError for mismatched shapes, non-finite entries, rcond or share outside (0, 1), or
    R ≤ rank (no residual left to estimate s²)."""
    names = list(names)
    fit = _local_fit(residuals, jacobian, values, len(names), rcond, share, added_jacobian)
    values = np.asarray(values, dtype=np.float64)
    singular, kept, scale = fit.singular, fit.kept, fit.scale
    unresolved = np.sqrt((fit.directions[~kept] ** 2).sum(axis=0))
    identifiable = unresolved <= share
    basis = fit.directions[kept].T / singular[kept]               # V S⁻¹, (P, rank)
    relative_covariance = fit.variance * basis @ basis.T          # of value_j / |value_j|
    spread = np.sqrt(np.diag(relative_covariance))
    condition = singular[0] / singular[-1] if singular[-1] > 0.0 else math.inf
    rank, dof = fit.rank, fit.dof
    rows = []
    for j, name in enumerate(names):
        row = {"parameter": name, "value": values[j], "identifiable": bool(identifiable[j]),
               "unresolved_share": float(unresolved[j]), "rank": rank,
               "condition_number": condition, "residual_dof": dof,
               "most_correlated_with": "", "correlation": math.nan,
               "standard_error": math.inf, "relative_standard_error": math.inf}
        if identifiable[j]:
            row["standard_error"] = spread[j] * scale[j]
            row["relative_standard_error"] = spread[j] if values[j] != 0.0 else math.nan
            # an identifiable parameter's spread is 0 only when every one's is (s² = 0)
            others = [k for k in range(len(names)) if k != j and identifiable[k]]
            if others and spread[j] > 0.0:
                correlations = [relative_covariance[j, k] / (spread[j] * spread[k])
                                for k in others]
                best = int(np.argmax(np.abs(correlations)))
                row["most_correlated_with"] = names[others[best]]
                row["correlation"] = float(correlations[best])
        rows.append(row)
    return pd.DataFrame(rows, columns=UNCERTAINTY_COLUMNS)


@dataclass(frozen=True)
class PredictionUncertainty:
    """`prediction_uncertainty`'s answer: the prediction's standard error (its units; inf
    where the fit leaves it undetermined), its unresolved share, and the fit's resolved
    directions (`rank`; with rows of trials not yet made, those of J and them together) and
    residual degrees of freedom (R − the rank of the fit's own J)."""

    standard_error: float
    unresolved_share: float
    rank: int
    residual_dof: int

    @property
    def determined(self) -> bool:
        """Whether the fit's data determine the prediction (its standard error is finite)."""
        return math.isfinite(self.standard_error)


def prediction_uncertainty(residuals: np.ndarray, jacobian: np.ndarray,
                           values: Sequence[float], gradient: Sequence[float],
                           rcond: float = UNCERTAINTY_RCOND,
                           share: float = UNCERTAINTY_SHARE,
                           added_jacobian: Optional[np.ndarray] = None
                           ) -> PredictionUncertainty:
    """How well a least-squares fit's data determine a prediction y(θ) made with the fitted
    parameters, locally, from the fit's residuals (R,) and Jacobian (R, P) as in
    `parameter_uncertainty` and y's gradient (P,) with respect to the same parameter values
    (per unit of each).

    y moves along the parameters' relative directions as g = gradient·|value|. Its
    `unresolved_share` is the norm of g/|g|'s components along the directions the data do
    not resolve (0 when g = 0: nothing y depends on is fitted); above `share` the data
    leave y undetermined and its standard error is inf. Otherwise it is that of the
    Gauss-Newton covariance on the resolved directions, √(s²·gᵀ(JᵀJ)⁺g) in relative units,
    with the same s² = Σr² / (R − rank): like the parameters', a lower bound where the
    residuals are correlated; and a share above 0 (up to `share`) is left out of it: a move
    of the unresolved parameters moves y by up to that share of g's size besides.
    `added_jacobian` (A, P): rows of trials not yet measured, as in `parameter_uncertainty`
    (the split and `rank` with them, s² and `residual_dof` the fit's own). The same ValueErrors
    as `parameter_uncertainty`, and one for values that are not 1-D, a gradient that is not P
    finite numbers, or a product gradient·|value| that overflows."""
    values = np.asarray(values, dtype=np.float64)
    gradient = np.asarray(gradient, dtype=np.float64)
    if values.ndim != 1:
        raise ValueError(f"values must be a 1-D array (P,), got shape {values.shape}")
    columns = np.shape(jacobian)[-1] if np.ndim(jacobian) == 2 else len(values)
    if len(values) != columns:
        # a wrong count of values was blamed on the gradient (an audit, 2026-12)
        raise ValueError(f"values must hold one number per column of jacobian ({columns}), "
                         f"got {len(values)}")
    if gradient.shape != values.shape or not np.isfinite(gradient).all():
        raise ValueError(f"gradient must hold one finite number per value; got shape "
                         f"{gradient.shape} for values of shape {values.shape}")
    fit = _local_fit(residuals, jacobian, values, len(values), rcond, share, added_jacobian)
    rank = fit.rank
    with np.errstate(over="ignore"):
        relative = gradient * fit.scale
    if not np.isfinite(relative).all():
        raise ValueError("gradient × |value| overflows: give the gradient and values in units "
                         "where their product is finite")
    # scaled by its largest entry, so that squares of entries near the float range's end do
    # not overflow the norms
    largest = float(np.max(np.abs(relative)))
    if largest == 0.0:
        return PredictionUncertainty(0.0, 0.0, rank, fit.dof)
    direction = relative / largest
    unresolved = (float(np.linalg.norm(fit.directions[~fit.kept] @ direction))
                  / float(np.linalg.norm(direction)))
    if unresolved > share:
        return PredictionUncertainty(math.inf, unresolved, rank, fit.dof)
    along = fit.directions[fit.kept] @ direction / fit.singular[fit.kept]
    return PredictionUncertainty(largest * math.sqrt(fit.variance * float(along @ along)),
                                 unresolved, rank, fit.dof)


PREDICTION_COLUMNS = ["gait", "role", "training_gaits", "first_cycle", "last_cycle",
                      "predicted_speed_mm_s", "standard_error_mm_s", "distance_speed_mm_s",
                      "unresolved_share", "determined",
                      "measured_speed_mm_s", "z_score", "within_two_standard_errors",
                      "training_objective", "rank", "residual_dof"]
"""Columns of `gait_predictions`' table, one row per gait and role: "fitted" (a measured gait
with every measured gait in the fit), "held_out" (a measured gait, the fit on the others),
"unmeasured" (the fit on every measured gait) or "added" (a gait not measured whose trial the
fits take as made: the fit on every measured gait and it); the measured gaits fitted (joined
by spaces; every fit holds the added trials too); the
window of the speeds (1-based cycles, inclusive); the simulated speed over it along the gait's
forward axis (mm/s; `TrialFit.sim_speed_mm_s`) and its standard error
(`prediction_uncertainty`; inf where the fit leaves it undetermined); the simulated distance
covered over it / its duration (mm/s, unsigned: what the measured speed is, the tracks having
no robot axes; above |predicted| where the robot veers off its axis); the measured speed (the
distance covered signed by the paper's direction, `TrialFit.meas_speed_mm_s`; NaN when
unmeasured), (measured − predicted) / standard error (NaN where it is inf or 0), whether the
measured speed lies within two standard errors (≤; always where undetermined, empty when
unmeasured); the fit's objective on its gaits (`objective_of`), its resolved directions and
residual degrees of freedom."""


def window_speed(simulated: SimulatedRun, derivative_xy: np.ndarray, cycles=TRAINING_CYCLES
                 ) -> Tuple[float, np.ndarray]:
    """A simulated run's speed over the cycle window along its gait's forward axis (mm/s;
    `TrialFit.sim_speed_mm_s`, signed) and its derivative (P,) from the records' derivatives
    derivative_xy (n_records, 2, P)."""
    first, last = check_window(cycles)
    net, derivative = _net_displacement(simulated, np.asarray(derivative_xy, np.float64),
                                        cycles)
    duration = (last - first + 1) * simulated.path.period_s
    return net / duration, derivative / duration


def gait_predictions(simulated: Mapping[str, SimulatedRun],
                     derivatives: Mapping[str, np.ndarray], trials: Mapping[str, Trial],
                     values: Sequence[float], cycles=TRAINING_CYCLES,
                     samples: int = SAMPLES_PER_CYCLE, rcond: float = UNCERTAINTY_RCOND,
                     share: float = UNCERTAINTY_SHARE, predict_cycles=None,
                     added: Sequence[str] = (), added_sigma_mm: Optional[float] = None
                     ) -> pd.DataFrame:
    """Which gaits' speeds the measured trials determine, at one model point: a linearised
    leave-one-gait-out with the exact sensitivities. `simulated`: gait -> run at the point
    (every gait of `trials`, and others to predict), `derivatives`: gait -> its records'
    derivatives (n_records, 2, P) with respect to the P fitted parameters, whose `values`
    (P,) the point holds. Every measured gait gets a "fitted" row (the fit on every trial)
    and a "held_out" one (the fit on the others), every other gait an "unmeasured" row (the
    fit on every trial): its `window_speed` and the `prediction_uncertainty` of the
    fit's `objective_residuals` (each trial's phase fitted at the point, then held) on the
    window `cycles`. The speeds are those of `predict_cycles` (default `cycles`): a later
    window asks what the fit predicts of cycles it did not see, the measured speed then read
    there with the phase fitted on `cycles`. One table row per gait and role
    (`PREDICTION_COLUMNS`).

    `added`: gaits of `simulated` not measured whose trials every fit takes as made (role
    "added" instead of "unmeasured"): what measuring them would determine, before they are
    measured. Each adds its `trial_rows` on `cycles` with spread `added_sigma_mm` (mm; default
    the median σ of the measured trials at the point), weighted as a measured gait is; their
    residuals are taken to scatter as the fit's own (`prediction_uncertainty`'s
    `added_jacobian`), and a trial whose robot goes the model's way adds no direction residual.

    The fit is not redone without the held-out gait: the point is the same, only the data
    that determine it change, so a "held_out" row says how far the other gaits pin down
    what the held-out one needs, not where a fit without it would go. ValueError for a
    measured gait missing from `simulated`, fewer than two measured gaits, an added gait that
    is measured, not simulated or repeated, an added_sigma_mm below `DISPLACEMENT_FLOOR_MM`
    or not a finite number, or as `prediction_uncertainty`."""
    tables, _ = _predictions(simulated, derivatives, trials, values, cycles, samples, rcond,
                             share, predict_cycles, [added], added_sigma_mm)
    return tables[0]


def _predictions(simulated, derivatives, trials, values, cycles, samples, rcond, share,
                 predict_cycles, added_sets, added_sigma_mm) -> Tuple[list, float]:
    """`gait_predictions`' table for each set of added gaits in `added_sets`, the fits (and
    their phase searches) and the speeds made once for all, and the spread given the added
    trials."""
    predicted = check_window(cycles if predict_cycles is None else predict_cycles)
    measured = _checked_measured(simulated, trials)
    if len(measured) < 2:
        raise ValueError(f"gait_predictions needs at least two measured gaits (one held out, "
                         f"one fitted), got {len(measured)}")
    added_sets = [_checked_added(added, simulated, measured) for added in added_sets]
    if added_sigma_mm is not None:
        _check_sigma(added_sigma_mm, "added_sigma_mm")
    fits = {}

    def fit_of(training):
        if training not in fits:
            residuals, jacobian, table = objective_residuals(
                {g: simulated[g] for g in training}, derivatives,
                {g: trials[g] for g in training}, cycles, samples)
            fits[training] = residuals, jacobian, table
        return fits[training]

    # each trial's phase, fitted on `cycles` at the point: the same in every fit that holds it
    _, _, everyone = fit_of(tuple(measured))
    phases = dict(zip(everyone["gait"], everyone["phase_s"]))
    if added_sigma_mm is None:
        added_sigma_mm = _median_sigma(everyone)
    cases = ([(gait, "fitted", tuple(measured)) for gait in measured]
             + [(gait, "held_out", tuple(g for g in measured if g != gait)) for gait in measured]
             + [(gait, "unmeasured", tuple(measured)) for gait in simulated if gait not in trials])
    # what does not depend on the trials added, once for every set
    speeds = {}
    for gait in dict.fromkeys(gait for gait, _, _ in cases):
        run = simulated[gait]
        speed, gradient = window_speed(run, gait_entry(derivatives, gait, "derivatives"),
                                       predicted)
        ends = run.path.position(_window_ends(run.path, predicted))
        duration = (predicted[1] - predicted[0] + 1) * run.path.period_s
        measured_speed = math.nan
        if gait in trials:
            fit = trial_fit(run, trials[gait], predicted, samples, phases[gait])
            measured_speed = trials[gait].paper_sign * fit.meas_speed_mm_s
        speeds[gait] = (speed, gradient, float(np.hypot(*(ends[1] - ends[0]))) / duration,
                        measured_speed)
    rows_by_gait = _rows_by_gait(simulated, derivatives, added_sets, added_sigma_mm, cycles,
                                 samples)
    tables = []
    for added in added_sets:
        added_rows = _added_rows(rows_by_gait, added)
        rows = []
        for gait, role, training in cases:
            residuals, jacobian, table = fit_of(training)
            speed, gradient, distance_speed, measured_speed = speeds[gait]
            # weighted as one more gait of the fit's mean: objective_residuals' 1/√(gaits)
            uncertainty = prediction_uncertainty(
                residuals, jacobian, values, gradient, rcond, share,
                None if added_rows is None else added_rows / math.sqrt(len(training)))
            error = uncertainty.standard_error
            gap, within = math.nan, None
            if gait in trials:
                gap = measured_speed - speed
                within = bool(abs(gap) <= 2.0 * error)
            rows.append({"gait": gait, "role": "added" if gait in added else role,
                         "training_gaits": " ".join(training),
                         "first_cycle": predicted[0], "last_cycle": predicted[1],
                         "predicted_speed_mm_s": speed, "standard_error_mm_s": error,
                         "distance_speed_mm_s": distance_speed,
                         "unresolved_share": uncertainty.unresolved_share,
                         "determined": uncertainty.determined,
                         "measured_speed_mm_s": measured_speed,
                         "z_score": gap / error if 0.0 < error < math.inf else math.nan,
                         "within_two_standard_errors": within,
                         "training_objective": objective_of(table),
                         "rank": uncertainty.rank, "residual_dof": uncertainty.residual_dof})
        tables.append(pd.DataFrame(rows, columns=PREDICTION_COLUMNS))
    return tables, added_sigma_mm


def _checked_measured(simulated, trials) -> list:
    """The measured gaits (`trials`' keys), or ValueError naming those `simulated` lacks (or
    holds as None, a failed run's form in `result_runs`)."""
    missing = [gait for gait in trials if simulated.get(gait) is None]
    if missing:
        raise ValueError(f"no simulated run for the measured gait(s) {', '.join(missing)}")
    return list(trials)


def _checked_added(added, simulated, measured, name: str = "added") -> tuple:
    """Added gaits (`name`: the argument that gave them) as a tuple, or ValueError naming the
    one refused: measured, without a simulated run (missing or None), or repeated."""
    if isinstance(added, str):
        raise ValueError(f"{name} must be a sequence of gait names, not the string {added!r}")
    added = tuple(added)
    for gait in added:
        if gait in measured:
            raise ValueError(f"{name}: gait {gait!r} is measured: its trial is in the fits "
                             f"already")
        if simulated.get(gait) is None:
            raise ValueError(f"{name}: gait {gait!r} has no simulated run (missing, or None: "
                             f"failed)")
    if len(set(added)) != len(added):
        raise ValueError(f"{name}: gaits repeat: {', '.join(added)}")
    return added


DESIGN_COLUMNS = ["added_trials", "added_sigma_mm"] + PREDICTION_COLUMNS
"""Columns of `trial_design`'s table: the trials taken as made (joined by spaces; "none" for
none: an empty cell would read back as a missing value), the spread given them (mm; NaN for
none), then `gait_predictions`' columns."""


MAX_DESIGN_SETS = 1024
"""The most sets of candidate trials a design scores (`trial_design`, `parameter_design`):
a set costs two SVDs per gait and role, about 10 ms for sixteen gaits and eight parameters
(67 sets in 1.2 s with the fits' phase searches, a scratch timing on 2 cores), so this is under
a minute and a table of some 20,000 rows; the sets grow as 2^n with n candidates
(`design_set_count`)."""


def trial_design(simulated: Mapping[str, SimulatedRun], derivatives: Mapping[str, np.ndarray],
                 trials: Mapping[str, Trial], values: Sequence[float],
                 candidates: Sequence[str], cycles=TRAINING_CYCLES,
                 samples: int = SAMPLES_PER_CYCLE, rcond: float = UNCERTAINTY_RCOND,
                 share: float = UNCERTAINTY_SHARE, predict_cycles=None,
                 added_sigma_mm: Optional[float] = None, max_trials: Optional[int] = None
                 ) -> pd.DataFrame:
    """Which trial to measure next: `gait_predictions` with no trial added, then with sets of
    `candidates` (gaits of `simulated` not measured) added, stacked (`DESIGN_COLUMNS`): each
    alone and all of them together (more than one) by default, or with `max_trials` = k every
    set of at most k of them, the smaller first (the fewest trials that determine a gait;
    k ≥ their number: every subset). A held-out gait that the measured gaits leave
    undetermined and a set determines is one those trials would let the model predict; the
    standard errors say how closely, as far as the linearisation at this point and the spread
    expected of a trial (`added_sigma_mm`, default the measured trials' median σ) reach. With
    trials added, `z_score` and `within_two_standard_errors` are left empty: the point is not
    refitted to trials not yet made, so they would set its speeds against the precision that
    a refit on those trials would have. The arguments and ValueErrors are
    `gait_predictions`', and one for a max_trials that is not a whole number >= 1 or that asks
    for more than `MAX_DESIGN_SETS` sets."""
    sets = _design_sets(candidates, max_trials, simulated, list(trials))
    tables, added_sigma_mm = _predictions(simulated, derivatives, trials, values, cycles,
                                          samples, rcond, share, predict_cycles, [()] + sets,
                                          added_sigma_mm)
    for added, table in zip([()] + sets, tables):
        if added:
            table["z_score"] = math.nan
            table["within_two_standard_errors"] = None
        table.insert(0, "added_trials", " ".join(added) or "none")
        table.insert(1, "added_sigma_mm", added_sigma_mm if added else math.nan)
    return pd.concat(tables, ignore_index=True)


DESIGN_SUMMARY_COLUMNS = ["added_trials", "trials", "held_out_determined",
                          "held_out_undetermined", "every_held_out_determined",
                          "widest_held_out_standard_error_mm_s"]
"""Columns of `design_summary`'s table, one row per set of trials taken as made: the set
("none" for none) and its size, how many held-out gaits its fits determine, those they do not
(joined by spaces; "none" for none: an empty cell would read back as missing), whether they
determine all, and the largest standard error of the
held-out speeds they determine (mm/s; NaN where none is)."""


def design_summary(design: pd.DataFrame) -> pd.DataFrame:
    """One row per set of trials of a `trial_design` table (`DESIGN_SUMMARY_COLUMNS`), in the
    table's order, from its held-out rows (rows with no number, a failed gait's, are left
    out): which sets of trials would let the model predict every held-out gait, and how
    closely. ValueError for a table without `DESIGN_COLUMNS`."""
    missing = [column for column in DESIGN_COLUMNS if column not in design.columns]
    if missing:
        raise ValueError(f"design must be a trial_design table; it lacks {', '.join(missing)}")
    held = design[(design["role"] == "held_out") & design["predicted_speed_mm_s"].notna()]
    rows = []
    for trials in dict.fromkeys(design["added_trials"]):
        part = held[held["added_trials"] == trials]
        determined = part["determined"].astype(bool)
        free = part.loc[~determined, "gait"].tolist()
        errors = part.loc[determined, "standard_error_mm_s"]
        rows.append({"added_trials": trials,
                     "trials": 0 if trials == "none" else len(trials.split()),
                     "held_out_determined": int(determined.sum()),
                     "held_out_undetermined": " ".join(free) or "none",
                     "every_held_out_determined": not free,
                     # the max of none is NaN
                     "widest_held_out_standard_error_mm_s": float(errors.max())})
    return pd.DataFrame(rows, columns=DESIGN_SUMMARY_COLUMNS)


def parameter_design(simulated: Mapping[str, SimulatedRun],
                     derivatives: Mapping[str, np.ndarray], trials: Mapping[str, Trial],
                     names: Sequence[str], values: Sequence[float], candidates: Sequence[str],
                     cycles=TRAINING_CYCLES, samples: int = SAMPLES_PER_CYCLE,
                     rcond: float = UNCERTAINTY_RCOND, share: float = UNCERTAINTY_SHARE,
                     added_sigma_mm: Optional[float] = None, max_trials: Optional[int] = None
                     ) -> pd.DataFrame:
    """What the fit on every measured trial would determine of its parameters with trials of
    `candidates` taken as made: `parameter_uncertainty` of its `objective_residuals` (each
    trial's phase fitted at the point) with nothing added, then with the sets of
    `trial_design` (`max_trials`) added as `gait_predictions` adds them (spread
    `added_sigma_mm`, default the measured trials' median σ; weighted as a measured gait).
    One row per set and parameter: `DESIGN_COLUMNS`' first two, then `UNCERTAINTY_COLUMNS`.
    ValueError for a measured gait missing from `simulated`, and as `trial_design` and
    `parameter_uncertainty`."""
    measured = {g: simulated[g] for g in _checked_measured(simulated, trials)}
    sets = _design_sets(candidates, max_trials, simulated, list(measured))
    if added_sigma_mm is not None:
        _check_sigma(added_sigma_mm, "added_sigma_mm")
    residuals, jacobian, table = objective_residuals(measured, derivatives, trials, cycles,
                                                     samples)
    if added_sigma_mm is None:
        added_sigma_mm = _median_sigma(table)
    rows_by_gait = _rows_by_gait(simulated, derivatives, sets, added_sigma_mm, cycles, samples)
    tables = []
    for added in [()] + sets:
        rows = _added_rows(rows_by_gait, added)
        part = parameter_uncertainty(residuals, jacobian, names, values, rcond, share,
                                     None if rows is None else rows / math.sqrt(len(trials)))
        part.insert(0, "added_trials", " ".join(added) or "none")
        part.insert(1, "added_sigma_mm", added_sigma_mm if added else math.nan)
        tables.append(part)
    return pd.concat(tables, ignore_index=True)


def _design_sets(candidates, max_trials, simulated, measured) -> list:
    """The sets of candidate trials a design takes as made, beyond none: each alone and all
    (more than one) for max_trials None, else every set of at most max_trials, the smaller
    first. ValueError naming candidates or max_trials before any compute."""
    candidates = list(_checked_added(candidates, simulated, measured, "candidates"))
    sizes = _set_sizes(len(candidates), max_trials)
    count = design_set_count(len(candidates), max_trials)
    if count > MAX_DESIGN_SETS:
        raise ValueError(f"max_trials {max_trials} over {len(candidates)} candidates asks for "
                         f"{count} sets of trials, more than MAX_DESIGN_SETS = "
                         f"{MAX_DESIGN_SETS}: lower it or give fewer candidates")
    return [added for size in sizes for added in itertools.combinations(candidates, size)]


def _set_sizes(candidates: int, max_trials) -> list:
    """The sizes of the sets of trials a design takes (`trial_design`'s max_trials)."""
    if max_trials is None:
        return [1, candidates] if candidates > 1 else [1]
    if not is_whole(max_trials) or max_trials < 1:
        raise ValueError(f"max_trials must be a whole number >= 1 (None: each candidate alone "
                         f"and all together), got {max_trials!r}")
    return list(range(1, min(int(max_trials), candidates) + 1))


def design_set_count(candidates: int, max_trials: Optional[int] = None) -> int:
    """How many sets of trials, beyond none, `trial_design` scores for `candidates` candidate
    trials and `max_trials` (None: each alone and all together; k: every set of at most k).
    ValueError as `trial_design` for max_trials."""
    return sum(math.comb(candidates, size) for size in _set_sizes(candidates, max_trials))


def _rows_by_gait(simulated, derivatives, added_sets, sigma_mm, cycles, samples) -> dict:
    """The `trial_rows` of every gait in any set of `added_sets`, at one spread, each made once
    however many sets hold it."""
    gaits = dict.fromkeys(gait for added in added_sets for gait in added)
    return {g: trial_rows(simulated[g], derivatives[g], sigma_mm, cycles, samples)
            for g in gaits}


def _added_rows(rows_by_gait, added):
    """The rows (`_rows_by_gait`) of the added gaits, stacked (None for none)."""
    if not added:
        return None
    return np.vstack([rows_by_gait[g] for g in added])


def _median_sigma(table: pd.DataFrame) -> float:
    """The spread expected of a trial not yet measured (mm): the median σ of a table of
    `trajectory_objective` (the measured trials' cycle-to-cycle spread at the point)."""
    return float(np.median(table["sigma_mm"]))


def record_derivatives(trajectory_sensitivities: pd.DataFrame, instance: int,
                       parameters: Sequence[str]) -> np.ndarray:
    """(n_records, 2, P) d x_mm/dθ and d y_mm/dθ of one instance at its records, from
    `SimulationResult.trajectory_sensitivities` (columns "d(x_mm)/d(<parameter>)", a
    per-actuator field's by its index, "actuator_gains[1]"). ValueError naming an instance
    without records or a parameter the run was not differentiated by (a KeyError of a column
    name, or an empty array for an instance it does not hold, before: an audit, 2026-12)."""
    if not isinstance(trajectory_sensitivities, pd.DataFrame):
        raise ValueError(f"trajectory_sensitivities must be a result's table of them (a run "
                         f"with sensitivities and records), got "
                         f"{type(trajectory_sensitivities).__name__}")
    part = trajectory_sensitivities[trajectory_sensitivities["instance"] == instance]
    if part.empty:
        instances = trajectory_sensitivities["instance"]
        held = (f"its instances: {instances.min()}..{instances.max()}" if len(instances)
                else "it holds no records: a run with record_interval_s > 0 has them")
        raise ValueError(f"instance {instance!r}: no records of it in trajectory_sensitivities "
                         f"({held})")
    prefix = "d(x_mm)/d("
    differentiated = [column[len(prefix):-1] for column in part.columns
                      if column.startswith(prefix)]
    missing = [name for name in parameters if name not in differentiated]
    if missing:
        raise ValueError(f"parameters: {', '.join(map(repr, missing))} not among those the run "
                         f"was differentiated by ({', '.join(differentiated)}; a per-actuator "
                         f"field by its index, as actuator_gains[1])")
    return np.stack([np.stack([part[f"d({output})/d({name})"].to_numpy(dtype=np.float64)
                               for name in parameters], axis=-1)
                     for output in ("x_mm", "y_mm")], axis=1)
