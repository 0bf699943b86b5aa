"""A policy driven to goals (`taichi_star.envs.rollout.drive_policy`): it sees what the
environment shows, its robots go where a robot firing its answers alone goes, bit for bit, its
controllers stop where the environment would end their episodes and are judged at rest as the
planners' are; bad arguments and answers are refused naming them."""

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
from taichi_star.envs import StarSwimmerVectorEnv
from taichi_star.envs import rollout
from taichi_star.envs.rollout import POLICY_COLUMNS, POLICY_CYCLE_COLUMNS, drive_policy
from taichi_star.lookahead import compare_controllers

PARAMS = ts.StarParams.preset("paper")
SOLVER = ts.SolverConfig(dt=5e-3)
SETTLE = 1
FRAMES = 3
A1_A3 = np.array([1, 0, 1, 0, 0, 0, 0, 0], dtype=np.float32)  # float 0/1, as SB3 answers


def replay(firings: int, coast: int):
    """A robot of its own firing A1+A3 `firings` periods in a row, then coasting `coast`: its
    (x, y) mm at every period boundary and its records (FRAMES a period)."""
    robot = ts.Simulator([PARAMS], SOLVER)
    boundaries, records = [robot.state()[["centroid_x_mm", "centroid_y_mm"]].to_numpy()[0]], []
    for gait in ["A1+A3"] * firings + ["none"] * coast:
        robot.fire([gait])
        records.append(robot.advance(PARAMS.period, record_interval_s=PARAMS.period / FRAMES))
        boundaries.append(robot.state()[["centroid_x_mm", "centroid_y_mm"]].to_numpy()[0])
    return np.array(boundaries), pd.concat(records, ignore_index=True)


@pytest.fixture(scope="module")
def driven():
    """Goal 0 lies 1 mm from where one period of A1+A3 takes the robot (within the 2-mm
    tolerance at the first boundary: its controller stops there); goal 1 lies 30 mm the other
    way (out of reach in max_cycles = 2: stopped by the budget)."""
    boundaries, _ = replay(1, 0)
    first = boundaries[1]
    goals = np.array([first + [0.0, 1.0], -30.0 * first / np.hypot(*first)])
    observed = []

    def policy(observation):
        observed.append(observation.copy())
        return np.tile(A1_A3, (len(observation), 1))

    tables = drive_policy(policy, goals, PARAMS, SOLVER, tolerance_mm=2.0, max_cycles=2,
                          settle_cycles=SETTLE, frames_per_cycle=FRAMES, mode="fixed")
    return goals, observed, tables


def test_the_robots_go_where_their_firings_alone_take_them(driven):
    goals, _, (summary, cycles, path) = driven
    assert list(summary.columns) == POLICY_COLUMNS and list(cycles.columns) == POLICY_CYCLE_COLUMNS
    assert (summary["mode"] == "fixed").all() and summary["status"].eq("ok").all()
    # goal 0: stopped at boundary 1 within the tolerance (terminated), judged a period later
    # at rest; goal 1: stopped by the budget at boundary 2, never within the tolerance
    assert summary["terminated"].tolist() == [True, False]
    assert summary["run_cycles"].tolist() == [1 + SETTLE, 2 + SETTLE]
    assert summary["cycles_fired"].tolist() == [1, 2]
    for goal, firings in ((0, 1), (1, 2)):
        boundaries, records = replay(firings, SETTLE)
        row = summary.iloc[goal]
        assert row["final_error_mm"] == np.hypot(*(goals[goal] - boundaries[firings]))
        assert row["end_error_mm"] == np.hypot(*(goals[goal] - boundaries[firings + SETTLE]))
        assert row["reached"] == (row["end_error_mm"] <= 2.0)
        assert np.isnan(row["cycles_to_goal"]) != row["reached"]
        own = cycles[cycles["goal"] == goal]
        np.testing.assert_array_equal(own[["x_mm", "y_mm"]].to_numpy(),
                                      boundaries[:len(own)])
        assert own["gait"].tolist()[:firings] == ["A1+A3"] * firings
        assert set(own["gait"].tolist()[firings:]) <= {"none"}
        np.testing.assert_array_equal(own["distance_mm"].to_numpy(),
                                      np.hypot(*(goals[goal] - boundaries[:len(own)]).T))
        # the whole path, driven and coasting to rest
        trail = path[(path["goal"] == goal) & (path["t_s"] > 0)]
        np.testing.assert_array_equal(trail[["x_mm", "y_mm"]].to_numpy()[:len(records)],
                                      records[["centroid_x_mm", "centroid_y_mm"]].to_numpy())
        assert trail["controlled"].tolist()[:len(records)] == \
            (records["t_s"] <= firings * PARAMS.period + 1e-9).tolist()
    # one row per cycle while a robot is driven, up to the last stop
    assert cycles["cycle"].max() == 2 and len(cycles) == 2 * 3


