"""The trajectory objective's gradient (identification.objective_and_gradient): its pieces on
analytic cases, and the whole against central differences of the objective itself on
synthetic paths whose parameter derivatives are known in closed form (no simulation: the
sensitivities themselves are tested in tests/model/test_sensitivities.py)."""

import dataclasses
import math
import re
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from taichi_star import identification as ident

T = 2.0
DT = 1.0 / 64


def test_distance_derivative_is_the_projection_on_the_unit_vector():
    # |(3, 4)| = 5 and its derivative along (dx, dy) is (3 dx + 4 dy) / 5, for two directions
    delta = np.array([[3.0, 4.0], [0.0, 0.0]])
    derivative = np.array([[[1.0, 0.0], [0.0, 2.0]], [[1.0, 5.0], [2.0, 1.0]]])
    got = ident.distance_derivative(delta, derivative)
    np.testing.assert_allclose(got[0], [3.0 / 5.0, 8.0 / 5.0], rtol=1e-15)
    # at Δp = 0 the norm has no derivative: 0 by convention (module docstring)
    np.testing.assert_array_equal(got[1], [0.0, 0.0])


def test_path_derivative_interpolates_the_record_derivatives_linearly():
    t = np.array([0.0, 1.0, 3.0])
    path = ident.CentroidPath(t, np.zeros(3), np.zeros(3), T)
    records = np.zeros((3, 2, 1))
    records[:, 0, 0] = [0.0, 2.0, 6.0]      # dx/dθ
    records[:, 1, 0] = [1.0, 1.0, -3.0]     # dy/dθ
    got = ident.path_derivative(path, records, np.array([0.5, 2.0, 3.0]))
    np.testing.assert_allclose(got[:, 0, 0], [1.0, 4.0, 6.0], rtol=1e-15)
    np.testing.assert_allclose(got[:, 1, 0], [1.0, -1.0, -3.0], rtol=1e-15)


def model_path(theta, forward_sign=1.0, end_s=3 * T):
    """A simulated run pulsing at 0, T, 2T: per cycle a surge a·(1 − e^{−τ/0.2}) plus a glide
    b·τ/T along (cos 30°, sin 30°), and a sideways wobble c·sin(2πt/T); θ = (a, b, c). Returns
    the run and its record derivatives (n, 2, 3), exact."""
    a, b, c = theta
    t = np.arange(0, int(round(end_s / DT)) + 1) * DT
    local, cycle = np.mod(t, T), np.floor(t / T)
    surge, glide = cycle * (1 - np.exp(-T / 0.2)) + (1 - np.exp(-local / 0.2)), t / T
    along = forward_sign * (a * surge + b * glide)
    wobble = np.sin(2 * np.pi * t / T)
    direction, normal = np.array([np.cos(np.pi / 6), np.sin(np.pi / 6)]), np.array(
        [-np.sin(np.pi / 6), np.cos(np.pi / 6)])
    xy = along[:, None] * direction + c * wobble[:, None] * normal
    derivative = np.stack([forward_sign * surge[:, None] * direction,
                           forward_sign * glide[:, None] * direction,
                           wobble[:, None] * normal], axis=-1)          # (n, 2, 3)
    run = ident.SimulatedRun("A1+A2", ident.CentroidPath(t, xy[:, 0], xy[:, 1], T),
                             (float(direction[0]), float(direction[1])))
    return run, derivative


def measured_trial():
    """A "measurement": the model at other parameters, delayed by 0.37 s, with a small
    cycle-to-cycle variation (σ above its floor on a multi-cycle window)."""
    run, _ = model_path((3.1, 0.9, 0.3), end_s=8 * T)
    t = run.path.t_s + 0.37
    growth = 1.0 + 0.04 * np.floor(run.path.t_s / T)
    return ident.Trial("A1+A2", ident.CentroidPath(
        np.concatenate([[0.0], t]), np.concatenate([[0.0], run.path.x_mm * growth]),
        np.concatenate([[0.0], run.path.y_mm * growth]), T), +1.0)


