"""The trajectory objective (taichi_star.identification) on synthetic paths: exactly zero when
the simulation is the measurement, the pulse phase recovered from a shifted path, the cycle
window respected, wrong directions penalised; and on the recorded trials."""

import math

import numpy as np
import pytest

from taichi_star import identification as ident
from taichi_star.experiment import PAPER_GAITS

# binary fractions throughout: every time below is exact in floating point, so interpolation
# at a sample time returns the sample itself
T = 4.0
DT = 1.0 / 64


def stroke(t, phase, gain=1.0, turn_deg=90.0):
    """A swimmer pulsing at phase + kT: each cycle a surge of 3 mm easing out over ~0.3 s plus
    a 1-mm glide, along a fixed direction turned by turn_deg from x (camera axes; 90°: exact
    in floating point), cycles growing 10 % each (a speed-up); the path is still before the
    first pulse."""
    local = np.mod(t - phase, T)
    cycle = np.floor((t - phase) / T)
    per_cycle = lambda k: gain * (3.0 + 1.0) * 1.1 ** k  # noqa: E731
    done = np.array([sum(per_cycle(j) for j in range(int(k))) if k > 0 else 0.0 for k in cycle])
    within = gain * 1.1 ** cycle * (3.0 * (1 - np.exp(-local / 0.3)) + 1.0 * local / T)
    # the fraction of the cycle's surge travelled at the end equals (3(1 − e^{−T/0.3}) + 1):
    # close to 4; the small leftover is a jump at each pulse, harmless here
    s = np.where(cycle >= 0, done + within, 0.0)
    if turn_deg == 90.0:
        return np.zeros_like(s), s
    return s * np.cos(np.radians(turn_deg)), s * np.sin(np.radians(turn_deg))


def measured(phase, end_s=16.0, turn_deg=90.0):
    t = np.arange(0, int(end_s / DT) + 1) * DT
    x, y = stroke(t, phase, turn_deg=turn_deg)
    return ident.Trial("A1+A2", ident.CentroidPath(t, x, y, T), +1.0)


def simulated(sign=+1.0, end_s=16.0, gain=1.0, dt=DT):
    """The same swimmer simulated from a pulse at t = 0, swimming along the forward axis (1, 0)
    (sign −1: against it)."""
    t = np.arange(0, int(end_s / dt) + 1) * dt
    _, s = stroke(t, 0.0, gain)
    s = sign * s
    return ident.SimulatedRun("A1+A2", ident.CentroidPath(t, s, np.zeros_like(s), T), (1.0, 0.0))


def test_objective_is_exactly_zero_when_the_simulation_is_the_measurement():
    # phase 1 s: on the search grid (latest phase min(T, 16 − 3T) = 4 s, 64 points)
    fit = ident.trial_fit(simulated(), measured(1.0), cycles=(1, 3))
    assert fit.phase_s == 1.0
    assert fit.trajectory_error == 0.0 and fit.direction_residual == 0.0 and fit.objective == 0.0
    assert fit.direction_matches
    # net over cycles 1-3: (4 + 4.4 + 4.84) mm minus the small leftover of each surge
    assert fit.meas_net_mm == pytest.approx(fit.sim_net_signed_mm, abs=1e-12)
    assert fit.meas_net_mm == pytest.approx(13.24, rel=1e-3)
    assert fit.sim_speed_mm_s == pytest.approx(fit.sim_net_signed_mm / (3 * T), rel=1e-15)


def test_phase_recovered_from_a_shifted_measurement():
    # a phase off the grid, the simulation recorded on another time grid than the video
    trial = measured(1.234, turn_deg=-37.0)
    fit = ident.trial_fit(simulated(dt=0.01), trial, cycles=(1, 3))
    # linear interpolation of two sampled paths (DT = 15.6 ms, 10 ms) limits the alignment:
    # well within one video frame
    assert fit.phase_s == pytest.approx(1.234, abs=2e-3)
    assert fit.trajectory_error < 1e-3 * ident.trial_fit(simulated(dt=0.01), trial, (1, 3),
                                                         phase_s=0.5).trajectory_error


