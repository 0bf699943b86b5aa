"""The whole-run reference of the sensitivity checks: `extrapolated_difference` on analytic
difference quotients, the steps, and `check_sensitivities` on fake runs (the statuses of the runs
behind each row, the absolute error, the work it counts)."""

import warnings
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from taichi_star import SolverConfig, StarParams, sensitivity_check
from taichi_star.sensitivities import parse_directions
from taichi_star.sensitivity_check import (check_sensitivities, difference_step,
                                           extrapolated_difference, instance_runs)


@pytest.mark.parametrize("first, second", [(0.0, 0.0), (3.0, 0.0), (0.0, -9.4e3), (2.5, 7.0)])
def test_terms_of_first_and_second_order_in_the_step_are_removed(first, second):
    """D(h) = D + a·h + b·h² gives D back (to rounding: the quotients are ~16 and the weights
    8/3, −2, 1/3, so 1e-14 relative), whatever a and b; the former 2·D(h) − D(2h) keeps −2·b·h²."""
    derivative, h = 16.25599, 1e-4

    def quotient(step):
        return derivative + first * step + second * step ** 2

    value = extrapolated_difference(quotient(h), quotient(2 * h), quotient(4 * h))
    assert value == pytest.approx(derivative, rel=1e-14, abs=0)
    former = 2 * quotient(h) - quotient(2 * h)
    assert former - derivative == pytest.approx(-2 * second * h ** 2, rel=1e-6, abs=1e-14)


def test_a_third_order_term_is_left_as_eight_times_its_value_at_h():
    """c·h³ in D(h) leaves (8·1 − 6·8 + 64)/3 = 8 times c·h³: the O(h³) remainder the docs
    quote for long runs of the joint radius. Arrays of quotients work element by element."""
    h, c = np.array([1e-4, 2e-4]), np.array([5.0, -3.0])
    quotients = [c * (m * h) ** 3 for m in (1.0, 2.0, 4.0)]
    np.testing.assert_allclose(extrapolated_difference(*quotients), 8 * c * h ** 3, rtol=1e-12)


@pytest.mark.parametrize("field, own, at_zero", [
    # ε relative to the value (FIELD_RELATIVE_STEPS): 1e-3 for τ, 1e-4 for α, 1e-2 for C∥, so
    # 2e-5 and 2e-4 at 0.02, and for α, the jet linear in α², that of its usual scale, 0.1
    # (LINEAR_FIELDS: its ε at 0, below its default 0.8), 1e-5 (2e-6 until 2026-12); at 0,
    # 10 · RELATIVE_STEP (1e-4) · ZERO_VALUE_SCALE (0.01) · the top of the field's range: τ's
    # 1.0 s, α's 10, C∥'s 100
    ("damping_time", 2e-5, 1e-5),
    ("alpha", 1e-5, 1e-4),
    ("drag_parallel", 2e-4, 1e-3),
])
def test_the_difference_step_is_the_fields_own_but_at_zero_ten_default_steps(field, own,
                                                                           at_zero):
    """Off zero h is the sensitivities' ε of the field; at 0 ten times the default ε there
    (for α and C∥ ten and a tenth of their own ε at 0: 1e-5 and 1e-2; for τ, whose own ε is
    ten default ones, its own). rel 1e-12: the steps are products of three or four decimal
    factors, each rounded once."""
    (direction,) = parse_directions([field])
    moved = StarParams.preset("paper").replace(**{field: 0.02})
    assert difference_step(direction, moved) == pytest.approx(own, rel=1e-12)
    zero = StarParams.preset("paper").replace(**{field: 0.0})
    assert difference_step(direction, zero) == pytest.approx(at_zero, rel=1e-12)


def test_a_delay_at_zero_steps_by_ten_default_steps_of_the_period():
    """A delay's range is the period (3.15 s in the paper preset): at 0, h = 10 · 1e-4 · 0.01 ·
    3.15 s = 3.15e-5 s (rel 1e-12: products of decimal factors, each rounded once)."""
    (direction,) = parse_directions(["actuator_delays[0]"])
    paper = StarParams.preset("paper")
    assert paper.period == 3.15 and paper.actuator_delays[0] == 0.0
    assert difference_step(direction, paper) == pytest.approx(3.15e-5, rel=1e-12)


SLOPE = 2.5
"""d(output)/dα of the fake runs: their output is SLOPE·α, and α's sensitivity is SLOPE."""
WRONG_GAIN_SENSITIVITY = 0.5
"""The fake sensitivity by A8's gain, which the output does not depend on: a wrong one."""
BASE_ALPHA = 0.8
"""α of the paper preset, whose differences' h is 8e-5 and Taylor step H 8e-3."""


