"""How far a fit's data determine a prediction (identification.prediction_uncertainty) and the
linearised leave-one-gait-out built on it (identification.gait_predictions): against the
normal equations of linear fits, on exactly unresolved directions and at the share's
boundary, and on synthetic paths whose derivatives are known in closed form (no simulation)."""

import dataclasses
import math

import numpy as np
import pandas as pd
import pytest

from taichi_star import identification as ident

from .test_identification_gradient import T, measured_trial, model_path


def _linear_fit(rng, rows=40):
    """A linear model's Jacobian (its design), values of three scales and residuals."""
    design = rng.normal(size=(rows, 3)) / np.array([2.0, 0.5, 30.0])
    return rng.normal(size=rows), design, np.array([2.0, -0.5, 30.0])


def test_a_prediction_of_a_full_rank_fit_has_the_gauss_newton_variance():
    """Against s²·gᵀ(JᵀJ)⁻¹g from the normal equations (numpy's inverse, another route than
    the scaled SVD; cond(JᵀJ) ~10, so 1e-12 leaves room for rounding). A prediction that is a
    parameter itself has that parameter's standard error from `parameter_uncertainty`, and
    the error does not depend on the parameters' units (a column × 1e3, its value / 1e3, its
    gradient entry × 1e3)."""
    residuals, jacobian, values = _linear_fit(np.random.default_rng(7))
    gradient = np.array([0.3, -2.0, 0.01])
    got = ident.prediction_uncertainty(residuals, jacobian, values, gradient)
    variance = residuals @ residuals / (len(residuals) - 3)
    expected = math.sqrt(variance * gradient @ np.linalg.inv(jacobian.T @ jacobian) @ gradient)
    assert got.standard_error == pytest.approx(expected, rel=1e-12)
    assert got.unresolved_share < 1e-12 and got.determined
    assert (got.rank, got.residual_dof) == (3, len(residuals) - 3)
    table = ident.parameter_uncertainty(residuals, jacobian, ["a", "b", "c"], values)
    for j in range(3):
        own = ident.prediction_uncertainty(residuals, jacobian, values, np.eye(3)[j])
        assert own.standard_error == pytest.approx(table.standard_error[j], rel=1e-12)
    units = np.array([1.0, 1.0, 1e3])
    rescaled = ident.prediction_uncertainty(residuals, jacobian * units, values / units,
                                            gradient * units)
    assert rescaled.standard_error == pytest.approx(expected, rel=1e-12)


def test_a_prediction_along_a_direction_the_data_cannot_see_is_undetermined():
    """Column c = 2 × column a leaves (2, 0, −1) (relative units: values 1) unseen. A
    prediction along it is undetermined (inf, share 1); one orthogonal to it (b alone, or
    a + 2c, which moves the residuals as 5a does) keeps the pseudo-inverse's variance,
    s²·gᵀ(JᵀJ)⁺g over R − 2 degrees of freedom; a zero gradient is known exactly."""
    residuals, jacobian, _ = _linear_fit(np.random.default_rng(11))
    jacobian[:, 2] = 2.0 * jacobian[:, 0]
    values = np.ones(3)
    unseen = ident.prediction_uncertainty(residuals, jacobian, values, [2.0, 0.0, -1.0])
    assert unseen.standard_error == math.inf and not unseen.determined
    assert (unseen.rank, unseen.residual_dof) == (2, len(residuals) - 2)
    assert unseen.unresolved_share == pytest.approx(1.0, rel=1e-12)
    variance = residuals @ residuals / (len(residuals) - 2)
    inverse = np.linalg.pinv(jacobian.T @ jacobian)
    for gradient in ([0.0, 1.0, 0.0], [1.0, 0.0, 2.0]):
        seen = ident.prediction_uncertainty(residuals, jacobian, values, gradient)
        gradient = np.array(gradient)
        assert seen.standard_error == pytest.approx(
            math.sqrt(variance * gradient @ inverse @ gradient), rel=1e-9)
        assert seen.unresolved_share < 1e-12 and seen.rank == 2
    zero = ident.prediction_uncertainty(residuals, jacobian, values, np.zeros(3))
    assert (zero.standard_error, zero.unresolved_share, zero.rank) == (0.0, 0.0, 2)
    assert zero.residual_dof == len(residuals) - 2


def test_a_prediction_is_determined_up_to_exactly_its_unresolved_share():
    """A diagonal Jacobian whose second direction (1e-7 of the first) is unresolved, and a
    prediction turned from the first axis by a small angle: its share is sin(angle); with
    `share` at exactly that it is determined (≤), just below not."""
    jacobian = np.vstack([np.diag([1.0, 1e-7]), np.zeros((4, 2))])
    residuals = np.arange(6.0)
    angle = 0.004
    gradient = [math.cos(angle), math.sin(angle)]
    first = ident.prediction_uncertainty(residuals, jacobian, [1.0, 1.0], gradient)
    assert first.unresolved_share == pytest.approx(math.sin(angle), rel=1e-12)
    at = ident.prediction_uncertainty(residuals, jacobian, [1.0, 1.0], gradient,
                                      share=first.unresolved_share)
    below = ident.prediction_uncertainty(residuals, jacobian, [1.0, 1.0], gradient,
                                         share=first.unresolved_share * (1 - 1e-12))
    assert at.determined and not below.determined
    # determined: the resolved part alone, s·cos(angle)/1 with s² = Σr²/(6 − 1)
    assert at.standard_error == pytest.approx(math.sqrt(55.0 / 5) * math.cos(angle), rel=1e-12)


@pytest.mark.parametrize("gradient", [[1.0, 2.0], [1.0, math.nan, 0.0], [[1.0, 0.0, 0.0]]])
def test_a_gradient_that_does_not_match_the_values_is_refused(gradient):
    residuals, jacobian, values = _linear_fit(np.random.default_rng(2))
    with pytest.raises(ValueError, match="one finite number per value"):
        ident.prediction_uncertainty(residuals, jacobian, values, gradient)


def test_a_gradient_near_the_float_range_is_scaled_not_overflowed():
    """The standard error is linear in the gradient: 1e300 × (1, 1, 1) (squares beyond the
    float range) gives 1e300 × the error of (1, 1, 1), to rounding (1e-12); a gradient whose
    product with |value| (2) overflows is refused, naming it."""
    residuals, jacobian, values = _linear_fit(np.random.default_rng(2))
    unit = ident.prediction_uncertainty(residuals, jacobian, values, np.ones(3))
    huge = ident.prediction_uncertainty(residuals, jacobian, values, np.full(3, 1e300))
    assert huge.standard_error == pytest.approx(1e300 * unit.standard_error, rel=1e-12)
    assert huge.unresolved_share == unit.unresolved_share
    with pytest.raises(ValueError, match=r"gradient × \|value\| overflows: give the gradient "
                                         r"and values in units where their product is finite"):
        ident.prediction_uncertainty(residuals, jacobian, values, [1e308, 0.0, 0.0])


def test_values_that_are_not_one_dimensional_are_refused_as_values():
    residuals, jacobian, values = _linear_fit(np.random.default_rng(2))
    with pytest.raises(ValueError, match=r"values must be a 1-D array \(P,\)"):
        ident.prediction_uncertainty(residuals, jacobian, values[None, :], np.ones(3))


