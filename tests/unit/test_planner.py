"""The planner's model (taichi_star.planner.PrimitiveModel) without simulation: predictions in
the body frame, open-loop plans to a lattice goal."""

import math

import numpy as np

from taichi_star.planner import PrimitiveModel


def square_model(turn_deg=0.0):
    """Four gaits stepping 10 mm along ±x and ±y, one of them turning."""
    return PrimitiveModel(["A1", "A3", "A5", "A7"], [(10, 0), (0, 10), (-10, 0), (0, -10)],
                          [turn_deg, 0.0, 0.0, 0.0])


def test_model_predicts_in_the_body_frame():
    model = square_model(turn_deg=90.0)
    a1 = model.gaits.index("A1")
    position, heading = model.predict(np.zeros((2, 2)), np.array([0.0, math.pi / 2]),
                                      np.array([a1, a1]))
    np.testing.assert_allclose(position, [(10, 0), (0, 10)], atol=1e-12)
    np.testing.assert_allclose(heading, [math.pi / 2, math.pi])
    assert model.gaits[0] == "none" and not model.masks[0].any()


def test_plan_reaches_a_lattice_goal_in_the_fewest_cycles():
    model = square_model()
    plan = model.plan(np.array([[30.0, 20.0], [0.5, 0.0]]), tolerance_mm=1.0, max_cycles=8)
    steps = model.steps_mm[plan].sum(axis=1)
    np.testing.assert_allclose(steps, [(30, 20), (0, 0)])
    assert (plan[0, :5] != 0).all() and (plan[0, 5:] == 0).all() and (plan[1] == 0).all()