def central_difference(theta, trials, cycles, phases=None, forward_sign=1.0, step=1e-6):
    gradient = []
    for p in range(3):
        values = []
        for sign in (1.0, -1.0):
            moved = np.array(theta, dtype=float)
            moved[p] += sign * step
            run, _ = model_path(moved, forward_sign)
            values.append(ident.objective_of(ident.trajectory_objective(
                {"A1+A2": run}, trials, cycles, samples=16, phases=phases)))
        gradient.append((values[0] - values[1]) / (2 * step))
    return np.array(gradient)


@pytest.mark.parametrize("cycles", [(1, 1), (1, 3)])
def test_gradient_equals_central_differences_at_held_phases(cycles):
    trials = {"A1+A2": measured_trial()}
    theta = (2.5, 1.2, 0.1)
    run, derivative = model_path(theta)
    fitted = ident.trajectory_objective({"A1+A2": run}, trials, cycles, samples=16)
    phases = {"A1+A2": float(fitted["phase_s"].iloc[0])}
    value, gradient, table = ident.objective_and_gradient(
        {"A1+A2": run}, {"A1+A2": derivative}, trials, cycles, samples=16, phases=phases)
    assert value == pytest.approx(ident.objective_of(fitted), rel=1e-15)
    expected = central_difference(theta, trials, cycles, phases)
    # the objective is a polynomial of degree ≤ 4 in θ away from Δp = 0 (squared distances
    # of affine paths, divided by a fixed σ): a central difference with step 1e-6 is exact to
    # O(1e-12) relative; its rounding, ~1e-16 · J / 1e-6 ≈ 1e-10 · J, sets the tolerance
    np.testing.assert_allclose(gradient, expected, rtol=1e-7, atol=1e-7 * abs(value))


def test_gradient_equals_central_differences_of_the_refitted_objective_with_sigma_at_floor():
    # one cycle: σ is at its floor, the objective is the misfit over a constant, and the
    # envelope theorem makes the held-phase gradient that of the re-fitted objective; the phase
    # is refitted to ~1e-9 s each time, and the objective is stationary in it, so the
    # difference quotients differ by O(J_φφ·(1e-9)²/1e-6): far below the tolerance
    trials = {"A1+A2": measured_trial()}
    theta = (2.5, 1.2, 0.1)
    run, derivative = model_path(theta)
    value, gradient, table = ident.objective_and_gradient(
        {"A1+A2": run}, {"A1+A2": derivative}, trials, (1, 1), samples=16)
    assert table["sigma_mm"].iloc[0] == ident.DISPLACEMENT_FLOOR_MM
    expected = central_difference(theta, trials, (1, 1))
    np.testing.assert_allclose(gradient, expected, rtol=1e-6, atol=1e-6 * abs(value))


@pytest.mark.parametrize("forward_sign", [1.0, -1.0])
def test_gradient_on_three_cycles_follows_the_refitted_phase(forward_sign):
    """Three cycles: σ depends on the phase, which moves with θ; the gradient (held-phase part
    plus `phase_motion`) equals central differences of the re-fitted objective. Step 1e-3: a
    smaller one is swamped by the refit's own precision (~1e-9 s × ∂J/∂φ ≈ 16 / step); at 1e-3
    the quotients' truncation was ~1e-6 of the largest component (measured 6e-7, 2e-6 and
    5.6e-6 absolute on -6.5, -4.7 and -0.061). Backwards (forward_sign −1) the wrong-way
    residual ρ = max(0, −sΔ)/σ(φ) moves with the phase too, and the objective (6,609) is
    dominated by it: there both sides carry noise of ~1e-5 of the largest component, the
    quotients the re-fitted phases' (1e-3 and 3e-4 steps differ by 2.4e-5 relative) and the
    gradient the phase's second difference at PHASE_STEP_S (two searches' phases 9e-10 s apart
    moved it 1.7e-5): measured 1.7e-5 of the largest component with the 192-point phase
    search, 5.8e-6 with the 64-point one: 5e-5 there, 1e-5 forwards (leaving the phase's
    motion out misses by 14-40 %, the assertion before)."""
    trials = {"A1+A2": measured_trial()}
    theta = (2.5, 1.2, 0.1)
    run, derivative = model_path(theta, forward_sign)
    value, gradient, table = ident.objective_and_gradient(
        {"A1+A2": run}, {"A1+A2": derivative}, trials, (1, 3), samples=16)
    assert table["sigma_mm"].iloc[0] > ident.DISPLACEMENT_FLOOR_MM
    residuals, jacobian, _ = ident.objective_residuals(
        {"A1+A2": run}, {"A1+A2": derivative}, trials, (1, 3), samples=16)
    held = 2.0 * jacobian.T @ residuals
    # the phase's motion is 14-40 % of the components here: leaving it out fails
    assert np.all(np.abs(gradient - held) > 0.1 * np.abs(gradient))
    assert (table["direction_residual"].iloc[0] > 0) == (forward_sign < 0)
    expected = central_difference(theta, trials, (1, 3), forward_sign=forward_sign, step=1e-3)
    tolerance = 1e-5 if forward_sign > 0 else 5e-5
    np.testing.assert_allclose(gradient, expected, rtol=0,
                               atol=tolerance * np.abs(expected).max())