@pytest.mark.parametrize("count", [2, 4])
def test_values_of_another_count_than_the_jacobians_columns_are_refused_as_values(count):
    """One value too few or too many for the Jacobian's three columns, with a gradient that
    matches the values: the values are named (the gradient was: an audit, 2026-12)."""
    residuals, jacobian, _ = _linear_fit(np.random.default_rng(2))
    with pytest.raises(ValueError, match=rf"^values must hold one number per column of "
                                         rf"jacobian \(3\), got {count}$"):
        ident.prediction_uncertainty(residuals, jacobian, np.ones(count), np.ones(count))


def test_the_fit_is_checked_as_parameter_uncertainty_checks_it():
    residuals, jacobian, values = _linear_fit(np.random.default_rng(2))
    with pytest.raises(ValueError, match="^residuals, jacobian and values must be finite$"):
        ident.prediction_uncertainty(np.full_like(residuals, np.nan), jacobian, values,
                                     np.ones(3))
    with pytest.raises(ValueError, match="share must be in"):
        ident.prediction_uncertainty(residuals, jacobian, values, np.ones(3), share=1.0)
    with pytest.raises(ValueError, match="no residual degree of freedom"):
        ident.prediction_uncertainty(residuals[:3], jacobian[:3], values, np.ones(3))


# ------------------------------------------------------------------ on paths

def test_window_speed_and_its_derivative_against_the_path_itself():
    """The speed is the forward net move over the window / its duration (trial_fit's
    simulated speed), and the model path is linear in θ = (a, b, c), so its derivative
    equals a central difference of the speed to rounding (1e-9 of a step 1e-3)."""
    theta = np.array([2.0, 0.7, 0.2])
    run, derivative = model_path(theta, forward_sign=-1.0)
    speed, gradient = ident.window_speed(run, derivative, (2, 3))
    fit = ident.trial_fit(dataclasses.replace(run), measured_trial(), (2, 3))
    assert speed == pytest.approx(fit.sim_speed_mm_s, rel=1e-14)
    assert speed < 0  # the path runs against its forward axis
    for p in range(3):
        moved = [ident.window_speed(model_path(theta + sign * 1e-3 * np.eye(3)[p], -1.0)[0],
                                    derivative, (2, 3))[0] for sign in (1.0, -1.0)]
        assert gradient[p] == pytest.approx((moved[0] - moved[1]) / 2e-3, rel=1e-9, abs=1e-12)


def _gaits_and_trials():
    """Three synthetic "gaits" at θ = (a, b, c, d): A1 and A1+A2 the model path (d moves
    nothing), A1+A3 the path run backwards along its forward axis with its surge a + d (so only
    it sees d); trials of each made from the measured_trial path, A1+A3's with the paper's
    sign −1 (its robot measured swimming in reverse, as the simulated one does)."""
    theta = (2.6, 0.8, 0.25)
    runs, derivatives, trials = {}, {}, {}
    for gait, forward_sign in (("A1", 1.0), ("A1+A2", 1.0), ("A1+A3", -1.0)):
        run, derivative = model_path(theta, forward_sign)
        runs[gait] = dataclasses.replace(run, gait=gait)
        d_column = derivative[:, :, :1] if gait == "A1+A3" else np.zeros_like(derivative[:, :, :1])
        derivatives[gait] = np.concatenate([derivative, d_column], axis=-1)
        trials[gait] = dataclasses.replace(measured_trial(), gait=gait,
                                           paper_sign=forward_sign)
    return runs, derivatives, trials


def test_gait_predictions_hold_a_gait_out_of_the_fit_and_say_what_the_others_determine():
    runs, derivatives, trials = _gaits_and_trials()
    values = np.array([2.6, 0.8, 0.25, 1.0])
    extra, extra_derivative = model_path((2.6, 0.8, 0.25))
    runs["A2"] = dataclasses.replace(extra, gait="A2")
    derivatives["A2"] = np.concatenate([extra_derivative, np.zeros((len(extra.path.t_s), 2, 1))],
                                       axis=-1)
    table = ident.gait_predictions(runs, derivatives, trials, values, (1, 3))
    assert list(table.columns) == ident.PREDICTION_COLUMNS
    assert list(zip(table.gait, table.role)) == [
        ("A1", "fitted"), ("A1+A2", "fitted"), ("A1+A3", "fitted"), ("A1", "held_out"),
        ("A1+A2", "held_out"), ("A1+A3", "held_out"), ("A2", "unmeasured")]
    rows = {(row.gait, row.role): row for row in table.itertuples()}
    # only A1+A3 moves with d: held out, the others leave its speed undetermined
    held = rows[("A1+A3", "held_out")]
    assert held.standard_error_mm_s == math.inf and not held.determined
    assert held.within_two_standard_errors and math.isnan(held.z_score)
    assert held.training_gaits == "A1 A1+A2" and held.rank == 3
    # the unresolved direction is d's axis exactly (its column is zero without A1+A3)
    _, gradient = ident.window_speed(runs["A1+A3"], derivatives["A1+A3"], (1, 3))
    scaled = gradient * values
    assert held.unresolved_share == pytest.approx(abs(scaled[3]) / np.linalg.norm(scaled),
                                                  rel=1e-12)
    # the same gait in the fit: its standard error is that of the normal equations
    residuals, jacobian, _ = ident.objective_residuals(
        {g: runs[g] for g in trials}, derivatives, trials, (1, 3))
    for gait in trials:
        row = rows[(gait, "fitted")]
        speed, gradient = ident.window_speed(runs[gait], derivatives[gait], (1, 3))
        scaled = gradient * np.abs(values)
        relative = jacobian * np.abs(values)
        variance = residuals @ residuals / (len(residuals) - 4)
        expected = math.sqrt(variance * scaled @ np.linalg.inv(relative.T @ relative) @ scaled)
        assert row.determined and row.standard_error_mm_s == pytest.approx(expected, rel=1e-8)
        fit = ident.trial_fit(runs[gait], trials[gait], (1, 3))
        assert row.predicted_speed_mm_s == pytest.approx(fit.sim_speed_mm_s, rel=1e-14)
        # the distance covered, signed by the paper's direction: A1+A3 measured in reverse
        assert row.measured_speed_mm_s == pytest.approx(trials[gait].paper_sign
                                                        * fit.meas_speed_mm_s, rel=1e-14)
        assert np.sign(row.measured_speed_mm_s) == (-1 if gait == "A1+A3" else 1)
        # the model path runs along its forward axis with a sideways wobble that returns each
        # cycle: the distance covered equals |speed| to rounding
        assert row.distance_speed_mm_s == pytest.approx(abs(speed), rel=1e-12)
        gap = row.measured_speed_mm_s - row.predicted_speed_mm_s
        assert row.z_score == pytest.approx(gap / row.standard_error_mm_s, rel=1e-12)
        assert row.within_two_standard_errors == (abs(gap) <= 2 * row.standard_error_mm_s)
    # A1 held out: A1+A2 is the same path, so the others determine it, d aside
    assert rows[("A1", "held_out")].determined
    unmeasured = rows[("A2", "unmeasured")]
    assert unmeasured.determined and math.isnan(unmeasured.measured_speed_mm_s)
    assert unmeasured.within_two_standard_errors is None
    assert unmeasured.training_gaits == "A1 A1+A2 A1+A3"


