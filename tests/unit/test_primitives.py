"""taichi_star.primitives without simulation: the body-frame vectors follow the gait symmetry."""

import numpy as np

import taichi_star as ts
from taichi_star.primitives import transform_vectors


def test_transform_vectors_follows_the_gait_symmetry():
    """A1's bisector (1, 0) goes where Gait.transform sends A1."""
    for rotation in range(8):
        for reflect in (False, True):
            image = ts.Gait.parse("A1+A2").transform(rotation, reflect).forward
            vector = transform_vectors(ts.Gait.parse("A1+A2").forward, rotation, reflect)
            np.testing.assert_allclose(vector, image, atol=1e-15)


def test_primitives_of_unequal_actuators_are_refused_before_compute():
    """One gait per symmetry class stands for its images only if the eight actuators are equal:
    differing gains or delays (the identified preset) are refused naming the field; equal
    non-default ones are fine."""
    import pytest

    from taichi_star.primitives import check_measurement

    solver = ts.SolverConfig()
    check_measurement(ts.StarParams(actuator_gains=(1.3,) * 8, actuator_delays=(0.05,) * 8),
                      solver, 5, 1)
    with pytest.raises(ValueError, match=r"actuator_gains must be equal for all eight actuators"):
        check_measurement(ts.StarParams.preset("identified"), solver, 5, 1)
    with pytest.raises(ValueError, match=r"actuator_delays must be equal"):
        check_measurement(ts.StarParams(actuator_delays=(0.0,) * 7 + (0.01,)), solver, 5, 1)
    with pytest.raises(ValueError, match=r"actuator_gains"):
        ts.primitives.measure_glides(ts.StarParams.preset("identified"))