def test_the_policy_sees_what_the_environment_shows(driven):
    goals, observed, _ = driven
    env = StarSwimmerVectorEnv(2, params=PARAMS, solver=SOLVER, goal_tolerance_mm=2.0,
                               goal_distance_mm=40.0)
    first, _ = env.reset(options={"goal": goals})
    np.testing.assert_array_equal(observed[0], first)
    after, *_ = env.step(np.tile(A1_A3, (2, 1)))
    np.testing.assert_array_equal(observed[1], after)
    # asked while a robot is driven: at boundaries 0 and 1 (goal 0 stops at 1, goal 1 at 2)
    assert len(observed) == 2


def test_its_table_sits_beside_the_planners(driven):
    summary = driven[2][0]
    other = summary.drop(columns="terminated").assign(mode="other", reached=True)
    table = compare_controllers(pd.concat([summary, other]))
    assert table["mode"].tolist() == ["fixed", "other"]
    assert table["reached"].tolist() == [int(summary["reached"].sum()), 2]


def forbidden_batch(*args, **kwargs):
    raise AssertionError("a robot was built")


@pytest.mark.parametrize("policy, kwargs, message", [
    ("fire", {}, r"policy must be a callable from observations to actions, got str"),
    (lambda obs: np.zeros((len(obs), 8)), {"tolerance_mm": 60.0},
     r"tolerance_mm = 60 mm reaches goal 0"),
    (lambda obs: np.zeros((len(obs), 8)), {"max_cycles": 0}, r"max_cycles must be an integer"),
    (lambda obs: np.zeros((len(obs), 8)), {"mode": ""}, r"mode must be a non-empty name"),
])
def test_arguments_are_refused_before_compute(monkeypatch, policy, kwargs, message):
    monkeypatch.setattr(rollout, "GoalReachingBatch", forbidden_batch)
    with pytest.raises(ValueError, match=message):
        drive_policy(policy, [[50.0, 0.0]], PARAMS, SOLVER, **kwargs)


@pytest.mark.parametrize("answer, message", [
    (np.full((1, 8), 0.5), r"^policy: action must hold only 0 and 1"),
    (np.zeros((1, 7)), r"^policy: action must have shape \(1, 8\)"),
])
def test_an_answer_that_is_no_action_is_refused_naming_the_policy(answer, message):
    with pytest.raises(ValueError, match=message):
        drive_policy(lambda obs: answer, [[50.0, 0.0]], PARAMS, SOLVER, max_cycles=1)


@pytest.mark.parametrize("below", [False, True])
def test_a_controller_stops_at_exactly_the_tolerance_and_not_a_hair_outside(below):
    """The environment's rule, distance <= tolerance: a tolerance equal to goal 0's distance
    at the first boundary stops it there; one a hair below drives it on."""
    boundaries, _ = replay(1, 0)
    goal = boundaries[1] + [0.0, 1.0]
    distance = np.hypot(*(goal - boundaries[1]))
    tolerance = np.nextafter(distance, 0.0) if below else distance
    summary, cycles, _ = drive_policy(lambda obs: np.tile(A1_A3, (1, 1)), [goal], PARAMS,
                                      SOLVER, tolerance_mm=tolerance, max_cycles=2,
                                      settle_cycles=0, frames_per_cycle=FRAMES)
    assert summary["terminated"].iloc[0] == (not below)
    assert cycles["gait"].iloc[1] == ("A1+A3" if below else "none")