def fake_simulate(calls):
    """A stand-in for `simulate`, recording each call's keyword arguments in `calls`: output
    SLOPE·α, whatever the gains; A1+A3's runs fail (its centre run first, at 0.005 s, by
    step_limit; every moved run at 0.03 s), A1+A2's run at −4h (α below 0.8 − 3·10⁻⁴, between
    −2h and −4h for α's h = 8·10⁻⁵) at 0.01 s and
    its Taylor run at +2H (α above 0.81) at 0.02 s, A1's none. A failed run's output is NaN,
    as `simulate` gives a failed instance's metrics."""
    def outcome(p, centre):
        if p.gait == "A1+A3":
            return ("step_limit", 0.005) if centre else ("non_finite", 0.03)
        if p.gait == "A1+A2" and p.alpha < BASE_ALPHA - 3e-4:
            return "newton_failed", 0.01
        if p.gait == "A1+A2" and p.alpha > 0.81:
            return "non_finite", 0.02
        return "ok", np.nan

    def simulate(params, duration_s, solver, arch="cpu", **options):
        calls.append(options)
        centre = bool(options.get("sensitivities"))
        status, failure = zip(*(outcome(p, centre) for p in params))
        summary = pd.DataFrame({
            "displacement_x_mm": [SLOPE * p.alpha if s == "ok" else np.nan
                                  for p, s in zip(params, status)],
            "status": status, "failure_time_s": failure})
        derivative = {"alpha": SLOPE, "actuator_gains[7]": WRONG_GAIN_SENSITIVITY}
        return SimpleNamespace(summary=summary, sensitivity=lambda output, label: np.full(
            len(params), derivative[label]))
    return simulate


GAITS = ("A1", "A1+A2", "A1+A3")


def fake_check(monkeypatch, **options):
    """(check_sensitivities' table for alpha and A8's gain on GAITS with the fake runs, the
    warnings it gave, the keyword arguments of its simulate calls)."""
    calls = []
    monkeypatch.setattr(sensitivity_check, "simulate", fake_simulate(calls))
    params = [StarParams.preset("paper", gait=gait) for gait in GAITS]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        table = check_sensitivities(params, 0.02, SolverConfig(), ["alpha", "actuator_gains[7]"],
                                    **options)
    return table, [str(w.message) for w in caught], calls


def test_every_row_keeps_the_status_of_its_first_failed_run_and_one_warning_names_them(
        monkeypatch):
    """The centre run's failure comes first, then the moved runs' (−4h before the Taylor
    run's +2H); rows whose runs failed are kept, NaN, not dropped, and one warning counts and
    names them."""
    table, told, _ = fake_check(monkeypatch)
    assert len(table) == 6
    by_row = table.set_index(["gait", "parameter"])
    expected = {("A1", "alpha"): ("ok", np.nan),
                ("A1+A2", "alpha"): ("newton_failed", 0.01),
                ("A1+A3", "alpha"): ("step_limit", 0.005),
                ("A1", "actuator_gains[7]"): ("ok", np.nan),
                ("A1+A2", "actuator_gains[7]"): ("ok", np.nan),
                ("A1+A3", "actuator_gains[7]"): ("step_limit", 0.005)}
    for row, (status, failure) in expected.items():
        assert by_row.loc[row, "status"] == status, row
        np.testing.assert_equal(by_row.loc[row, "failure_time_s"], failure)
    assert np.isnan(by_row.loc[("A1+A2", "alpha"), "relative_error"])
    assert told == ["check_sensitivities: 3 of 6 rows rest on a run that did not finish ok, "
                    "their differences unusable (columns status, failure_time_s): A1+A2 alpha "
                    "(newton_failed at 0.01 s); A1+A3 alpha (step_limit at 0.005 s); A1+A3 "
                    "actuator_gains[7] (step_limit at 0.005 s)"]