def measured_track_run(theta, first_frame=30):
    """A "simulated" run that is the measured A1+A3 track itself from one of its frames on,
    scaled by θ (its derivative: the track); forward points against its net travel, so that
    the wrong-way residual is 0."""
    track = ident.measured_trials(["A1+A3"])["A1+A3"].path
    x = (track.x_mm[first_frame:] - track.x_mm[first_frame]) * theta
    y = (track.y_mm[first_frame:] - track.y_mm[first_frame]) * theta
    net = np.array([x[-1], y[-1]]) / np.hypot(x[-1], y[-1])
    path = ident.CentroidPath(track.t_s[first_frame:] - track.t_s[first_frame], x, y,
                              track.period_s)
    derivative = np.stack([x / theta, y / theta], axis=1)[:, :, None]
    return ident.SimulatedRun("A1+A3", path, (float(-net[0]), float(-net[1]))), derivative


def test_on_the_measured_track_the_phase_moves_between_kinks_and_not_at_one():
    """The measured track (60 frames/s, linear between frames): fitted between two kinks of
    the misfit the phase moves with θ, and the gradient with its motion equals central
    differences of the re-fitted objective (step 1e-4: measured agreement 7e-7 relative; the
    motion is 3 % of the gradient); set on a frame time, where the track's kink pulls every
    sample of a cycle at once, the kink test finds it and the phase has no motion."""
    trials = {"A1+A3": ident.measured_trials(["A1+A3"])["A1+A3"]}
    theta = 1.1
    run, derivative = measured_track_run(theta)
    _, gradient, table = ident.objective_and_gradient(
        {"A1+A3": run}, {"A1+A3": derivative}, trials, (1, 3))
    residuals, jacobian, _ = ident.objective_residuals(
        {"A1+A3": run}, {"A1+A3": derivative}, trials, (1, 3))
    assert abs(gradient[0] - 2.0 * jacobian[:, 0] @ residuals) > 0.01 * abs(gradient[0])
    refitted = [ident.objective_of(ident.trajectory_objective(
        {"A1+A3": measured_track_run(theta + sign * 1e-4)[0]}, trials, (1, 3)))
        for sign in (1.0, -1.0)]
    assert gradient[0] == pytest.approx((refitted[0] - refitted[1]) / 2e-4, rel=1e-5)
    fit = ident.trial_fit(run, trials["A1+A3"], (1, 3))
    frames = trials["A1+A3"].path.t_s
    on_frame = dataclasses.replace(fit, phase_s=float(frames[np.argmin(np.abs(frames
                                                                              - fit.phase_s))]))
    assert on_frame.phase_s != fit.phase_s
    np.testing.assert_array_equal(ident.trial_phase_motion(run, derivative, trials["A1+A3"],
                                                           on_frame, (1, 3)), [0.0])


@pytest.mark.parametrize("case", ["one cycle", "phase given", "phase at its bound",
                                  "phase at its upper bound"])