def test_with_a_stop_speed_a_robot_swimming_through_is_driven_on():
    """Goal 0's case of `driven`: within the tolerance at the first boundary, but still
    swimming; with a stop speed below its speed the controller goes on to the budget."""
    boundaries, _ = replay(1, 0)
    goal = boundaries[1] + [0.0, 1.0]
    for stop_speed, stop in ((None, 1), (1e-3, 2)):
        summary, cycles, _ = drive_policy(lambda obs: np.tile(A1_A3, (1, 1)), [goal], PARAMS,
                                          SOLVER, tolerance_mm=2.0, max_cycles=2,
                                          settle_cycles=0, frames_per_cycle=FRAMES,
                                          stop_speed_mm_s=stop_speed)
        assert summary["run_cycles"].iloc[0] == stop
        assert summary["terminated"].iloc[0] == (stop_speed is None)


@pytest.mark.parametrize("settled, settle, max_cycles, terminated, stop, run", [
    (True, 2, 5, True, 1, 3),    # coasted 2 periods at boundary 3: stopped at 1, judged at 3
    (True, 3, 4, False, 4, 7),   # one period short of 3 there: on to the budget
    (False, 2, 5, True, 3, 5)])  # in passing at boundary 3: judged 2 periods later
def test_a_settled_controller_is_judged_where_its_episode_ended(settled, settle, max_cycles,
                                                                terminated, stop, run):
    """The policy fires A1+A3 once, then nothing; the goal lies 0.5 mm from where the robot
    is 3 boundaries in (tolerance 1 mm, outside it at every other boundary). With `settled` the
    task's episode ends there only after `settle` unfired periods, and the controller is deemed
    to have stopped that long before: its judgement at rest is the environment's success."""
    boundaries, _ = replay(1, 6)
    goal = boundaries[3] + [0.0, 0.5]
    others = np.delete(np.hypot(*(boundaries - goal).T), 3)
    assert others.min() > 1.0  # the robot glides > 0.5 mm a period
    answers = iter([A1_A3[None]])
    summary, cycles, _ = drive_policy(lambda obs: next(answers, np.zeros((1, 8))), [goal],
                                      PARAMS, SOLVER, tolerance_mm=1.0, max_cycles=max_cycles,
                                      settle_cycles=settle, frames_per_cycle=FRAMES,
                                      settled=settled)
    row = summary.iloc[0]
    assert row["terminated"] == terminated and row["run_cycles"] == run
    assert row["cycles_fired"] == 1
    assert row["final_error_mm"] == np.hypot(*(goal - boundaries[stop]))
    assert row["end_error_mm"] == np.hypot(*(goal - boundaries[run]))
    assert row["reached"] == (run == 3)
    if settled:
        assert row["reached"] == row["terminated"]
    assert cycles["cycle"].max() == stop + (settle if settled and terminated else 0)


@pytest.mark.parametrize("kwargs, message", [
    ({"settled": "yes"}, r"^settled must be True or False, got 'yes'"),
    ({"settled": True, "settle_cycles": 0}, r"^settled needs settle_cycles >= 1"),
])
def test_a_settling_is_refused_before_compute(monkeypatch, kwargs, message):
    monkeypatch.setattr(rollout, "GoalReachingBatch", forbidden_batch)
    with pytest.raises(ValueError, match=message):
        drive_policy(lambda obs: np.zeros((1, 8)), [[50.0, 0.0]], PARAMS, SOLVER, **kwargs)


def test_the_policy_sees_the_times_since_firing_capped_as_it_was_trained():
    """since_fired_cap_s is the task's: a never-fired actuator reads it (the observation's
    last 8 entries), here 20 s instead of the default 10 s."""
    observed = []

    def policy(observation):
        observed.append(observation.copy())
        return np.zeros((len(observation), 8))

    drive_policy(policy, [[50.0, 0.0]], PARAMS, SOLVER, max_cycles=1, settle_cycles=0,
                 since_fired_cap_s=20.0)
    np.testing.assert_array_equal(observed[0][0, -8:], np.full(8, 20.0, dtype=np.float32))
