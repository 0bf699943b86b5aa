"""The planner's model (taichi_star.planner.PrimitiveModel) without simulation: predictions in
the body frame, open-loop plans to a lattice goal."""

import math
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from taichi_star.planner import ALIGNED_DEG, PrimitiveModel

COMMITTED_PRIMITIVES = Path(__file__).resolve().parents[2] / "results" / "primitives.csv"


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
    assert model.masks.dtype == bool and model.masks[a1].tolist() == [True] + [False] * 7
    # "none" neither steps nor turns
    position, heading = model.predict(np.ones((1, 2)), np.array([0.3]), np.array([0]))
    assert position.tolist() == [[1.0, 1.0]] and heading.tolist() == [0.3]
    with pytest.raises(ValueError, match="turns_deg"):
        PrimitiveModel(["A1", "A3"], [(10, 0), (0, 10)], [0.0])


def test_plan_reaches_a_lattice_goal_in_the_fewest_cycles():
    model = square_model()
    plan = model.plan(np.array([[30.0, 20.0], [0.5, 0.0]]), tolerance_mm=1.0, max_cycles=8)
    steps = model.steps_mm[plan].sum(axis=1)
    np.testing.assert_allclose(steps, [(30, 20), (0, 0)])
    assert (plan[0, :5] != 0).all() and (plan[0, 5:] == 0).all() and (plan[1] == 0).all()


def glide_model(glide_mm=5.0):
    """A1 steps 10 mm along x per cycle and glides glide_mm on after its last firing; A5 steps
    back."""
    return PrimitiveModel(["A1", "A5"], [(10, 0), (-10, 0)], [0.0, 0.0],
                          glides_mm=[(glide_mm, 0), (-glide_mm, 0)])


def test_the_plan_stops_firing_early_for_the_glide():
    a1 = 1
    goal, tolerance = np.array([[40.0, 0.0]]), 5.0
    # a robot that glides 8 mm after its last firing: the glide-blind plan fires until the
    # model puts it on the goal (4 × 10 mm) and the robot comes to rest 8 mm past it
    blind = PrimitiveModel(["A1", "A5"], [(10, 0), (-10, 0)], [0.0, 0.0])
    plan = blind.plan(goal, tolerance, max_cycles=6)[0]
    assert plan.tolist() == [a1, a1, a1, a1, 0, 0]
    assert 4 * 10 + 8 - goal[0, 0] > tolerance
    # planning for the glide stops after three: at rest at 30 + 8 = 38 mm, within 5 mm
    model = glide_model(8.0)
    assert model.gaits[a1] == "A1"
    plan = model.plan(goal, tolerance, max_cycles=6)[0]
    assert plan.tolist() == [a1, a1, a1, 0, 0, 0]
    rest = model.rest(model.steps_mm[plan].sum(axis=0)[None], np.zeros(1), np.array([a1]))
    np.testing.assert_allclose(rest, [(38.0, 0.0)])
    # exactly reachable: two firings and the glide rest on a goal 2·10 + 8 = 28 mm ahead
    assert model.plan(np.array([[28.0, 0.0]]), 0.5, max_cycles=4)[0].tolist() == [a1, a1, 0, 0]


def test_rest_and_choice_use_the_last_gait_and_the_heading():
    model = glide_model()
    a1, a5 = model.gaits.index("A1"), model.gaits.index("A5")
    position = np.array([[20.0, 0.0], [0.0, 20.0], [20.0, 0.0]])
    heading = np.array([0.0, math.pi / 2, 0.0])
    last = np.array([a1, a1, 0])
    np.testing.assert_allclose(model.rest(position, heading, last),
                               [(25, 0), (0, 25), (20, 0)], atol=1e-12)
    goals = np.array([[25.0, 0.0], [0.0, 25.0], [25.0, 0.0]])
    choice = model.choose(position, heading, goals, 1.0, last)
    # the first two glide into their goals: stop firing
    assert choice[:2].tolist() == [0, 0]
    # the third is at rest 5 mm short (tolerance 1 mm): one A1 would rest at 35 mm, one A5 at
    # 5 mm; of the pairs only A5 then A1 rests on the goal (20 − 10 + 10 + 5 = 25)
    assert choice[2] == a5
    assert model.choose(position[2:], heading[2:], goals[2:], 1.0).tolist() == [a5]  # last: none
    assert model.choose(position[2:], heading[2:], goals[2:], 5.0, last[2:]).tolist() == [0]


