"""The whole-run reference of the sensitivity checks: `extrapolated_difference` on analytic
difference quotients."""

import numpy as np
import pytest

from taichi_star import StarParams
from taichi_star.sensitivities import RELATIVE_STEP, ZERO_VALUE_SCALE, parse_directions
from taichi_star.sensitivity_check import difference_step, extrapolated_difference


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


@pytest.mark.parametrize("field", ["damping_time", "alpha", "drag_parallel"])
def test_the_difference_step_is_the_fields_own_but_at_zero_the_default(field):
    """Off zero h is the sensitivities' ε of the field (1e-3 of the damping time, 1e-2 of C∥);
    at 0 ten times the default ε there, RELATIVE_STEP of ZERO_VALUE_SCALE of the range's top
    (1.0 s for the damping time, whose own ε had put the runs at −4h = −4e-4 s, where BDF2
    diverged)."""
    (direction,) = parse_directions([field])
    moved = StarParams.preset("paper").replace(**{field: 0.02})
    assert difference_step(direction, moved) == direction.step(moved)
    assert direction.step(moved) == pytest.approx(direction.relative_step * 0.02, rel=1e-15)
    at_zero = StarParams.preset("paper").replace(**{field: 0.0})
    top = direction.step(at_zero) / (direction.relative_step * ZERO_VALUE_SCALE)
    assert difference_step(direction, at_zero) == pytest.approx(
        10 * RELATIVE_STEP * ZERO_VALUE_SCALE * top, rel=1e-12)
