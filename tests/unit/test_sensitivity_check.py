"""The whole-run reference of the sensitivity checks: `extrapolated_difference` on analytic
difference quotients."""

import numpy as np
import pytest

from taichi_star.sensitivity_check import extrapolated_difference


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