def test_gait_predictions_refuse_what_they_cannot_answer():
    runs, derivatives, trials = _gaits_and_trials()
    values = np.array([2.6, 0.8, 0.25, 1.0])
    with pytest.raises(ValueError, match=r"no simulated run for the measured gait\(s\) "
                                         r"A1\+A2, A1\+A3$"):
        ident.gait_predictions({"A1": runs["A1"]}, derivatives, trials, values)
    with pytest.raises(ValueError, match="at least two measured gaits"):
        ident.gait_predictions(runs, derivatives, {"A1": trials["A1"]}, values)
    # a gait without its derivatives was a KeyError naming the gait alone (an audit, 2026-12)
    partial = {gait: derivatives[gait] for gait in derivatives if gait != "A1+A2"}
    with pytest.raises(ValueError, match=r"^derivatives has no entry for gait 'A1\+A2'; "
                                         r"derivatives: " + ", ".join(partial).replace("+", r"\+")
                                         + "$"):
        ident.gait_predictions(runs, partial, trials, values)


def test_gait_predictions_of_a_later_window_read_it_at_the_phase_fitted_on_the_fit_window():
    """Fitted on cycle 1, predicted over cycles 2-3: the speeds are those of cycles 2-3, the
    measured one read there at the phase fitted on cycle 1; the standard errors are the fit's
    covariance carried to the later speed (the same rows as over cycle 1 otherwise)."""
    runs, derivatives, trials = _gaits_and_trials()
    values = np.array([2.6, 0.8, 0.25, 1.0])
    later = ident.gait_predictions(runs, derivatives, trials, values, (1, 1),
                                   predict_cycles=(2, 3))
    same = ident.gait_predictions(runs, derivatives, trials, values, (1, 1))
    assert (later.first_cycle == 2).all() and (later.last_cycle == 3).all()
    assert (same.first_cycle == 1).all() and (same.last_cycle == 1).all()
    residuals, jacobian, _ = ident.objective_residuals(
        {g: runs[g] for g in ("A1", "A1+A2")}, derivatives,
        {g: trials[g] for g in ("A1", "A1+A2")}, (1, 1))
    for row in later.itertuples():
        speed, gradient = ident.window_speed(runs[row.gait], derivatives[row.gait], (2, 3))
        assert row.predicted_speed_mm_s == pytest.approx(speed, rel=1e-14)
        phase = ident.trial_fit(runs[row.gait], trials[row.gait], (1, 1)).phase_s
        fit = ident.trial_fit(runs[row.gait], trials[row.gait], (2, 3), phase_s=phase)
        assert row.measured_speed_mm_s == pytest.approx(
            trials[row.gait].paper_sign * fit.meas_speed_mm_s, rel=1e-14)
        if row.role == "held_out" and row.gait == "A1+A3":
            expected = ident.prediction_uncertainty(residuals, jacobian, values, gradient)
            assert row.standard_error_mm_s == expected.standard_error == math.inf
    np.testing.assert_array_equal(later.training_objective, same.training_objective)
    # the model path repeats each cycle; the "measurement" grows 4 % a cycle
    np.testing.assert_allclose(later.predicted_speed_mm_s, same.predicted_speed_mm_s, rtol=1e-9)
    assert (later.measured_speed_mm_s.abs() > 1.03 * same.measured_speed_mm_s.abs()).all()


def test_a_window_the_simulated_path_does_not_cover_is_refused():
    """The path ends at 3T: cycles 3-4 need it to 4T (np.interp would hold its last point);
    cycles 3-3 end exactly at its last record, which is allowed (≤)."""
    run, derivative = model_path((2.0, 0.7, 0.2))
    with pytest.raises(ValueError, match=r"cycles 3-4 need the simulated path over \[4, 8\] s"):
        ident.window_speed(run, derivative, (3, 4))
    assert math.isfinite(ident.window_speed(run, derivative, (3, 3))[0])


def test_a_window_before_the_path_starts_is_refused_naming_what_the_path_covers():
    """A path recorded from T on cannot give cycle 1 (from 0); the message names the window
    needed and the path's own span."""
    run, derivative = model_path((2.0, 0.7, 0.2))
    late = dataclasses.replace(run, path=ident.CentroidPath(
        run.path.t_s[64:], run.path.x_mm[64:], run.path.y_mm[64:], T))
    with pytest.raises(ValueError, match=r"cycles 1-1 need the simulated path over \[0, 2\] s; "
                                         r"it covers \[1, 6\] s"):
        ident.window_speed(late, derivative[64:], (1, 1))


def _growing(run, derivative, rate=0.1):
    """The run with every record scaled by 1 + rate·(cycle − 1), its derivatives likewise (the
    path stays linear in θ): a robot that speeds up from cycle to cycle."""
    factor = 1.0 + rate * np.floor(run.path.t_s / run.path.period_s + 1e-9)
    path = ident.CentroidPath(run.path.t_s, run.path.x_mm * factor, run.path.y_mm * factor,
                              run.path.period_s)
    return dataclasses.replace(run, path=path), derivative * factor[:, None, None]


def test_gait_predictions_of_a_robot_that_speeds_up_use_the_predicted_window_throughout():
    """On paths that speed up from cycle to cycle each window has its own speed and distance:
    the rows of cycles 2-3 are those of cycles 2-3, not of the fit's cycle 1 nor of cycles 1-3
    (the distance over [T, 3T], its start not at the origin); the fits' objectives and residual
    degrees of freedom are those of their own gaits, on `samples` points per cycle."""
    runs, derivatives, trials = _gaits_and_trials()
    for gait in runs:
        runs[gait], derivatives[gait] = _growing(runs[gait], derivatives[gait])
    values = np.array([2.6, 0.8, 0.25, 1.0])
    table = ident.gait_predictions(runs, derivatives, trials, values, (1, 1), samples=32,
                                   predict_cycles=(2, 3))
    for row in table.itertuples():
        run = runs[row.gait]
        speed, _ = ident.window_speed(run, derivatives[row.gait], (2, 3))
        assert row.predicted_speed_mm_s == pytest.approx(speed, rel=1e-14)
        assert speed != pytest.approx(ident.window_speed(run, derivatives[row.gait], (1, 3))[0],
                                      rel=1e-3)
        ends = run.path.position(np.array([1.0, 3.0]) * T)
        assert row.distance_speed_mm_s == pytest.approx(
            np.hypot(*(ends[1] - ends[0])) / (2 * T), rel=1e-14)
        training = row.training_gaits.split()
        objective = ident.objective_of(ident.trajectory_objective(
            {g: runs[g] for g in training}, {g: trials[g] for g in training}, (1, 1), 32))
        assert row.training_objective == pytest.approx(objective, rel=1e-14)
        assert row.residual_dof == len(training) * (32 + 1) - row.rank