def test_cycles_after_the_window_change_nothing():
    base = measured(1.0)
    fit = ident.trial_fit(simulated(), base, cycles=(1, 3))
    path = base.path
    # the window ends at phase + 3T = 13 s: change everything after it
    after = path.t_s > 1.0 + 3 * T
    changed = ident.Trial(base.gait, ident.CentroidPath(
        path.t_s, np.where(after, path.x_mm + 5.0, path.x_mm), path.y_mm, T), +1.0)
    again = ident.trial_fit(simulated(), changed, cycles=(1, 3))
    assert again == fit  # bitwise: the phase search never reads past the window either
    # ... while a change inside the window, or a window that includes cycle 4, sees it
    inside = path.t_s > 1.0 + 2.5 * T
    changed_inside = ident.Trial(base.gait, ident.CentroidPath(
        path.t_s, np.where(inside, path.x_mm + 5.0, path.x_mm), path.y_mm, T), +1.0)
    assert ident.trial_fit(simulated(), changed_inside, cycles=(1, 3), phase_s=1.0).objective > 0.1
    assert ident.trial_fit(simulated(), changed, cycles=(2, 3), phase_s=1.0).objective == 0.0
    long_trial = ident.Trial(base.gait, ident.CentroidPath(
        path.t_s, np.where(after, path.x_mm + 5.0, path.x_mm), path.y_mm, T), +1.0)
    assert ident.trial_fit(simulated(end_s=16.0), long_trial, cycles=(3, 3),
                           phase_s=0.0).objective > 0


def test_validation_window_with_the_training_phase():
    trial = measured(1.0, end_s=28.0)
    sim = simulated(end_s=28.0)
    training = ident.trial_fit(sim, trial, ident.TRAINING_CYCLES)
    validation = ident.trial_fit(sim, trial, ident.VALIDATION_CYCLES, phase_s=training.phase_s)
    assert (validation.first_cycle, validation.last_cycle) == (4, 6)
    assert validation.objective == 0.0
    with pytest.raises(ValueError, match="phase_s must be in"):
        ident.trial_fit(sim, trial, (4, 6), phase_s=5.0)
    with pytest.raises(ValueError, match=r"cycles 1-6 from 0 s need the path"):
        ident.trial_fit(simulated(end_s=16.0), trial, (1, 6))


def test_wrong_direction_is_penalised():
    trial = measured(1.0)
    right = ident.trial_fit(simulated(+1.0), trial, (1, 3))
    wrong = ident.trial_fit(simulated(-1.0), trial, (1, 3))
    # the same distances the wrong way: the curves agree, the direction residual is the
    # wrong-way travel in units of σ
    assert wrong.trajectory_error == right.trajectory_error == 0.0
    assert not wrong.direction_matches
    assert wrong.direction_residual == pytest.approx(right.meas_net_mm / wrong.sigma_mm,
                                                     rel=1e-12)
    assert wrong.objective == pytest.approx(wrong.direction_residual ** 2, rel=1e-15)
    # σ: the spread of the three cycles (10 % growth per cycle), well above the floor
    assert wrong.sigma_mm > 5 * ident.DISPLACEMENT_FLOOR_MM
    # half speed the right way: no direction penalty, a curve error instead
    slow = ident.trial_fit(simulated(+1.0, gain=0.5), trial, (1, 3))
    assert slow.direction_residual == 0.0 and slow.trajectory_error > 0
    assert slow.objective < wrong.objective


def test_bad_windows_and_inputs():
    with pytest.raises(ValueError, match="cycles must be integers"):
        ident.check_window((0, 3))
    with pytest.raises(ValueError, match="cycles must be integers"):
        ident.check_window((3, 2))
    with pytest.raises(ValueError, match="cycles must be a pair"):
        ident.check_window(3)
    with pytest.raises(ValueError, match="samples must be"):
        ident.tau_grid(T, 0)
    with pytest.raises(ValueError, match="strictly increasing"):
        ident.CentroidPath(np.array([0.0, 0.0]), np.zeros(2), np.zeros(2), T)
    with pytest.raises(ValueError, match="period_s"):
        ident.CentroidPath(np.array([0.0, 1.0]), np.zeros(2), np.zeros(2), 0.0)
    with pytest.raises(ValueError, match="shorter than cycles up to 5"):
        ident.latest_phase(measured(1.0), (1, 5))


def test_recorded_trials_cover_both_windows():
    trials = ident.measured_trials()
    assert list(trials) == list(PAPER_GAITS)
    for trial in trials.values():
        # every trial covers cycles 1-6 from any phase in [0, T)
        assert ident.latest_phase(trial, ident.VALIDATION_CYCLES) == pytest.approx(
            trial.path.period_s)
        curves = ident.cycle_curves(trial.path, 0.0, ident.TRAINING_CYCLES)
        assert curves.shape == (3, ident.SAMPLES_PER_CYCLE)
        assert np.isfinite(curves).all() and (curves >= 0).all()
    assert [trials[g].paper_sign for g in PAPER_GAITS] == [1, 1, -1, -1, -1]
    assert math.isclose(trials["A1"].path.period_s, 3.15)