def test_the_phase_motion_is_left_out_exactly_where_it_is_zero(monkeypatch, case):
    """σ at its floor (envelope theorem), a held phase, and a phase at the edge of its range
    (the bound holds it): the gradient is 2·Jᵀr of the residuals, bit for bit."""
    trials = {"A1+A2": measured_trial()}
    run, derivative = model_path((2.5, 1.2, 0.1))
    cycles, phases = (1, 3), None
    if case == "one cycle":
        cycles = (1, 1)
    elif case == "phase given":
        phases = {"A1+A2": 0.41}
    elif case == "phase at its bound":
        monkeypatch.setattr(ident, "align_phase", lambda *args, **kwargs: 0.0)
    else:
        latest = ident.latest_phase(trials["A1+A2"], cycles)
        monkeypatch.setattr(ident, "align_phase", lambda *args, **kwargs: latest)
    _, gradient, table = ident.objective_and_gradient(
        {"A1+A2": run}, {"A1+A2": derivative}, trials, cycles, samples=16, phases=phases)
    residuals, jacobian, _ = ident.objective_residuals(
        {"A1+A2": run}, {"A1+A2": derivative}, trials, cycles, samples=16, phases=phases)
    np.testing.assert_array_equal(gradient, 2.0 * jacobian.T @ residuals)
    if case != "one cycle":
        assert table["sigma_mm"].iloc[0] > ident.DISPLACEMENT_FLOOR_MM


def test_direction_residual_enters_the_gradient_only_when_the_robot_swims_the_wrong_way():
    trials = {"A1+A2": measured_trial()}
    theta = (2.5, 1.2, 0.1)
    run, derivative = model_path(theta, forward_sign=-1.0)
    fitted = ident.trajectory_objective({"A1+A2": run}, trials, (1, 2), samples=16)
    phases = {"A1+A2": float(fitted["phase_s"].iloc[0])}
    value, gradient, table = ident.objective_and_gradient(
        {"A1+A2": run}, {"A1+A2": derivative}, trials, (1, 2), samples=16, phases=phases)
    assert table["direction_residual"].iloc[0] > 0
    expected = central_difference(theta, trials, (1, 2), phases, forward_sign=-1.0)
    # as in the held-phase test: polynomial in θ, step 1e-6, rounding ~1e-10 relative
    np.testing.assert_allclose(gradient, expected, rtol=1e-7, atol=1e-7 * abs(value))
    # the boundary −sΔ = 0 (no travel: a = b = 0, the wobble returns each cycle): the left
    # derivative, i.e. no direction term; the curve term is then all of the gradient
    still, still_derivative = model_path((0.0, 0.0, 0.1))
    _, at_kink, fit = ident.objective_and_gradient(
        {"A1+A2": still}, {"A1+A2": still_derivative}, trials, (1, 1), samples=16)
    assert fit["sim_net_signed_mm"].iloc[0] == pytest.approx(0.0, abs=1e-12)
    phases = {"A1+A2": float(fit["phase_s"].iloc[0])}
    run_plus, _ = model_path((1e-6, 0.0, 0.1))
    table = ident.trajectory_objective({"A1+A2": run_plus}, trials, (1, 1), 16, phases)
    assert table["direction_residual"].iloc[0] == 0.0   # moving a up keeps ρ at 0


def test_record_derivatives_reads_the_sensitivity_columns():
    table = {"instance": [0, 0, 1, 1], "t_s": [0.0, 1.0, 0.0, 1.0],
             "d(x_mm)/d(alpha)": [1.0, 2.0, 3.0, 4.0], "d(y_mm)/d(alpha)": [5.0, 6.0, 7.0, 8.0],
             "d(x_mm)/d(actuator_gains[1])": [9.0, 10.0, 11.0, 12.0],
             "d(y_mm)/d(actuator_gains[1])": [13.0, 14.0, 15.0, 16.0]}
    got = ident.record_derivatives(pd.DataFrame(table), 1, ["alpha", "actuator_gains[1]"])
    np.testing.assert_array_equal(got, [[[3.0, 11.0], [7.0, 15.0]], [[4.0, 12.0], [8.0, 16.0]]])
    # a name the run was not differentiated by, or a whole per-actuator field, was a KeyError
    # of a column; an instance it does not hold, an empty array (an audit, 2026-12)
    for names in (["alpha", "drag_perpendicular"], ["actuator_gains"]):
        with pytest.raises(ValueError, match=rf"^parameters: '{re.escape(names[-1])}' not "
                                             rf"among those the run was differentiated by "
                                             rf"\(alpha, actuator_gains\[1\]; "):
            ident.record_derivatives(pd.DataFrame(table), 1, names)
    with pytest.raises(ValueError, match=r"^instance 7: no records of it in "
                                         r"trajectory_sensitivities \(its instances: 0\.\.1\)"):
        ident.record_derivatives(pd.DataFrame(table), 7, ["alpha"])
    with pytest.raises(ValueError, match=r"\(it holds no records: a run with record_interval_s "
                                         r"> 0 has them\)$"):
        ident.record_derivatives(pd.DataFrame(table).iloc[:0], 0, ["alpha"])
    with pytest.raises(ValueError, match=r"^trajectory_sensitivities must be a result's table of "
                                         r"them .*, got NoneType$"):
        ident.record_derivatives(None, 0, ["alpha"])  # a run without sensitivities