def test_gait_predictions_pass_the_share_on_and_take_exactly_two_measured_gaits():
    """A1+A3 held out has an unresolved share of ~0.3 (d's axis): undetermined at the default
    share (1 %), determined at share 0.99; two measured gaits (the fewest) are enough."""
    runs, derivatives, trials = _gaits_and_trials()
    values = np.array([2.6, 0.8, 0.25, 1.0])
    loose = ident.gait_predictions(runs, derivatives, trials, values, (1, 3), share=0.99)
    held = loose[(loose.gait == "A1+A3") & (loose.role == "held_out")].iloc[0]
    assert held.determined and 0.01 < held.unresolved_share < 0.99
    two = ident.gait_predictions({g: runs[g] for g in ("A1", "A1+A2")}, derivatives,
                                 {g: trials[g] for g in ("A1", "A1+A2")}, values, (1, 3))
    assert list(two.role) == ["fitted", "fitted", "held_out", "held_out"]


def test_within_two_standard_errors_includes_the_boundary_and_a_zero_error_gives_no_z(
        monkeypatch):
    """The rule is |measured − predicted| ≤ 2 s.e.: a standard error of exactly half the gap
    (halving is exact in binary) is within, one a hair smaller is not; an error of 0 (a speed
    no fitted parameter moves) gives no z-score, and within only for an exact match."""
    runs, derivatives, trials = _gaits_and_trials()
    values = np.array([2.6, 0.8, 0.25, 1.0])
    plain = ident.gait_predictions(runs, derivatives, trials, values, (1, 3))
    gaps = dict(zip(plain.gait + plain.role, plain.measured_speed_mm_s
                    - plain.predicted_speed_mm_s))

    def table_with(error_of_gap):
        calls = iter(plain.gait + plain.role)

        def fixed(residuals, jacobian, values, gradient, rcond, share, added_jacobian):
            return ident.PredictionUncertainty(error_of_gap(abs(gaps[next(calls)])), 0.0, 4, 1)
        monkeypatch.setattr(ident, "prediction_uncertainty", fixed)
        return ident.gait_predictions(runs, derivatives, trials, values, (1, 3))

    at = table_with(lambda gap: gap / 2.0)
    assert at.within_two_standard_errors[:6].all()
    below = table_with(lambda gap: np.nextafter(gap / 2.0, 0.0))
    assert not below.within_two_standard_errors[:6].any()
    zero = table_with(lambda gap: 0.0)
    assert zero.z_score.isna().all() and not zero.within_two_standard_errors[:6].any()


# ------------------------------------------------------------------ trials not yet measured

def test_added_rows_give_the_normal_equations_with_them_and_the_fits_own_scatter():
    """Rows of a trial not yet measured join the Jacobian, not the residuals: against
    s²·gᵀ(JᵀJ + AᵀA)⁻¹g with s² = Σr²/(R − 3) of the fit alone (numpy's inverse, another route
    than the SVD; cond ~10: 1e-12); the parameters' standard errors likewise; the rank is of J
    and A together, the residual degrees of freedom the fit's own. The added rows halve
    nothing for free: with A = J (the same trial twice) the variance halves exactly."""
    residuals, jacobian, values = _linear_fit(np.random.default_rng(7))
    added = np.random.default_rng(8).normal(size=(25, 3)) / np.array([2.0, 0.5, 30.0])
    gradient = np.array([0.3, -2.0, 0.01])
    got = ident.prediction_uncertainty(residuals, jacobian, values, gradient,
                                       added_jacobian=added)
    variance = residuals @ residuals / (len(residuals) - 3)
    inverse = np.linalg.inv(jacobian.T @ jacobian + added.T @ added)
    assert got.standard_error == pytest.approx(math.sqrt(variance * gradient @ inverse @ gradient),
                                               rel=1e-12)
    assert (got.rank, got.residual_dof) == (3, len(residuals) - 3)
    table = ident.parameter_uncertainty(residuals, jacobian, ["a", "b", "c"], values,
                                        added_jacobian=added)
    np.testing.assert_allclose(table.standard_error, np.sqrt(variance * np.diag(inverse)),
                               rtol=1e-12)
    assert (table.residual_dof == len(residuals) - 3).all()
    alone = ident.prediction_uncertainty(residuals, jacobian, values, gradient)
    twice = ident.prediction_uncertainty(residuals, jacobian, values, gradient,
                                         added_jacobian=jacobian)
    assert twice.standard_error == pytest.approx(alone.standard_error / math.sqrt(2), rel=1e-12)


def test_an_added_trial_resolves_a_direction_the_fit_cannot_see():
    """Column c = 2 × column a leaves (2, 0, −1) unseen (values 1): a prediction along it is
    undetermined by the fit alone and determined once rows that see c on its own are added,
    with the variance of the normal equations of J and A over the fit's R − 2 degrees of
    freedom; the rank rises to 3, the degrees of freedom do not move."""
    residuals, jacobian, _ = _linear_fit(np.random.default_rng(11))
    jacobian[:, 2] = 2.0 * jacobian[:, 0]
    values = np.ones(3)
    gradient = np.array([2.0, 0.0, -1.0])
    assert not ident.prediction_uncertainty(residuals, jacobian, values, gradient).determined
    added = np.zeros((4, 3))
    added[:, 2] = [1.0, -0.5, 0.25, 2.0]
    got = ident.prediction_uncertainty(residuals, jacobian, values, gradient,
                                       added_jacobian=added)
    variance = residuals @ residuals / (len(residuals) - 2)
    expected = math.sqrt(variance * gradient @ np.linalg.inv(jacobian.T @ jacobian
                                                             + added.T @ added) @ gradient)
    assert got.determined and got.standard_error == pytest.approx(expected, rel=1e-9)
    assert (got.rank, got.residual_dof) == (3, len(residuals) - 2)
    table = ident.parameter_uncertainty(residuals, jacobian, ["a", "b", "c"], values,
                                        added_jacobian=added)
    assert table.identifiable.all() and (table["rank"] == 3).all()


def test_no_added_rows_or_zero_rows_change_nothing():
    """An empty (0, P) block is no trial: the same bits as none; rows of zeros (a trial that
    moves with no parameter) the same numbers to rounding (another SVD: 1e-12)."""
    residuals, jacobian, values = _linear_fit(np.random.default_rng(3))
    gradient = np.array([1.0, 0.5, -0.2])
    plain = ident.prediction_uncertainty(residuals, jacobian, values, gradient)
    empty = ident.prediction_uncertainty(residuals, jacobian, values, gradient,
                                         added_jacobian=np.zeros((0, 3)))
    zeros = ident.prediction_uncertainty(residuals, jacobian, values, gradient,
                                         added_jacobian=np.zeros((6, 3)))
    assert empty == plain
    assert zeros.standard_error == pytest.approx(plain.standard_error, rel=1e-12)
    assert (zeros.rank, zeros.residual_dof) == (plain.rank, plain.residual_dof)


@pytest.mark.parametrize("added, message", [
    (np.ones((2, 4)), r"added_jacobian must have shape \(A, 3\), one column per parameter, "
                      r"got \(2, 4\)"),
    (np.ones(3), r"added_jacobian must have shape \(A, 3\).*got \(3,\)"),
    (np.full((2, 3), np.inf), "^added_jacobian must be finite$")])