def streak_model():
    """A1 steps 10 mm along x per cycle and A3 10 mm along y; their glides grow with the
    streak: 2, 5, 7 mm after 1, 2, 3 (and more) firings in a row (A3's along y)."""
    glides = [[(2, 0), (0, 2)], [(5, 0), (0, 5)], [(7, 0), (0, 7)]]
    return PrimitiveModel(["A1", "A3"], [(10, 0), (0, 10)], [0.0, 0.0], glides_mm=glides)


def test_rest_uses_the_glide_of_the_streak_capped_at_the_longest_measured():
    model = streak_model()
    a1, a3 = model.gaits.index("A1"), model.gaits.index("A3")
    position, heading = np.zeros((6, 2)), np.array([0.0] * 5 + [math.pi / 2])
    last = np.array([a1, a1, a1, a1, a3, a1])
    streak = np.array([1, 2, 3, 4, 2, 2])
    np.testing.assert_allclose(model.rest(position, heading, last, streak),
                               [(2, 0), (5, 0), (7, 0), (7, 0), (0, 5), (0, 5)], atol=1e-12)
    np.testing.assert_allclose(model.rest(position[:1], heading[:1], last[:1]), [(2, 0)])
    np.testing.assert_allclose(model.rest(position[:1], heading[:1], np.array([0]),
                                          np.array([0])), [(0, 0)])


def test_next_streak_counts_a_gait_or_one_stepping_the_same_way_fired_in_a_row():
    """Steps along x (A1), 44° and 46° from it (A2, A3) and none (A1+A5): a gait continues
    its own streak, or one of a gait stepping within ALIGNED_DEG = 45° of it."""
    steps = [(10, 0), (10 * math.cos(math.radians(44)), 10 * math.sin(math.radians(44))),
             (10 * math.cos(math.radians(46)), 10 * math.sin(math.radians(46))), (0, 0)]
    model = PrimitiveModel(["A1", "A2", "A3", "A1+A5"], steps, [0.0] * 4)
    a1, a2, a3, a15 = (model.gaits.index(g) for g in ("A1", "A2", "A3", "A1+A5"))
    last = np.array([a1, a1, a1, a1, 0, a15, a15, a1])
    streak = np.array([3, 3, 3, 3, 0, 2, 2, 2])
    choice = np.array([a1, a2, a3, 0, a1, a15, a1, a15])
    np.testing.assert_array_equal(model.next_streak(last, streak, choice),
                                  [4, 4, 1, 0, 1, 3, 1, 1])
    assert ALIGNED_DEG == 45.0


def test_gaits_the_symmetry_puts_exactly_45_degrees_apart_continue_the_streak():
    """Pairs exactly ALIGNED_DEG apart by the robot's symmetry measure that angle to the
    rounding of their steps, whose sign decided (half the 3,072 pairs each way, mirror images
    unlike; A1+A2 then A2+A3, which the robot swims 9.4 mm a cycle, was predicted at 4.97 mm:
    an audit, 2026-12): the angle itself is within, so every such pair of the committed table
    continues, mirror images alike, and 45° plus the slack's worth more does not."""
    table = pd.read_csv(COMMITTED_PRIMITIVES)
    model = PrimitiveModel.from_table(table)
    index = {gait: model.gaits.index(gait) for gait in model.gaits}
    for first, second in (("A1+A2", "A2+A3"), ("A1+A7", "A6+A8"), ("A1+A3", "A2+A4"),
                          ("A1+A8", "A7+A8")):
        before, after = model.steps_mm[index[first]], model.steps_mm[index[second]]
        angle = math.degrees(math.acos(before @ after / np.hypot(*before) / np.hypot(*after)))
        assert angle == pytest.approx(45.0, abs=1e-6), (first, second)
        assert model.next_streak(np.array([index[first]]), np.array([3]),
                                 np.array([index[second]])).tolist() == [4], (first, second)
    # just outside: a step turned by 45° and a relative 1e-8 more starts a new streak
    turned = math.radians(45.0) * (1 + 1e-8)
    steps = [(10.0, 0.0), (10 * math.cos(turned), 10 * math.sin(turned))]
    outside = PrimitiveModel(["A1", "A2"], steps, [0.0, 0.0])
    a1, a2 = outside.gaits.index("A1"), outside.gaits.index("A2")
    assert outside.next_streak(np.array([a1]), np.array([3]), np.array([a2])).tolist() == [1]