def test_trial_residuals_refuse_derivatives_of_the_wrong_shape():
    run, derivative = model_path((2.5, 1.2, 0.1))
    with pytest.raises(ValueError, match=r"derivative_xy must have shape \(385, 2, P\)"):
        ident.trial_residuals(run, derivative[:-1], measured_trial(), (1, 1), 16)


def test_any_wrong_way_travel_gets_a_direction_row_however_small():
    """Backwards by a few micrometres over the window (a = 1e-3 mm per surge): ρ > 0, and its
    Jacobian row is −s·dΔ/dθ / σ, the surge's and the glide's net derivatives along the
    forward axis (the wobble c returns each cycle: 0)."""
    run, derivative = model_path((1e-3, 0.0, 0.1), forward_sign=-1.0)
    fit, residuals, jacobian = ident.trial_residuals(run, derivative, measured_trial(), (1, 1),
                                                     16)
    assert 0.0 < -fit.sim_net_signed_mm < 1e-2 and residuals[-1] == fit.direction_residual > 0
    surge_net = 1 - np.exp(-T / 0.2)        # model_path's surge over one cycle, glide's is 1
    np.testing.assert_allclose(jacobian[-1], [surge_net / fit.sigma_mm, 1.0 / fit.sigma_mm, 0.0],
                               rtol=1e-12, atol=1e-12)
    # no travel at all (the boundary −sΔ = 0 exactly): no row, as for the right way
    still, still_derivative = model_path((0.0, 0.0, 0.0))
    fit, residuals, jacobian = ident.trial_residuals(still, still_derivative, measured_trial(),
                                                     (1, 1), 16)
    assert fit.sim_net_signed_mm == 0.0 and residuals[-1] == 0.0
    np.testing.assert_array_equal(jacobian[-1], [0.0, 0.0, 0.0])


@pytest.mark.parametrize("shape, moves", [("parabola", True), ("flat", False), ("kink", False),
                                          ("parabola and kink", False)])
def test_the_phase_moves_only_where_the_misfit_is_smoothly_convex(monkeypatch, shape, moves):
    """The kink rule of `trial_phase_motion` on misfits of known shape about the fitted phase
    φ₀ (the misfit replaced; everything else the three-cycle synthetic case, whose objective
    changes with the phase): a parabola of curvature 0.2 (below 1: any positive curvature
    counts) moves; a flat misfit (curvature exactly 0) and a convex kink |φ − φ₀| (second
    differences 2/h: ten times larger at the small step than at the wide one) do not, nor a
    parabola a·δ² with a kink 2a·h·|δ| (h = PHASE_STEP_S): second differences 2a + 4a at the
    small step and 2a + 0.4a at the wide one, a ratio of 2.5, above the rule's 2."""
    trial = measured_trial()
    run, derivative = model_path((2.5, 1.2, 0.1))
    fit = ident.trial_fit(run, trial, (1, 3), 16)
    assert fit.sigma_mm > ident.DISPLACEMENT_FLOOR_MM
    centre = fit.phase_s
    misfit = {"parabola": lambda at: 0.1 * (at - centre) ** 2, "flat": lambda at: 1.0,
              "kink": lambda at: abs(at - centre),
              "parabola and kink": lambda at: 0.1 * (at - centre) ** 2
              + 0.2 * ident.PHASE_STEP_S * abs(at - centre)}[shape]
    monkeypatch.setattr(ident, "_misfit", lambda curves, trial, at, cycles, samples: misfit(at))
    motion = ident.trial_phase_motion(run, derivative, trial, fit, (1, 3), 16)
    assert np.any(motion != 0.0) == moves