def test_added_rows_that_do_not_fit_the_parameters_are_refused(added, message):
    residuals, jacobian, values = _linear_fit(np.random.default_rng(2))
    with pytest.raises(ValueError, match=message):
        ident.prediction_uncertainty(residuals, jacobian, values, np.ones(3),
                                     added_jacobian=added)
    with pytest.raises(ValueError, match=message):
        ident.parameter_uncertainty(residuals, jacobian, ["a", "b", "c"], values,
                                    added_jacobian=added)


def test_trial_rows_are_the_cycle_curves_derivatives_over_sigma_and_the_sample_count():
    """The model path is linear in θ, so a central difference of its cycle curves (distances:
    smooth away from zero, which they are after each pulse's first sample) is their derivative
    to rounding and truncation of |Δp|'s curvature (step 1e-6: 1e-7); over σ·√(cycles ×
    samples) that is the rows, at any σ; and they are `trial_residuals`' curve rows at the
    trial's own σ, its last row (the direction residual's) aside."""
    theta = np.array([2.6, 0.8, 0.25])
    run, derivative = model_path(theta)
    sigma, step = 0.3, 1e-6
    columns = []
    for p in range(3):
        ends = [ident.cycle_curves(model_path(theta + sign * step * np.eye(3)[p])[0].path, 0.0,
                                   (1, 3), 32).ravel() for sign in (1.0, -1.0)]
        columns.append((ends[0] - ends[1]) / (2 * step))
    expected = np.stack(columns, axis=1) / (sigma * math.sqrt(3 * 32))
    rows = ident.trial_rows(run, derivative, sigma, (1, 3), 32)
    assert rows.shape == (3 * 32, 3)
    np.testing.assert_allclose(rows, expected, rtol=1e-7, atol=1e-9 * np.abs(expected).max())
    fit, _, jacobian = ident.trial_residuals(run, derivative, measured_trial(), (1, 3), 32)
    np.testing.assert_array_equal(ident.trial_rows(run, derivative, fit.sigma_mm, (1, 3), 32),
                                  jacobian[:-1])


@pytest.mark.parametrize("sigma", [0.0, -1.0, math.nan, math.inf, "1", True,
                                   np.nextafter(ident.DISPLACEMENT_FLOOR_MM, 0.0), 10**400])
def test_trial_rows_refuse_a_spread_below_the_tracking_floor_or_not_a_number(sigma):
    """A trial's spread is at least the floor `trial_fit` puts under a measured one (exactly
    the floor is allowed: ≥)."""
    run, derivative = model_path((2.6, 0.8, 0.25))
    with pytest.raises(ValueError, match=r"sigma_mm must be a finite number of mm >= "
                                         r"DISPLACEMENT_FLOOR_MM = 0\.05 \(the tracking noise"):
        ident.trial_rows(run, derivative, sigma)
    assert ident.trial_rows(run, derivative, ident.DISPLACEMENT_FLOOR_MM).shape == (3 * 64, 3)


def _with_candidates():
    """`_gaits_and_trials` and two unmeasured gaits: A2 (the model path, blind to d) and A4
    (the path backwards, its surge a + d: it sees d as A1+A3 does)."""
    runs, derivatives, trials = _gaits_and_trials()
    for gait, sign in (("A2", 1.0), ("A4", -1.0)):
        run, derivative = model_path((2.6, 0.8, 0.25), sign)
        runs[gait] = dataclasses.replace(run, gait=gait)
        d_column = derivative[:, :, :1] if gait == "A4" else np.zeros_like(derivative[:, :, :1])
        derivatives[gait] = np.concatenate([derivative, d_column], axis=-1)
    return runs, derivatives, trials, np.array([2.6, 0.8, 0.25, 1.0])


def test_an_added_trial_lets_the_fits_determine_what_only_it_and_the_held_out_gait_see():
    """Only A1+A3 moves with d among the measured gaits: held out, its speed is undetermined;
    with A4's trial added (it sees d too) it is determined, with the normal equations' error of
    the other two gaits' Jacobian and A4's rows (`trial_rows` at the measured trials' median σ,
    over √2 as the fit of two gaits weighs each), the fit's own s². A2 added (blind to d)
    leaves it undetermined. The added gait's row says "added"; the other stays "unmeasured"."""
    runs, derivatives, trials, values = _with_candidates()
    plain = ident.gait_predictions(runs, derivatives, trials, values, (1, 3))
    with_a4 = ident.gait_predictions(runs, derivatives, trials, values, (1, 3), added=("A4",))
    with_a2 = ident.gait_predictions(runs, derivatives, trials, values, (1, 3), added=["A2"])

    def row(table, gait, role):
        return table[(table.gait == gait) & (table.role == role)].iloc[0]

    assert not row(plain, "A1+A3", "held_out").determined
    assert not row(with_a2, "A1+A3", "held_out").determined
    held = row(with_a4, "A1+A3", "held_out")
    assert held.determined and held["rank"] == 4
    sigma = float(np.median(ident.trajectory_objective(
        {g: runs[g] for g in trials}, trials, (1, 3))["sigma_mm"]))
    training = {g: runs[g] for g in ("A1", "A1+A2")}
    residuals, jacobian, _ = ident.objective_residuals(
        training, derivatives, {g: trials[g] for g in training}, (1, 3))
    added = ident.trial_rows(runs["A4"], derivatives["A4"], sigma, (1, 3)) / math.sqrt(2)
    _, gradient = ident.window_speed(runs["A1+A3"], derivatives["A1+A3"], (1, 3))
    scaled, relative = gradient * values, np.vstack([jacobian, added]) * values
    variance = residuals @ residuals / (len(residuals) - 3)      # the two gaits' rank: 3
    expected = math.sqrt(variance * scaled @ np.linalg.inv(relative.T @ relative) @ scaled)
    assert held.standard_error_mm_s == pytest.approx(expected, rel=1e-8)
    assert held.residual_dof == len(residuals) - 3
    assert list(with_a4.role[with_a4.gait.isin(["A2", "A4"])]) == ["unmeasured", "added"]
    # the predictions themselves do not move: only what determines them
    np.testing.assert_array_equal(with_a4.predicted_speed_mm_s, plain.predicted_speed_mm_s)
    np.testing.assert_array_equal(with_a4.training_objective, plain.training_objective)
    # a smaller expected spread weighs the trial more: the error shrinks
    tight = ident.gait_predictions(runs, derivatives, trials, values, (1, 3), added=("A4",),
                                   added_sigma_mm=sigma / 2)
    assert row(tight, "A1+A3", "held_out").standard_error_mm_s < held.standard_error_mm_s


@pytest.mark.parametrize("added, sigma, message", [
    (("A1",), None, r"added: gait 'A1' is measured: its trial is in the fits already"),
    (("A3",), None, r"added: gait 'A3' has no simulated run \(missing, or None: failed\)"),
    (("A5",), None, r"added: gait 'A5' has no simulated run \(missing, or None: failed\)"),
    (("A4", "A4"), None, "added: gaits repeat: A4, A4"),
    ("A4", None, "added must be a sequence of gait names, not the string 'A4'"),
    (("A4",), 0.0, r"added_sigma_mm must be a finite number of mm >= DISPLACEMENT_FLOOR_MM .*"),
    ((), -1.0, r"added_sigma_mm must be a finite number of mm >= .*got -1\.0")])