def test_plan_and_choice_use_the_glide_of_the_streak():
    model = streak_model()
    a1, a3 = model.gaits.index("A1"), model.gaits.index("A3")
    # 12 mm ahead: one firing rests at 10 + 2 = 12 (the k = 3 glide would overshoot to 17)
    assert model.plan(np.array([[12.0, 0.0]]), 0.5, 3)[0].tolist() == [a1, 0, 0]
    # 25 mm: two firings rest at 20 + 5; 37 mm: three at 30 + 7; 47 mm: four at 40 + 7
    for goal, fired in ((25.0, 2), (37.0, 3), (47.0, 4)):
        plan = model.plan(np.array([[goal, 0.0]]), 0.5, 6)[0]
        assert plan.tolist() == [a1] * fired + [0] * (6 - fired), goal
    # a streak broken by another gait starts again at 1: A1 then A3 rests at (10, 10 + 2)
    rest_second = model.plan(np.array([[10.0, 12.0]]), 0.5, 4)[0]
    assert sorted(rest_second[:2].tolist()) == [a1, a3] and rest_second[2:].tolist() == [0, 0]
    # having fired A1 twice at x = 20: stopping rests at 25; one more A1 rests at 30 + 7 = 37
    at, heading = np.array([[20.0, 0.0]]), np.zeros(1)
    assert model.choose(at, heading, np.array([[25.0, 0.0]]), 0.5, np.array([a1]),
                        np.array([2])).tolist() == [0]
    assert model.choose(at, heading, np.array([[37.0, 0.0]]), 0.5, np.array([a1]),
                        np.array([2])).tolist() == [a1]
    # the same robot having fired A1 once: another A1 is its second in a row, at rest at
    # 30 + 5 = 35
    assert model.choose(at, heading, np.array([[35.0, 0.0]]), 0.5, np.array([a1]),
                        np.array([1])).tolist() == [a1]


