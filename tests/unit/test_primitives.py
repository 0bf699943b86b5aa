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