def test_gait_predictions_refuse_an_added_trial_they_cannot_take(added, sigma, message):
    """Refused naming the argument, a failed run (None, as `result_runs` gives it) as a
    missing one, and a bad spread even with no trial added."""
    runs, derivatives, trials, values = _with_candidates()
    runs["A5"] = None
    with pytest.raises(ValueError, match=f"^{message}$"):
        ident.gait_predictions(runs, derivatives, trials, values, (1, 3), added=added,
                               added_sigma_mm=sigma)


def test_trial_design_stacks_nothing_added_each_candidate_and_all_of_them():
    """The sets in order: none, A2, A4, both; each set's rows are `gait_predictions`' with it
    added, at one σ: the measured trials' median unless given; none added has no σ and is
    named "none" (an empty cell would read back from a CSV as missing)."""
    runs, derivatives, trials, values = _with_candidates()
    design = ident.trial_design(runs, derivatives, trials, values, ["A2", "A4"], (1, 3))
    assert list(design.columns) == ident.DESIGN_COLUMNS
    assert list(dict.fromkeys(design.added_trials)) == ["none", "A2", "A4", "A2 A4"]
    sigma = float(np.median(ident.trajectory_objective(
        {g: runs[g] for g in trials}, trials, (1, 3))["sigma_mm"]))
    assert design.added_sigma_mm[design.added_trials == "none"].isna().all()
    assert (design.added_sigma_mm[design.added_trials != "none"] == sigma).all()
    comparisons = ["z_score", "within_two_standard_errors"]
    for text in ("none", "A2", "A4", "A2 A4"):
        part = design[design.added_trials == text].drop(columns=["added_trials",
                                                                 "added_sigma_mm"])
        added = () if text == "none" else tuple(text.split())
        expected = ident.gait_predictions(runs, derivatives, trials, values, (1, 3),
                                          added=added)
        if added:  # the point is not refitted to trials not made: no comparison with them
            assert part.z_score.isna().all() and part.within_two_standard_errors.isna().all()
            part, expected = part.drop(columns=comparisons), expected.drop(columns=comparisons)
        else:
            assert part.within_two_standard_errors.iloc[:6].notna().all()
        pd.testing.assert_frame_equal(part.reset_index(drop=True), expected)
    given = ident.trial_design(runs, derivatives, trials, values, ["A4"], (1, 3),
                               added_sigma_mm=0.5)
    assert list(dict.fromkeys(given.added_trials)) == ["none", "A4"]  # one candidate: no "all"
    assert (given.added_sigma_mm[given.added_trials == "A4"] == 0.5).all()
    with pytest.raises(ValueError, match="candidates must be a sequence of gait names"):
        ident.trial_design(runs, derivatives, trials, values, "A4", (1, 3))


def test_trial_design_of_at_most_k_trials_takes_the_smaller_sets_first(monkeypatch):
    """Three candidates: max_trials 3 (or more) gives the 2³ − 1 = 7 subsets after none,
    singles, then pairs, then all three, in the candidates' order; max_trials 2 stops at the
    pairs; a set's rows equal `gait_predictions`' with it added. A count that is not a whole
    number >= 1 is refused naming max_trials, and so is one asking for more sets than
    MAX_DESIGN_SETS (at exactly it, allowed: ≤)."""
    runs, derivatives, trials, values = _with_candidates()
    run, derivative = model_path((2.6, 0.8, 0.25))
    runs["A5"] = dataclasses.replace(run, gait="A5")
    derivatives["A5"] = np.concatenate([derivative, np.zeros_like(derivative[:, :, :1])], -1)
    candidates = ["A2", "A4", "A5"]
    every = ["none", "A2", "A4", "A5", "A2 A4", "A2 A5", "A4 A5", "A2 A4 A5"]
    for k, expected in ((3, every), (5, every), (2, every[:-1]), (1, every[:4])):
        design = ident.trial_design(runs, derivatives, trials, values, candidates, (1, 3),
                                    max_trials=k)
        assert list(dict.fromkeys(design.added_trials)) == expected
    comparisons = ["z_score", "within_two_standard_errors"]
    design = ident.trial_design(runs, derivatives, trials, values, candidates, (1, 3),
                                max_trials=np.int64(3))
    part = design[design.added_trials == "A4 A5"].drop(columns=["added_trials",
                                                                "added_sigma_mm"])
    pd.testing.assert_frame_equal(part.drop(columns=comparisons).reset_index(drop=True),
                                  ident.gait_predictions(runs, derivatives, trials, values,
                                                         (1, 3), added=("A4", "A5"))
                                  .drop(columns=comparisons))
    for bad in (0, -1, 1.5, True, "2"):
        with pytest.raises(ValueError, match=r"max_trials must be a whole number >= 1 \(None: "
                                             r"each candidate alone and all together\), got"):
            ident.trial_design(runs, derivatives, trials, values, candidates, (1, 3),
                               max_trials=bad)
    monkeypatch.setattr(ident, "MAX_DESIGN_SETS", 6)
    at = ident.trial_design(runs, derivatives, trials, values, candidates, (1, 3), max_trials=2)
    assert at.added_trials.nunique() == 7          # none and the 6 sets
    with pytest.raises(ValueError, match="max_trials 3 over 3 candidates asks for 7 sets of "
                                         "trials, more than MAX_DESIGN_SETS = 6"):
        ident.parameter_design(runs, derivatives, trials, ["a", "b", "c", "d"], values,
                               candidates, (1, 3), max_trials=3)


