"""The measured trials as the package ships them (taichi_star.experiment)."""

import numpy as np
import pytest

from taichi_star.experiment import PAPER_GAITS, experimental_trajectory


@pytest.mark.parametrize("gait", PAPER_GAITS)
def test_a_trajectory_starts_at_the_origin_and_its_displacement_is_the_distance_from_it(gait):
    table = experimental_trajectory(gait)
    assert table.columns.tolist() == ["t_s", "x_mm", "y_mm", "displacement_mm"]
    assert (table.loc[0, ["t_s", "x_mm", "y_mm"]] == 0.0).all()
    np.testing.assert_array_equal(table["displacement_mm"], np.hypot(table["x_mm"], table["y_mm"]))
    assert table["displacement_mm"].iloc[-1] > 10.0     # every trial swims centimetres


def test_a_gait_never_measured_is_refused_naming_the_measured_ones():
    with pytest.raises(ValueError, match=r"^no experimental trajectory for gait 'A2'; measured "
                                         r"gaits: A1, A1\+A2, A1\+A3, A1\+A4, A1\+A3\+A5$"):
        experimental_trajectory("A2")
    assert experimental_trajectory("a3+a1").equals(experimental_trajectory("A1+A3"))