def test_glides_are_read_from_a_primitive_table_and_checked():
    table = pd.DataFrame({"gait": ["A1", "A5"], "step_x_mm": [10.0, -10.0],
                          "step_y_mm": [0.0, 0.0], "turn_deg": [0.0, 0.0],
                          "status": ["ok", "ok"], "glide1_x_mm": [5.0, -5.0],
                          "glide1_y_mm": [0.0, 1.0], "glide2_x_mm": [6.0, -6.0],
                          "glide2_y_mm": [0.5, 2.0], "glide3_x_mm": [7.0, -7.0],
                          "glide3_y_mm": [1.0, 3.0]})
    model = PrimitiveModel.from_table(table)
    np.testing.assert_array_equal(model.glides_mm, [[(0, 0), (5, 0), (-5, 1)],
                                                    [(0, 0), (6, 0.5), (-6, 2)],
                                                    [(0, 0), (7, 1), (-7, 3)]])
    # a streak of 0 (nothing fired yet) glides as one firing
    np.testing.assert_array_equal(model.glide(np.array([1]), np.array([0])), [(5, 0)])
    table = table.drop(columns=["glide3_x_mm", "glide3_y_mm"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # one streak of glides: no warning
        one = PrimitiveModel.from_table(table.drop(columns=["glide2_x_mm", "glide2_y_mm"]))
    # the first streak's glides of the table: none without firing, then A1's and A5's
    np.testing.assert_array_equal(one.glides_mm, [[(0, 0), (5, 0), (-5, 1)]])
    # none: plans from it overshoot, warned
    with pytest.warns(RuntimeWarning, match="the primitive table has no glides from one firing"):
        without = PrimitiveModel.from_table(table.drop(columns=["glide1_x_mm", "glide1_y_mm",
                                                                "glide2_x_mm", "glide2_y_mm"]))
    assert without.glides_mm.shape == (1, 3, 2) and not without.glides_mm.any()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # planning without glides on purpose (plan's 0)
        PrimitiveModel.from_table(table.drop(columns=["glide1_x_mm", "glide1_y_mm",
                                                      "glide2_x_mm", "glide2_y_mm"]),
                                  expect_glides=False)
    # a gap in the streaks: only those before it are read
    with pytest.warns(RuntimeWarning, match="the primitive table has no glides from one firing"):
        gap = PrimitiveModel.from_table(table.drop(columns=["glide1_x_mm", "glide1_y_mm"]))
    assert not gap.glides_mm.any()
    legacy = table.drop(columns=["glide2_x_mm", "glide2_y_mm"]).rename(
        columns={"glide1_x_mm": "glide_x_mm", "glide1_y_mm": "glide_y_mm"})
    with pytest.raises(ValueError, match="measure it again"):
        PrimitiveModel.from_table(legacy)
    with pytest.raises(ValueError, match="glides_mm"):
        PrimitiveModel(["A1"], [(10, 0)], [0.0], glides_mm=[(1, 0), (2, 0)])
    with pytest.raises(ValueError, match="glides_mm"):
        PrimitiveModel(["A1"], [(10, 0)], [0.0], glides_mm=np.zeros((0, 1, 2)))
    with pytest.raises(ValueError, match="must be finite"):
        PrimitiveModel(["A1"], [(10, 0)], [0.0], glides_mm=[(np.nan, 0)])


def test_a_primitive_table_is_checked_cell_by_cell_before_the_glides_warning():
    """A text where a number belongs (a TypeError from NumPy before), a kept gait's NaN or
    inf in another column the planner reads (its streak's step or its step_y_mm: refused
    after the warning of missing glides), a gait listed twice: each refused naming the column
    and the gait, and before any warning. A failed gait's missing numbers are no fault (it is
    left out, with a warning saying so); nor is a column the planner does not read
    (`..._keeps_only_ok_and_finite_rows`: an ok gait without a steady step or turn is left
    out)."""
    table = pd.DataFrame({"gait": ["A1", "A5", "A3"], "step_x_mm": [10.0, -10.0, np.nan],
                          "step_y_mm": [0.0, 0.0, np.nan], "turn_deg": [0.0, 0.0, np.nan],
                          "status": ["ok", "ok", "newton_failed"],
                          "step1_x_mm": [6.0, -6.0, np.nan], "step1_y_mm": [0.0, 0.0, np.nan],
                          "direction_deg": ["east", "west", "x"]})
    with pytest.warns(RuntimeWarning) as told:
        assert PrimitiveModel.from_table(table, expect_glides=False).gaits == ["none", "A1", "A5"]
    assert [str(w.message) for w in told] == [
        "the primitive table's gaits A3 (1 of status newton_failed) failed their measurement: "
        "left out of the model"]
    for column, value, message in (
            ("step_x_mm", "abc", "'abc', not a number"),
            ("step_y_mm", np.nan, "nan, not a finite number (status ok)"),
            ("step1_y_mm", np.inf, "inf, not a finite number (status ok)")):
        broken = table.astype({column: object})
        broken.loc[1, column] = value
        with warnings.catch_warnings():
            warnings.simplefilter("error")   # refused before the glides' warning
            with pytest.raises(ValueError) as error:
                PrimitiveModel.from_table(broken)
        assert str(error.value) == f"table: {column} of gait A5 is {message}"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match="^gaits must name each gait once, got A1"):
            PrimitiveModel.from_table(table.assign(gait=["A1", "A1", "A3"]))


def test_steps_of_a_streak_speed_up_to_the_steady_step():
    """A1's first firing from rest steps 6 mm, its second 9 mm, every later one its steady
    10 mm; the glide is 2 mm after any streak."""
    model = PrimitiveModel(["A1"], [(10, 0)], [0.0], glides_mm=[(2, 0)],
                           streak_steps_mm=[[(6, 0)], [(9, 0)]])
    a1 = model.gaits.index("A1")
    np.testing.assert_array_equal(model.step(np.array([a1] * 4), np.array([1, 2, 3, 9])),
                                  [(6, 0), (9, 0), (10, 0), (10, 0)])
    np.testing.assert_array_equal(model.step(np.array([a1])), [(10, 0)])  # no streak: steady
    position, _ = model.predict(np.zeros((2, 2)), np.array([0.0, math.pi / 2]),
                                np.array([a1, a1]), np.array([1, 2]))
    np.testing.assert_allclose(position, [(6, 0), (0, 9)], atol=1e-12)
    # rests after 1, 2, 3 firings: 6 + 2 = 8, 15 + 2 = 17, 25 + 2 = 27
    for goal, fired in ((8.0, 1), (17.0, 2), (27.0, 3)):
        plan = model.plan(np.array([[goal, 0.0]]), 0.5, 4)[0]
        assert plan.tolist() == [a1] * fired + [0] * (4 - fired), goal
    # a streak of 0 steps as the first firing
    np.testing.assert_array_equal(model.step(np.array([a1]), np.array([0])), [(6, 0)])
    table = pd.DataFrame({"gait": ["A1"], "step_x_mm": [10.0], "step_y_mm": [0.0],
                          "turn_deg": [0.0], "status": ["ok"], "step1_x_mm": [6.0],
                          "step1_y_mm": [0.5], "step2_x_mm": [8.0], "step2_y_mm": [0.25]})
    np.testing.assert_array_equal(PrimitiveModel.from_table(table).streak_steps_mm,
                                  [[(0, 0), (6, 0.5)], [(0, 0), (8, 0.25)], [(0, 0), (10, 0)]])
    with pytest.raises(ValueError, match="streak_steps_mm"):
        PrimitiveModel(["A1"], [(10, 0)], [0.0], streak_steps_mm=[(6, 0)])


def random_model(rng):
    """Four gaits with random steps, turns, two streak steps and three streak glides."""
    steps = rng.normal(scale=8.0, size=(4, 2))
    return PrimitiveModel(["A1", "A2", "A3", "A4"], steps, rng.uniform(-40, 40, 4),
                          glides_mm=rng.normal(scale=3.0, size=(3, 4, 2)),
                          streak_steps_mm=steps * rng.uniform(0.3, 0.9, (2, 4, 1)))


def chosen_by_enumeration(model, position, heading, goal, tolerance, last, streak):
    """`choose`'s rule for one robot, by scalar calls of the model's public pieces: stop if
    its rest is within the tolerance; else the first gait whose one cycle and glide rest
    within it (the nearest); else the first gait of the nearest rest over every two-cycle
    pair ("none" first: stopping now; "none" second: gliding after the first)."""
    def one(index):
        return np.array([index])

    def rest_after(pos, head, gait, run):
        return model.rest(pos[None], np.array([head]), one(gait), one(run))[0]

    stop = rest_after(position, heading, last, streak)
    if math.dist(goal, stop) <= tolerance:
        return 0
    gaits = range(len(model.gaits))
    firsts = {}
    for g in gaits:
        run = model.next_streak(last, streak, g)
        pos, head = model.predict(position[None], np.array([heading]), one(g), one(run))
        firsts[g] = (pos[0], head[0], run, stop if g == 0 else rest_after(pos[0], head[0], g, run))
    distances = [math.dist(goal, firsts[g][3]) for g in gaits]
    if min(distances) <= tolerance:
        return int(np.argmin(distances))
    best, choice = math.inf, None
    for g in gaits:
        pos, head, run, rest_first = firsts[g]
        for h in gaits:
            if g == 0:
                rest = stop
            elif h == 0:
                rest = rest_first
            else:
                second_run = model.next_streak(g, run, h)
                pos2, head2 = model.predict(pos[None], np.array([head]), one(h), one(second_run))
                rest = rest_after(pos2[0], head2[0], h, second_run)
            if math.dist(goal, rest) < best:
                best, choice = math.dist(goal, rest), g
    return choice


@pytest.mark.parametrize("seed", range(6))
def test_choice_equals_enumerating_every_one_and_two_cycle_plan(seed):
    """Random models and states (position, heading, last gait and its streak, goal): the
    vectorised choice equals the enumeration, for robots that stop, finish in one cycle or
    plan two; one robot's early stop does not end the others' choices."""
    rng = np.random.default_rng(seed)
    model = random_model(rng)
    count = 24
    position = rng.normal(scale=20.0, size=(count, 2))
    heading = rng.uniform(-math.pi, math.pi, count)
    last = rng.integers(0, len(model.gaits), count)
    streak = np.where(last == 0, 0, rng.integers(1, 5, count))
    goal = position + rng.normal(scale=15.0, size=(count, 2))
    goal[:4] = model.rest(position[:4], heading[:4], last[:4], streak[:4]) + 0.5  # stop there
    for b in range(4, 8):      # finish in one cycle of a gait: its rest after it, nearly
        gait = rng.integers(1, len(model.gaits))
        run = model.next_streak(last[b], streak[b], gait)
        moved, turned = model.predict(position[b:b + 1], heading[b:b + 1], np.array([gait]),
                                      np.array([run]))
        goal[b] = model.rest(moved, turned, np.array([gait]), np.array([run]))[0] + 0.4
    tolerance = 1.5
    got = model.choose(position, heading, goal, tolerance, last, streak)
    expected = [chosen_by_enumeration(model, position[b], heading[b], goal[b], tolerance,
                                      last[b], streak[b]) for b in range(count)]
    assert got.tolist() == expected
    assert (got[:4] == 0).all() and (got[4:8] != 0).all() and (got[8:] != 0).any()


def test_tolerance_boundaries_of_the_choice():
    """At rest exactly the tolerance from the goal: stop (≤). One cycle resting exactly the
    tolerance from it: that gait (≤), though two cycles of another would rest on the goal."""
    model = PrimitiveModel(["A1", "A3"], [(10, 0), (6, 0)], [0.0, 0.0])
    a1, a3 = model.gaits.index("A1"), model.gaits.index("A3")
    origin, heading = np.zeros((1, 2)), np.zeros(1)
    assert model.choose(origin, heading, np.array([[2.0, 0.0]]), 2.0).tolist() == [0]
    assert model.choose(origin, heading, np.array([[12.0, 0.0]]), 2.0).tolist() == [a1]
    # just outside that: the two cycles A3, A3 land on 12 mm
    assert model.choose(origin, heading, np.array([[12.0, 0.0]]), 1.999).tolist() == [a3]
    # stopping within the tolerance stops, though a gait would rest nearer the goal; at
    # exactly the tolerance too (not a step of A2's 1.2 mm, which would rest 0.8 mm from it)
    near = PrimitiveModel(["A1", "A2"], [(10, 0), (1.2, 0)], [0.0, 0.0])
    at = np.array([[10.0, 0.0]])
    assert near.choose(at, heading, np.array([[11.5, 0.0]]), 2.0).tolist() == [0]
    assert near.choose(at, heading, np.array([[12.0, 0.0]]), 2.0).tolist() == [0]
    assert near.choose(at, heading, np.array([[12.0, 0.0]]), 1.999).tolist() == [
        near.gaits.index("A2")]


def test_a_primitive_table_keeps_only_ok_and_finite_rows():
    """A failed gait, and an ok one without a steady step or turn (a measurement too short for
    one), are left out, each with a warning naming it (both were silent: audits, 2026-12; a
    table whose fastest class had failed planned with the other 248 gaits without a word);
    a table of ok gaits says nothing."""
    table = pd.DataFrame({"gait": ["A1", "A2", "A3", "A4"],
                          "step_x_mm": [10.0, 5.0, np.nan, 3.0], "step_y_mm": [0.0] * 4,
                          "turn_deg": [0.0, 10.0, 0.0, np.nan],
                          "status": ["ok", "nan_state", "ok", "ok"]})
    with pytest.warns(RuntimeWarning) as told:
        model = PrimitiveModel.from_table(table, expect_glides=False)
    assert [str(w.message) for w in told] == [
        "the primitive table's gaits A2 (1 of status nan_state) failed their measurement: left "
        "out of the model",
        "the primitive table's gaits A3, A4 (2 of status ok) have no finite step_x_mm or "
        "turn_deg (a measurement too short for a steady step): left out of the model"]
    assert model.gaits == ["none", "A1"]
    np.testing.assert_array_equal(model.steps_mm, [(0, 0), (10, 0)])
    with pytest.warns(RuntimeWarning, match=r"gaits A2 \(1 of status nan_state\) failed"):
        PrimitiveModel.from_table(table.iloc[:2], expect_glides=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # only ok gaits with steps: nothing to say
        PrimitiveModel.from_table(table.iloc[:1], expect_glides=False)


def test_plans_and_choices_refuse_what_they_cannot_plan_with():
    """A NaN goal planned "stop" as if reached, a (2,) goal was two goals, a tolerance of 0
    or NaN was taken, max_cycles 2.5 a TypeError, last = -1 the last gait and 999 an
    IndexError (an audit, 2026-12): each a ValueError naming the argument."""
    model = PrimitiveModel(["A1", "A2"], [(10, 0), (0, 10)], [0.0, 0.0])
    good = np.array([[30.0, 0.0]])
    assert model.plan(good, 0.5, 1).shape == (1, 1)
    for goal in (np.array([[np.nan, 0.0]]), np.array([50.0, 0.0]), np.array([[2000.0, 0.0]])):
        with pytest.raises(ValueError, match="^goal_mm must be"):
            model.plan(goal, 0.5, 3)
    for tolerance in (0.0, -1.0, np.nan, "5"):
        with pytest.raises(ValueError, match="^tolerance_mm must be a finite number > 0 mm"):
            model.plan(good, tolerance, 3)
    for cycles in (0, 2.5, True):
        with pytest.raises(ValueError, match="^max_cycles must be an integer >= 1"):
            model.plan(good, 0.5, cycles)
    at, heading = np.zeros((1, 2)), np.zeros(1)
    assert model.choose(at, heading, good, 0.5, np.array([2]), np.array([1])).shape == (1,)
    for last, message in ((np.array([-1]), r"^last must be \(1,\) integers >= 0"),
                          (np.array([3]), r"^last must hold gait indices in \[0, 2\]"),
                          (np.array([0.5]), r"^last must be \(1,\) integers")):
        with pytest.raises(ValueError, match=message):
            model.choose(at, heading, good, 0.5, last)
    with pytest.raises(ValueError, match=r"^streak must be \(1,\) integers >= 0"):
        model.choose(at, heading, good, 0.5, np.array([1]), np.array([-2]))
    with pytest.raises(ValueError, match=r"^heading_rad must be a finite array of shape \(1\)"):
        model.choose(at, np.zeros(2), good, 0.5)
    with pytest.raises(ValueError, match=r"^goal_mm must be a finite array of shape \(1, 2\)"):
        model.choose(at, heading, np.zeros((2, 2)), 0.5)


def test_a_drive_is_checked_at_the_ends_of_its_ranges_before_any_compute():
    """goals a finite, non-empty (G, 2) array; max_cycles ≥ 1 and settle_cycles ≥ 0, integers
    (a bool is not one); tolerance_mm > 0; the period and period / frames_per_cycle whole
    numbers of steps: each end accepted, just past it refused naming the argument."""
    from taichi_star import SolverConfig, StarParams
    from taichi_star.planner import check_drive

    params, solver = StarParams(), SolverConfig()
    goals = check_drive([[40, 0], [0, -6]], params, solver, tolerance_mm=1e-9, max_cycles=1,
                        settle_cycles=0, frames_per_cycle=1)
    assert goals.dtype == np.float64 and goals.tolist() == [[40.0, 0.0], [0.0, -6.0]]
    # 3.15 s is 3150 steps of 1 ms: 10 frames of 315 steps, 7 of 450 (whole), 4 of 787.5 (not)
    check_drive(goals, params, solver, frames_per_cycle=7)
    refused = [
        (dict(goals_mm=np.zeros((0, 2))), "goals_mm must be a finite"),
        (dict(goals_mm=[40.0, 0.0]), "goals_mm must be a finite"),
        (dict(goals_mm=[[40.0, 0.0, 0.0]]), "goals_mm must be a finite"),
        (dict(goals_mm=[[40.0, np.inf]]), "goals_mm must be a finite"),
        (dict(max_cycles=0), "max_cycles must be an integer >= 1, got 0"),
        (dict(max_cycles=True), "max_cycles must be an integer >= 1, got True"),
        (dict(settle_cycles=-1), "settle_cycles must be an integer >= 0, got -1"),
        (dict(settle_cycles=1.0), "settle_cycles must be an integer >= 0, got 1.0"),
        (dict(tolerance_mm=0.0), "tolerance_mm must be a finite number > 0 mm, got 0.0"),
        (dict(tolerance_mm=math.nan), "tolerance_mm must be a finite number > 0 mm, got nan"),
        (dict(frames_per_cycle=4), r"period / frames_per_cycle must be a whole number of steps "
                                   r"\(dt = 0.001 s\), got period 3.15 and 4 frames"),
        (dict(params=params.replace(period=3.1505), frames_per_cycle=1), "period / frames"),
    ]
    for changes, message in refused:
        arguments = {"goals_mm": goals, "params": params, "solver": solver, **changes}
        with pytest.raises(ValueError, match="^" + message):
            check_drive(**arguments)


def test_drive_is_told_when_it_judges_off_the_tables_glide_horizon(monkeypatch):
    """A coasting robot still moves, so a robot judged 12 cycles after its controller stopped,
    where the table's glides span 4, missed goals it reaches at 4 (an audit, 2026-12): the
    model keeps the table's glide_cycles and `drive` warns, before any compute, when
    settle_cycles differs; the same horizon, or a table that does not say, is silent."""
    from taichi_star import planner

    model = PrimitiveModel.from_table(pd.read_csv(COMMITTED_PRIMITIVES))
    assert model.glide_cycles == 4
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model.check_settle(4)
        PrimitiveModel(["A1"], [(10, 0)], [0.0]).check_settle(12)
    for settle in (3, 12):
        with pytest.warns(RuntimeWarning, match=rf"^settle_cycles = {settle} judges the robots "
                                                rf"{settle} cycles .* glides span 4"):
            model.check_settle(settle)

    class Started(Exception):
        pass

    def no_simulator(*args, **kwargs):
        raise Started
    monkeypatch.setattr(planner, "Simulator", no_simulator)
    with pytest.warns(RuntimeWarning, match="^settle_cycles = 12"):
        with pytest.raises(Started):
            planner.drive(model, [[50.0, 0.0]], settle_cycles=12)
    with pytest.raises(ValueError, match="^glide_cycles must be None or an integer >= 1"):
        PrimitiveModel(["A1"], [(10, 0)], [0.0], glide_cycles=0)


def test_closed_loop_gain_counts_goals_and_averages_over_those_both_modes_reached():
    """Two goals: goal 0 reached by both modes (in 2 and 1 cycles), goal 1 by the closed loop
    alone. Each figure computed by hand (a mutation audit, 2026-12, found only the refusals
    tested: `any` for "both reached", the rows counted for the goals, the largest end error
    for the mean, all survived)."""
    from taichi_star.planner import closed_loop_gain

    summary = pd.DataFrame({
        "goal": [0, 0, 1, 1], "mode": ["open", "closed", "open", "closed"],
        "reached": [True, True, False, True], "final_error_mm": [4.0, 2.0, 30.0, 3.0],
        "end_error_mm": [1.0, 0.5, 20.0, 1.5], "cycles_to_goal": [2.0, 1.0, math.nan, 5.0]})
    assert closed_loop_gain(summary) == {
        "open_reached": 1, "open_mean_error_mm": 17.0, "open_max_error_mm": 30.0,
        "open_mean_end_error_mm": 10.5,
        "closed_reached": 2, "closed_mean_error_mm": 2.5, "closed_max_error_mm": 3.0,
        "closed_mean_end_error_mm": 1.0,
        "open_mean_cycles_both_reached": 2.0, "closed_mean_cycles_both_reached": 1.0,
        "goals": 2}


@pytest.mark.parametrize("change, message", [
    (dict(streak_steps_mm=[[[math.nan, 0.0], [1.0, 0.0]]]),
     "steps_mm, turns_deg, glides_mm and streak_steps_mm must be finite"),
    (dict(glide_cycles=2.5), "glide_cycles must be None or an integer >= 1, got 2.5"),
    (dict(glide_cycles=0), "glide_cycles must be None or an integer >= 1, got 0")])
def test_a_model_refuses_a_non_finite_streak_and_a_fractional_glide_span(change, message):
    """Each refusal named what it refuses (a mutation audit, 2026-12: a NaN streak step and
    glide_cycles=2.5, silently 2, passed every test with the check removed)."""
    arguments = dict(gaits=["A1", "A3"], steps_mm=[[1.0, 0.0], [0.0, 1.0]],
                     turns_deg=[0.0, 0.0])
    with pytest.raises(ValueError) as error:
        PrimitiveModel(**arguments, **change)
    assert str(error.value) == message


@pytest.mark.parametrize("tolerance", [math.inf, 0.0, -1.0, math.nan, True, 10**400])
def test_plan_and_choose_refuse_a_tolerance_that_is_no_distance(tolerance):
    """An infinite tolerance planned to stand still (every goal "reached")."""
    model = PrimitiveModel(["A1"], [[1.0, 0.0]], [0.0])
    goal = np.array([[10.0, 0.0]])
    for call in (lambda: model.plan(goal, tolerance, 3),
                 lambda: model.choose(np.zeros((1, 2)), np.zeros(1), goal, tolerance)):
        with pytest.raises(ValueError, match=r"^tolerance_mm must be a finite number > 0 mm, got "):
            call()


def test_check_drive_counts_a_robot_per_goal_and_mode_and_names_the_first_near_goal(
        monkeypatch):
    """The work refused before compute is that of two robots per goal (open and closed loop),
    of the robot's nodes (n_arc 48: 433), and a tolerance that reaches goals before the robot
    moves names the first of them (a mutation audit, 2026-12: a count of goals and the last
    near goal both passed)."""
    import taichi_star as ts
    from taichi_star import planner

    asked = []
    monkeypatch.setattr(planner, "check_work",
                        lambda what, steps, batch=None, nodes=None: asked.append((batch, nodes)))
    goals = [[50.0, 0.0], [0.0, 60.0], [-70.0, 0.0]]
    planner.check_drive(goals, ts.StarParams(n_arc=48), ts.SolverConfig(dt=5e-3))
    assert asked == [(2 * len(goals), 433)]
    near = [[50.0, 0.0], [3.0, 0.0], [0.0, 4.0]]
    with pytest.raises(ValueError, match=r"^tolerance_mm = 5 mm reaches goal 1 \(3 mm from the "
                                         r"start\) before the robot moves"):
        planner.check_drive(near, ts.StarParams(), ts.SolverConfig(dt=5e-3))
