"""The time grid: which times are whole steps, and the record intervals it offers.

Exact checks: the intervals are compared with the integer multiples of dt they must be, and the
tolerance cases sit far inside and far outside STEP_TOLERANCE (1e-9 relative)."""

import numpy as np
import pytest

from taichi_star.timegrid import (STEP_TOLERANCE, check_duration, check_steps,
                                  interval_for_count, multiples_within, nearest_interval,
                                  on_grid, step_counts, whole_steps)


@pytest.mark.parametrize("time_s, dt, expected", [
    (3.3, 1e-3, 3300),             # 3.3 / 1e-3 = 3299.9999999999995 in floats: still a step
    (0.05, 1e-3, 50),
    (0.0, 1e-3, 0),
    (-0.002, 1e-3, -2),
    (0.0015, 1e-3, None),          # half a step off
    (1.0 + 1e-6, 1e-3, None),      # 1e-6 relative: a thousand times the tolerance
    (1.0 + 1e-12, 1e-3, 1000),     # 1e-12 relative: a thousandth of it
])
def test_whole_steps(time_s, dt, expected):
    assert whole_steps(time_s, dt) == expected


def test_step_counts_match_whole_steps_and_mark_off_grid_with_zero():
    periods = np.array([3.15, 0.0015, 2.0, 0.0])
    assert step_counts(periods, 1e-3).tolist() == [3150, 0, 2000, 0]
    assert on_grid(periods, 1e-3).tolist() == [True, False, True, True]


def test_multiples_within_counts_a_duration_of_exact_multiples_whatever_the_rounding():
    # 0.3 / 0.1 = 2.9999999999999996 in floats: three intervals, not two
    assert multiples_within(0.3, 0.1) == 3
    assert multiples_within(0.3 * (1 - 10 * STEP_TOLERANCE), 0.1) == 2
    assert multiples_within(0.35, 0.1) == 3


@pytest.mark.parametrize("interval_s, dt, steps", [
    (0.05, 1e-3, 50), (0.0504, 1e-3, 50), (0.0506, 1e-3, 51), (1e-5, 1e-3, 1), (0.1, 2.5e-4, 400)])
def test_nearest_interval_is_a_whole_number_of_steps_and_accepted(interval_s, dt, steps):
    interval = nearest_interval(interval_s, dt)
    assert interval == steps * dt
    assert check_steps("record_interval_s", interval, dt) == steps


@pytest.mark.parametrize("duration_s, count, dt, steps", [
    (3.15, 100, 1e-3, 31), (3.15, 10_000, 1e-3, 1), (1.0, 3, 1e-3, 333), (0.01, 10, 1e-3, 1)])
def test_interval_for_count_gives_at_least_count_records(duration_s, count, dt, steps):
    interval = interval_for_count(duration_s, count, dt)
    assert interval == steps * dt
    total = round(duration_s / dt)
    assert total // steps >= min(count, total)


def test_check_steps_names_the_parameter_and_the_nearest_valid_interval():
    with pytest.raises(ValueError, match=r"record_interval_s must be a whole number of steps "
                                         r"\(dt = 0.001 s\), got 0.0015 \(nearest valid: 0.002 s\)"):
        check_steps("record_interval_s", 0.0015, 1e-3)
    with pytest.raises(ValueError, match=r"got 0.0001 \(nearest valid: 0.001 s\)"):
        check_steps("record_interval_s", 1e-4, 1e-3)  # zero steps


def test_check_duration_refuses_less_than_one_step():
    assert check_duration(0.0006, 1e-3) == 1  # rounded to whole steps
    with pytest.raises(ValueError, match=r"duration_s must be at least one step \(dt = 0.001 s\)"):
        check_duration(0.0004, 1e-3)