def test_parameter_design_says_which_parameters_a_trial_would_determine():
    """Measured A1 and A1+A2 leave d free (neither moves with it): not identifiable with
    nothing added, nor with A2's trial (blind to d); with A4's (it sees d) every parameter is,
    with the normal equations' errors of J and A4's rows over √2 and the fit's own s². With
    nothing added the rows are `parameter_uncertainty`'s of the fit, the same bits."""
    runs, derivatives, trials, values = _with_candidates()
    trials = {g: trials[g] for g in ("A1", "A1+A2")}
    names = ["a", "b", "c", "d"]
    design = ident.parameter_design(runs, derivatives, trials, names, values, ["A2", "A4"],
                                    (1, 3))
    assert list(design.columns) == ident.DESIGN_COLUMNS[:2] + ident.UNCERTAINTY_COLUMNS
    assert list(dict.fromkeys(design.added_trials)) == ["none", "A2", "A4", "A2 A4"]
    residuals, jacobian, table = ident.objective_residuals(
        {g: runs[g] for g in trials}, derivatives, trials, (1, 3))
    plain = design[design.added_trials == "none"].drop(columns=["added_trials",
                                                                "added_sigma_mm"])
    pd.testing.assert_frame_equal(plain.reset_index(drop=True), ident.parameter_uncertainty(
        residuals, jacobian, names, values))

    def identifiable(text):
        return design.identifiable[design.added_trials == text].tolist()

    assert identifiable("none") == identifiable("A2") == [True, True, True, False]
    assert identifiable("A4") == identifiable("A2 A4") == [True] * 4
    sigma = float(np.median(table["sigma_mm"]))
    assert (design.added_sigma_mm[design.added_trials != "none"] == sigma).all()
    added = ident.trial_rows(runs["A4"], derivatives["A4"], sigma, (1, 3)) / math.sqrt(2)
    relative = np.vstack([jacobian, added]) * values
    variance = residuals @ residuals / (len(residuals) - 3)
    errors = np.sqrt(variance * np.diag(np.linalg.inv(relative.T @ relative))) * values
    np.testing.assert_allclose(design.standard_error[design.added_trials == "A4"], errors,
                               rtol=1e-8)
    with pytest.raises(ValueError, match="candidates: gait 'A1' is measured"):
        ident.parameter_design(runs, derivatives, trials, names, values, ["A1"], (1, 3))
    with pytest.raises(ValueError, match="candidates must be a sequence of gait names"):
        ident.parameter_design(runs, derivatives, trials, names, values, "A4", (1, 3))
    with pytest.raises(ValueError, match=r"^no simulated run for the measured gait\(s\) A1\+A2$"):
        ident.parameter_design({g: runs[g] for g in ("A1", "A4")}, derivatives, trials, names,
                               values, ["A4"], (1, 3))


def test_heavy_added_rows_never_lower_the_rank():
    """The cut between resolved and not stays rcond × the fit's own largest singular value: rows
    10⁶ × heavier than J along its first column (whose largest singular value they then
    dominate) leave its weakest direction (10⁻³ of the largest) resolved, and a prediction
    along it no less determined than without them (the rows do not see it: the same error to
    rounding)."""
    rng = np.random.default_rng(5)
    jacobian = rng.normal(size=(30, 3)) * np.array([1.0, 1e-3, 1.0])
    residuals = rng.normal(size=30)
    heavy = np.zeros((4, 3))
    heavy[:, 0] = 1e6
    plain = ident.prediction_uncertainty(residuals, jacobian, np.ones(3), [0.0, 1.0, 0.0])
    with_rows = ident.prediction_uncertainty(residuals, jacobian, np.ones(3), [0.0, 1.0, 0.0],
                                             added_jacobian=heavy)
    assert plain.rank == with_rows.rank == 3 and with_rows.determined
    assert with_rows.standard_error <= plain.standard_error * (1 + 1e-9)
    table = ident.parameter_uncertainty(residuals, jacobian, ["a", "b", "c"], np.ones(3),
                                        added_jacobian=heavy)
    assert table.identifiable.all() and (table["rank"] == 3).all()


def test_the_default_spread_of_a_trial_is_the_median_of_the_measured_ones():
    """Trials whose measured paths are scaled by 1, 2 and 4 have spreads about σ, 2σ and 4σ
    (each phase is fitted again): a trial taken as made gets the middle one (the median, not
    the mean nor the largest), in trial_design and parameter_design alike, and
    gait_predictions' rows with it equal those given it."""
    runs, derivatives, trials, values = _with_candidates()
    for gait, factor in (("A1+A2", 2.0), ("A1+A3", 4.0)):
        path = trials[gait].path
        trials[gait] = dataclasses.replace(trials[gait], path=ident.CentroidPath(
            path.t_s, path.x_mm * factor, path.y_mm * factor, path.period_s))
    sigmas = ident.trajectory_objective({g: runs[g] for g in trials}, trials, (1, 3))["sigma_mm"]
    low, middle, high = sorted(sigmas)
    assert middle > 1.5 * low and high > 1.5 * middle and middle < 0.9 * np.mean(sigmas)
    design = ident.trial_design(runs, derivatives, trials, values, ["A4"], (1, 3))
    parameters = ident.parameter_design(runs, derivatives, trials, list("abcd"), values, ["A4"],
                                        (1, 3))
    median = middle
    assert (design.added_sigma_mm[design.added_trials == "A4"] == median).all()
    assert (parameters.added_sigma_mm[parameters.added_trials == "A4"] == median).all()
    given = ident.gait_predictions(runs, derivatives, trials, values, (1, 3), added=("A4",),
                                   added_sigma_mm=median)
    np.testing.assert_array_equal(
        design.standard_error_mm_s[design.added_trials == "A4"], given.standard_error_mm_s)


def test_a_design_checks_its_candidates_before_any_fit_and_takes_none():
    """A measured, missing or repeated candidate is refused naming candidates; no candidate
    gives the rows with nothing added alone."""
    runs, derivatives, trials, values = _with_candidates()
    for candidates, message in ((["A4", "A1"], "candidates: gait 'A1' is measured"),
                                (["A9"], "candidates: gait 'A9' has no simulated run"),
                                (["A4", "A4"], "candidates: gaits repeat: A4, A4")):
        with pytest.raises(ValueError, match=message):
            ident.trial_design(runs, derivatives, trials, values, candidates, (1, 3))
    empty = ident.trial_design(runs, derivatives, trials, values, [], (1, 3))
    assert set(empty.added_trials) == {"none"} and empty.added_sigma_mm.isna().all()
    pd.testing.assert_frame_equal(
        empty.drop(columns=["added_trials", "added_sigma_mm"]),
        ident.gait_predictions(runs, derivatives, trials, values, (1, 3)))


def test_rows_added_to_a_fit_that_sees_nothing_resolve_only_what_they_see():
    """J = 0 (the measured data move with no parameter): the cut is 0, and rows that see the
    first parameter alone resolve it (a finite error, s² the fit's own over all R degrees of
    freedom) and nothing else (the second stays undetermined: its singular value 0 is not
    above the cut of 0)."""
    residuals = np.arange(1.0, 7.0)
    jacobian = np.zeros((6, 2))
    added = np.array([[2.0, 0.0], [1.0, 0.0]])
    first = ident.prediction_uncertainty(residuals, jacobian, [1.0, 1.0], [1.0, 0.0],
                                         added_jacobian=added)
    assert first.determined and (first.rank, first.residual_dof) == (1, 6)
    assert first.standard_error == pytest.approx(math.sqrt(91.0 / 6 / 5.0), rel=1e-12)
    second = ident.prediction_uncertainty(residuals, jacobian, [1.0, 1.0], [0.0, 1.0],
                                          added_jacobian=added)
    assert not second.determined and second.unresolved_share == pytest.approx(1.0, rel=1e-12)


