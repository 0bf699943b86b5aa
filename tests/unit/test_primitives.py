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


def test_actuators_equal_decides_between_the_symmetry_classes_and_all_gaits():
    """One gait per symmetry class stands for its images only if every per-actuator field
    holds one value: exactly equal values (non-default ones too) keep the 29 classes; a gain
    one ulp apart, a delay on one actuator or the identified preset's gains need all 255 gaits,
    each its own source with no symmetry."""
    import math

    from taichi_star.primitives import (actuators_equal, class_symmetries, gait_sources,
                                        simulated_gaits)

    equal = ts.StarParams(actuator_gains=(1.3,) * 8, actuator_delays=(0.05,) * 8)
    assert actuators_equal(equal) and actuators_equal(ts.StarParams())
    unequal = [equal.replace(actuator_gains=(1.3,) * 7 + (math.nextafter(1.3, 2.0),)),
               ts.StarParams(actuator_delays=(0.0,) * 7 + (0.01,)),
               ts.StarParams.preset("identified")]
    assert not any(actuators_equal(params) for params in unequal)
    reduced, direct = gait_sources(True), gait_sources(False)
    assert reduced == class_symmetries() and len(simulated_gaits(reduced)) == 29
    assert simulated_gaits(reduced) == [name for name, _ in ts.symmetry_classes()]
    assert set(direct) == set(reduced) and len(direct) == 255
    assert simulated_gaits(direct) == list(direct)
    assert all(source == (gait, 0, False, 1) for gait, source in direct.items())