@pytest.mark.parametrize("forward_sign, cycles", [(1.0, (1, 3)), (-1.0, (1, 2)), (-1.0, (2, 3))])
def test_residuals_square_to_the_objective_and_their_jacobian_equals_central_differences(
        forward_sign, cycles):
    # the least-squares form: Σ r² is the objective (mean over gaits), and each residual's
    # Jacobian row is its derivative at held phases; the backward gait makes ρ > 0, so the
    # direction row is checked too (on its own branch: ρ stays > 0 within the step)
    trials = {"A1+A2": measured_trial(), "A1+A3": measured_trial()}
    theta = (2.5, 1.2, 0.1)
    run, derivative = model_path(theta, forward_sign)

    def both_gaits(run):  # the same path stands for a second gait, compared with its own trial
        return {"A1+A2": run, "A1+A3": dataclasses.replace(run, gait="A1+A3")}

    runs, derivatives = both_gaits(run), {"A1+A2": derivative, "A1+A3": derivative}
    trials["A1+A3"] = ident.Trial("A1+A3", trials["A1+A3"].path, +1.0)
    residuals, jacobian, table = ident.objective_residuals(runs, derivatives, trials, cycles,
                                                           samples=16)
    assert residuals.shape == (2 * ((cycles[1] - cycles[0] + 1) * 16 + 1),)
    assert ident.residual_count(2, cycles, 16) == len(residuals)
    assert jacobian.shape == residuals.shape + (3,)
    # the sum is the mean of the two gaits' objectives up to the summation's rounding
    assert float(residuals @ residuals) == pytest.approx(ident.objective_of(table), rel=1e-13)
    assert (table["direction_residual"] > 0).all() == (forward_sign < 0)
    phases = dict(zip(table["gait"], table["phase_s"]))
    step, columns = 1e-6, []
    for p in range(3):
        moved = []
        for sign in (1.0, -1.0):
            shifted = np.array(theta)
            shifted[p] += sign * step
            moved_run, _ = model_path(shifted, forward_sign)
            moved.append(ident.objective_residuals(
                both_gaits(moved_run), derivatives, trials, cycles, 16,
                phases)[0])
        columns.append((moved[0] - moved[1]) / (2 * step))
    # each residual is a distance of affine paths over a fixed σ (smooth away from Δp = 0),
    # so the central difference is exact to O(step²) ≈ 1e-12; its rounding, ~1e-16·|r|/1e-6,
    # sets the tolerance
    scale = np.abs(residuals).max()
    np.testing.assert_allclose(jacobian, np.stack(columns, axis=-1), rtol=1e-7,
                               atol=1e-8 * scale)


def test_result_runs_drop_instances_whose_status_is_not_ok():
    """An instance flagged by the engine can have finite records (frozen at its last state):
    `result_runs` gives None for it, as for a non-finite one, and a run for the others."""
    t = np.linspace(0.0, 6.3, 4)
    trajectory = pd.DataFrame({"instance": np.repeat([0, 1, 2], 4), "t_s": np.tile(t, 3),
                               "x_mm": np.r_[t, 2 * t, np.nan * t], "y_mm": np.zeros(12)})
    summary = pd.DataFrame({"status": ["ok", "non_finite", "ok"]})
    result = SimpleNamespace(trajectory=trajectory, summary=summary)
    params = [SimpleNamespace(gait="A1+A2", period=3.15)] * 3
    runs = ident.result_runs(result, params)
    assert runs[1] is None and runs[2] is None  # flagged; non-finite records
    assert runs[0].path.x_mm.tolist() == t.tolist() and runs[0].path.period_s == 3.15
    # the flagged instance's records alone would have made a run
    assert ident.simulated_runs(trajectory, ["A1+A2"] * 3, [3.15] * 3)[1] is not None


def test_a_failed_run_has_no_gradient_and_says_so_naming_its_gait():
    """`trajectory_objective` scores a failed run (None) inf; the residuals and the gradient
    of one raised an AttributeError of NoneType (a mutation audit, 2026-12)."""
    trials = {"A1+A2": measured_trial()}
    run, derivative = model_path((2.5, 1.2, 0.1))
    assert ident.objective_of(ident.trajectory_objective({"A1+A2": None}, trials)) == math.inf
    for call in (ident.objective_residuals, ident.objective_and_gradient):
        with pytest.raises(ValueError, match=r"^simulated\['A1\+A2'\] is None \(a failed run\)"):
            call({"A1+A2": None}, {"A1+A2": derivative}, trials)