def test_a_nonzero_sensitivity_where_the_differences_are_exactly_zero_shows_in_its_error(
        monkeypatch):
    """A8's gain moves nothing (differences exactly 0: relative error inf, the spread NaN, so
    the study's filters on them left the row out): its absolute error is the wrong
    sensitivity itself; α's, |SLOPE − difference|, is rounding (1e-9: the difference quotients
    of SLOPE·α at h = 8e-5 lose ~1e-16/8e-5 of SLOPE each)."""
    table, _, _ = fake_check(monkeypatch)
    gain = table[(table["parameter"] == "actuator_gains[7]") & (table["status"] == "ok")]
    assert len(gain) == 2 and (gain["difference"] == 0.0).all()
    assert np.isinf(gain["relative_error"]).all() and gain["difference_spread"].isna().all()
    np.testing.assert_array_equal(gain["absolute_error"], WRONG_GAIN_SENSITIVITY)
    (alpha,) = table.loc[(table["parameter"] == "alpha") & (table["gait"] == "A1"),
                         "absolute_error"]
    assert alpha < 1e-9


@pytest.mark.parametrize("progress", [False, True, None])
def test_progress_reaches_every_simulate_call(monkeypatch, progress):
    _, _, calls = fake_check(monkeypatch, progress=progress)
    assert [call["progress"] for call in calls] == [progress] * 3


def test_the_instance_runs_count_the_replicas_the_moved_and_the_taylor_runs():
    """Per instance: itself, two replicas per direction, six moved runs and two Taylor runs
    per direction: 1 + 10·D. The study's default, 2 gaits × (8 settings × 40 parameters + 1 ×
    3 heights), is 6,478."""
    assert instance_runs(1, 0) == 1
    assert instance_runs(3, 2) == 3 * 21
    assert 8 * instance_runs(2, 40) + instance_runs(2, 3) == 6478


def _failed_table(count):
    return pd.DataFrame({"gait": [f"A{k + 1}" for k in range(count)], "parameter": "alpha",
                         "status": "non_finite", "failure_time_s": 0.01})


@pytest.mark.parametrize("count, tail", [(5, "A5 alpha (non_finite at 0.01 s)"),
                                         (6, "A5 alpha (non_finite at 0.01 s); and 1 more")])
def test_the_failed_rows_warning_names_five_and_counts_the_rest(count, tail):
    """At most FAILED_ROWS_NAMED (5) rows named, "and N more" only where N > 0."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sensitivity_check.warn_failed_rows(_failed_table(count))
    (message,) = [str(w.message) for w in caught]
    assert message.endswith(tail), message
    assert "A6 alpha" not in message


def test_the_spread_is_that_of_the_smallest_steps_difference(monkeypatch):
    """For an output α³ the central differences are 3α² + (kh)², so the spread
    |D(h) − D|/|D| is h²/(3α²) (that of D(2h) would be four times it)."""

    def simulate(params, duration_s, solver, arch="cpu", **options):
        summary = pd.DataFrame({"displacement_x_mm": [p.alpha ** 3 for p in params],
                                "status": "ok", "failure_time_s": np.nan})
        return SimpleNamespace(summary=summary, sensitivity=lambda output, label: np.array(
            [3 * p.alpha ** 2 for p in params]))

    monkeypatch.setattr(sensitivity_check, "simulate", simulate)
    params = [StarParams.preset("paper", gait="A1")]
    table = sensitivity_check.check_sensitivities(params, 0.02, SolverConfig(), ["alpha"])
    alpha = params[0].alpha
    h = sensitivity_check.difference_step(sensitivity_check.parse_directions(["alpha"])[0],
                                          params[0])
    assert table["difference_spread"].iloc[0] == pytest.approx(h ** 2 / (3 * alpha ** 2),
                                                               rel=1e-3)


def test_a_minus_4h_run_exactly_on_the_lowest_delay_is_central():
    """one_sided's boundary: a delay whose −4h run lands exactly on 0 (allowed) is still
    differenced centrally; a hair below, forward. (A stand-in direction with h = 1.)"""
    on = SimpleNamespace(field="actuator_delays", value=lambda p: 4.0, step=lambda p: 1.0)
    below = SimpleNamespace(field="actuator_delays", value=lambda p: float(np.nextafter(4.0, 0.0)),
               step=lambda p: 1.0)
    assert sensitivity_check.one_sided(on, None) is False
    assert sensitivity_check.one_sided(below, None) is True


def test_the_taylor_step_stays_outward_where_neither_side_is_allowed():
    """`inward` turns the step only where +2·step leaves the range and −2·step does not;
    where both leave it, the step is kept as it is."""
    nowhere = SimpleNamespace(value=lambda p: 1.0, allowed=lambda p, v: False)
    assert sensitivity_check.inward(nowhere, None, 0.05) == 0.05
    below_only = SimpleNamespace(value=lambda p: 1.0, allowed=lambda p, v: v < 1.0)
    assert sensitivity_check.inward(below_only, None, 0.05) == -0.05