def test_a_design_passes_its_window_samples_and_spread_on_and_numbers_its_rows():
    """trial_design with a later prediction window and 32 samples a cycle gives, per set, the
    rows of gait_predictions with the same arguments; parameter_design with 32 samples those
    of parameter_uncertainty on objective_residuals with 32 (and A4's trial_rows with 32), no
    spread for nothing added; both tables are numbered 0..n−1 (one index, not one per set);
    a bad spread is refused by parameter_design too, naming added_sigma_mm."""
    runs, derivatives, trials, values = _with_candidates()
    names = list("abcd")
    design = ident.trial_design(runs, derivatives, trials, values, ["A4"], (1, 1), samples=32,
                                predict_cycles=(2, 3))
    assert design.index.tolist() == list(range(len(design)))
    comparisons = ["z_score", "within_two_standard_errors"]
    for added in ((), ("A4",)):
        part = design[design.added_trials == (" ".join(added) or "none")]
        expected = ident.gait_predictions(runs, derivatives, trials, values, (1, 1),
                                          samples=32, predict_cycles=(2, 3), added=added)
        part = part.drop(columns=["added_trials", "added_sigma_mm"]).reset_index(drop=True)
        if added:
            part, expected = part.drop(columns=comparisons), expected.drop(columns=comparisons)
        pd.testing.assert_frame_equal(part, expected)
    assert (design.first_cycle == 2).all()
    parameters = ident.parameter_design(runs, derivatives, trials, names, values, ["A4"],
                                        (1, 3), samples=32)
    assert parameters.index.tolist() == list(range(len(parameters)))
    assert parameters.added_sigma_mm[parameters.added_trials == "none"].isna().all()
    residuals, jacobian, table = ident.objective_residuals(
        {g: runs[g] for g in trials}, derivatives, trials, (1, 3), 32)
    plain = parameters[parameters.added_trials == "none"].drop(
        columns=["added_trials", "added_sigma_mm"]).reset_index(drop=True)
    pd.testing.assert_frame_equal(plain, ident.parameter_uncertainty(residuals, jacobian, names,
                                                                     values))
    rows = ident.trial_rows(runs["A4"], derivatives["A4"], float(np.median(table.sigma_mm)),
                            (1, 3), 32) / math.sqrt(3)
    with_a4 = parameters[parameters.added_trials == "A4"].drop(
        columns=["added_trials", "added_sigma_mm"]).reset_index(drop=True)
    pd.testing.assert_frame_equal(with_a4, ident.parameter_uncertainty(
        residuals, jacobian, names, values, added_jacobian=rows))
    with pytest.raises(ValueError, match="^added_sigma_mm must be a finite number of mm >= "):
        ident.parameter_design(runs, derivatives, trials, names, values, ["A4"], (1, 3),
                               added_sigma_mm=0.01)
    given = ident.parameter_design(runs, derivatives, trials, names, values, ["A4"], (1, 3),
                                   samples=32, added_sigma_mm=0.5)
    assert (given.added_sigma_mm[given.added_trials == "A4"] == 0.5).all()
    rows = ident.trial_rows(runs["A4"], derivatives["A4"], 0.5, (1, 3), 32) / math.sqrt(3)
    np.testing.assert_array_equal(
        given.standard_error[given.added_trials == "A4"],
        ident.parameter_uncertainty(residuals, jacobian, names, values,
                                    added_jacobian=rows).standard_error)


def test_design_summary_counts_what_each_set_determines_of_the_held_out_gaits():
    """From a design of A2 and A4 on the synthetic gaits: with nothing or A2 added, A1+A3 held
    out is undetermined (only it and A4 see d), with A4 or both every held-out gait is
    determined; the widest error is the largest of the determined held-out rows; a failed
    gait's row (no numbers) counts for nothing; a table that is not a design is refused."""
    runs, derivatives, trials, values = _with_candidates()
    design = ident.trial_design(runs, derivatives, trials, values, ["A2", "A4"], (1, 3))
    summary = ident.design_summary(design)
    assert list(summary.columns) == ident.DESIGN_SUMMARY_COLUMNS
    assert summary.added_trials.tolist() == ["none", "A2", "A4", "A2 A4"]
    assert summary.trials.tolist() == [0, 1, 1, 2]
    assert summary.held_out_determined.tolist() == [2, 2, 3, 3]
    assert summary.held_out_undetermined.tolist() == ["A1+A3", "A1+A3", "none", "none"]
    assert summary.every_held_out_determined.tolist() == [False, False, True, True]
    for row in summary.itertuples():
        held = design[(design.added_trials == row.added_trials) & (design.role == "held_out")
                      & design.determined]
        assert row.widest_held_out_standard_error_mm_s == held.standard_error_mm_s.max()
    failed = pd.concat([design, pd.DataFrame([{"added_trials": "none", "gait": "A1+A4",
                                                "role": "held_out", "determined": False}])],
                       ignore_index=True)
    pd.testing.assert_frame_equal(ident.design_summary(failed), summary)
    with pytest.raises(ValueError, match="design must be a trial_design table; it lacks "
                                         "added_trials, added_sigma_mm"):
        ident.design_summary(design.drop(columns=["added_trials", "added_sigma_mm"]))


def test_design_summary_joins_the_undetermined_and_has_no_widest_error_when_none_is():
    """A hand-made design: a set that leaves two held-out gaits undetermined names both,
    joined by a space in their table order, and its widest error is NaN (none determined)."""
    rows = [{"added_trials": "none", "gait": gait, "role": "held_out", "determined": False,
             "predicted_speed_mm_s": 1.0, "standard_error_mm_s": math.inf}
            for gait in ("A1+A2", "A1+A4")]
    design = pd.DataFrame(rows).reindex(columns=ident.DESIGN_COLUMNS)
    summary = ident.design_summary(design)
    assert summary.held_out_undetermined.tolist() == ["A1+A2 A1+A4"]
    assert summary.held_out_determined.tolist() == [0]
    assert math.isnan(summary.widest_held_out_standard_error_mm_s[0])


def test_rows_added_to_a_fit_of_zeros_resolve_no_rounding_noise():
    """J = 0 and a rank-1 block of rows (an outer product, whose SVD leaves ~1e-16 rounding on
    the two directions it cannot see): only the direction it sees is resolved (rank 1, above
    the stacked matrix's rounding), a prediction along another is undetermined."""
    residuals = np.arange(1.0, 9.0)
    added = np.outer([1.0, 2.0, 3.0, 0.5], [0.3, 0.7, 1.1])
    along = ident.prediction_uncertainty(residuals, np.zeros((8, 3)), np.ones(3),
                                         [0.3, 0.7, 1.1], added_jacobian=added)
    across = ident.prediction_uncertainty(residuals, np.zeros((8, 3)), np.ones(3),
                                          [0.7, -0.3, 0.0], added_jacobian=added)
    assert along.rank == across.rank == 1
    assert along.determined and not across.determined


def test_design_set_count_is_the_number_of_sets_a_design_scores():
    """Each alone and all: n + 1 (n ≥ 2), 1 for one, 0 for none; at most k: Σ C(n, i) for
    i ≤ k, k beyond n the 2ⁿ − 1 subsets; the study's boundary: 11 candidates, at most 5 =
    1,023 sets (≤ 1,024 allowed), at most 6 = 1,485."""
    assert [ident.design_set_count(n) for n in (0, 1, 2, 4)] == [0, 1, 3, 5]
    assert ident.design_set_count(4, 2) == 4 + 6 and ident.design_set_count(4, 9) == 15
    assert ident.design_set_count(11, 5) == 1023 <= ident.MAX_DESIGN_SETS
    assert ident.design_set_count(11, 6) == 1485
    with pytest.raises(ValueError, match="max_trials must be a whole number >= 1"):
        ident.design_set_count(4, 0)
