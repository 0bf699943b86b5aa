"""The full model's lookahead controller (`taichi_star.lookahead`): what it reports is what a
robot firing its choices alone does, bit for bit; each choice is the candidate that comes to
rest nearest the goal, as candidates simulated one by one from the same present say; its
arguments are refused before compute; `compare_controllers` counts and averages as stated."""

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
from taichi_star.lookahead import (CONTROLLER_COLUMNS, LOOKAHEAD_CYCLE_COLUMNS,
                                   compare_controllers, every_gait, lookahead_drive)
from taichi_star.planner import PLAN_COLUMNS

PARAMS = ts.StarParams.preset("paper")
SOLVER = ts.SolverConfig(dt=5e-3)
SINGLES = [f"A{m}" for m in range(1, 9)]
GOALS = np.array([[-8.0, -3.0], [6.0, 0.5]])
SETTLE = 1


@pytest.fixture(scope="module")
def driven():
    return lookahead_drive(GOALS, PARAMS, SOLVER, tolerance_mm=1.0, max_cycles=3,
                           settle_cycles=SETTLE, gaits=SINGLES, frames_per_cycle=3)


def replay(gaits, coast):
    """A robot of its own firing `gaits` one per period, then coasting `coast` periods: its
    (x, y) mm at every period boundary and its records (3 a period)."""
    robot = ts.Simulator([PARAMS], SOLVER)
    boundaries, records = [robot.state()[["centroid_x_mm", "centroid_y_mm"]].to_numpy()[0]], []
    for gait in list(gaits) + ["none"] * coast:
        robot.fire([gait])
        records.append(robot.advance(PARAMS.period, record_interval_s=PARAMS.period / 3))
        boundaries.append(robot.state()[["centroid_x_mm", "centroid_y_mm"]].to_numpy()[0])
    return np.array(boundaries), pd.concat(records, ignore_index=True)


def test_a_robot_firing_the_choices_alone_goes_where_it_was_reported(driven):
    summary, cycles, path = driven
    assert list(summary.columns) == PLAN_COLUMNS and list(cycles.columns) == LOOKAHEAD_CYCLE_COLUMNS
    assert (summary["mode"] == "lookahead").all() and (cycles["mode"] == "lookahead").all()
    for goal in range(len(GOALS)):
        rows = cycles[cycles["goal"] == goal]
        stop = int(summary["run_cycles"].iloc[goal]) - SETTLE
        fired = rows["gait"].tolist()[:stop]
        assert "none" not in fired and rows["gait"].iloc[stop] == "none"
        assert summary["cycles_fired"].iloc[goal] == len(fired)
        boundaries, records = replay(fired, SETTLE + 1)
        # the state at each cycle boundary, then the rest it is judged at
        np.testing.assert_array_equal(rows[["x_mm", "y_mm"]].to_numpy(),
                                      boundaries[:len(rows)])
        at_rest = boundaries[stop + SETTLE]
        assert summary["end_error_mm"].iloc[goal] == np.hypot(*(GOALS[goal] - at_rest))
        assert summary["final_error_mm"].iloc[goal] == rows["distance_mm"].iloc[stop]
        assert summary["reached"].iloc[goal] == (summary["end_error_mm"].iloc[goal] <= 1.0)
        # the path: the robot's own records while it was driven
        own = path[path["goal"] == goal]
        driven_records = records[records["t_s"] <= stop * PARAMS.period + SOLVER.dt / 2]
        np.testing.assert_array_equal(
            own.loc[own["t_s"] > 0, ["x_mm", "y_mm"]].to_numpy()[:len(driven_records)],
            driven_records[["centroid_x_mm", "centroid_y_mm"]].to_numpy())
        assert own["controlled"].tolist() == (own["t_s"] <= stop * PARAMS.period + 1e-9).tolist()
        # each firing's predicted rest: the robot's, had it coasted from the next boundary on
        for cycle in range(len(fired)):
            rest, _ = replay(fired[:cycle + 1], SETTLE)
            np.testing.assert_array_equal(
                rows[["predicted_rest_x_mm", "predicted_rest_y_mm"]].to_numpy()[cycle],
                rest[-1])
        assert rows["predicted_rest_x_mm"].iloc[len(fired):].isna().all()


def test_each_choice_is_the_candidate_at_rest_nearest_the_goal(driven):
    """At the first cycle, from rest: each candidate on a robot of its own (the glide stays
    at rest, outside the tolerance: a gait is fired)."""
    _, cycles, _ = driven
    for goal in range(len(GOALS)):
        misses = []
        for gait in ["none"] + SINGLES:
            boundaries, _ = replay([gait], SETTLE)
            misses.append(np.hypot(*(GOALS[goal] - boundaries[-1])))
        first = cycles[(cycles["goal"] == goal) & (cycles["cycle"] == 0)].iloc[0]
        assert misses[0] > 1.0 and first["gait"] == (["none"] + SINGLES)[int(np.argmin(misses))]
        assert first["predicted_rest_error_mm"] == min(misses)


@pytest.mark.parametrize("tolerance, stops", [(15.5, True), (14.5, False)])
def test_it_stops_once_the_glide_comes_to_rest_within_the_tolerance(tolerance, stops):
    """A goal 15 mm beyond where one firing of A1+A3 from rest comes to rest, the glide's miss
    from the next cycle on: a tolerance above it stops there, though a second firing would land
    nearer; one below fires that second A1+A3."""
    boundaries, _ = replay(["A1+A3"], SETTLE + 1)
    rest = boundaries[1 + SETTLE]
    goal = rest + 15.0 * rest / np.hypot(*rest)
    _, cycles, _ = lookahead_drive([goal], PARAMS, SOLVER, tolerance_mm=tolerance,
                                   max_cycles=2, settle_cycles=SETTLE, gaits=["A1+A3", "A5"],
                                   frames_per_cycle=3)
    assert cycles["gait"].iloc[0] == "A1+A3"
    assert cycles["gait"].iloc[1] == ("none" if stops else "A1+A3")


def test_every_gait_is_the_glide_and_the_255_gaits_once():
    gaits = every_gait()
    assert gaits[0] == "none" and len(gaits) == 256 == len(set(gaits))
    assert gaits[1] == "A1" and gaits[-1] == "A1+A2+A3+A4+A5+A6+A7+A8"
    assert all(ts.Gait.parse(gait).name == gait for gait in gaits)


@pytest.mark.parametrize("kwargs, message", [
    ({"gaits": ["A1", "A1"]}, r"gaits names A1 more than once"),
    ({"gaits": ["none"]}, r"gaits must hold at least one gait that fires an actuator"),
    ({"gaits": "A1+A3"}, r"gaits must be a list of gaits"),
    ({"gaits": ["A9"]}, r"A9"),
    ({"max_cycles": 0}, r"max_cycles must be an integer >= 1"),
    ({"tolerance_mm": 7.0}, r"tolerance_mm = 7 mm reaches goal 1"),
    # past the step counter only with the lookahead's coasts (the planner's run is within it)
    ({"max_cycles": 2 * 10 ** 6}, r"max_cycles = 2000000 decisions of 2 periods .* the limit is"),
    ({"progress": "yes"}, r"progress must be True or False"),
])
def test_arguments_are_refused_before_compute(monkeypatch, kwargs, message):
    def forbidden(*args, **kw):
        raise AssertionError("a Simulator was built")
    monkeypatch.setattr("taichi_star.lookahead.Simulator", forbidden)
    arguments = {"params": PARAMS, "solver": SOLVER, "settle_cycles": SETTLE, **kwargs}
    with pytest.raises(ValueError, match=message):
        lookahead_drive(GOALS, **arguments)


def test_controllers_are_compared_over_the_goals_each_reached():
    summary = pd.DataFrame({
        "goal": [0, 1, 2, 0, 1, 2], "mode": ["closed"] * 3 + ["lookahead"] * 3,
        "reached": [True, True, False, True, True, True],
        "end_error_mm": [1.0, 2.0, 9.0, 0.5, 0.5, 2.0],
        "final_error_mm": [20.0, 21.0, 30.0, 10.0, 11.0, 12.0],
        "cycles_fired": [1, 2, 3, 2, 2, 2],
        "cycles_to_goal": [1.0, 3.0, np.nan, 2.0, 2.0, 5.0]})
    table = compare_controllers(summary)
    assert list(table.columns) == CONTROLLER_COLUMNS
    assert table["mode"].tolist() == ["closed", "lookahead"]
    assert table["reached"].tolist() == [2, 3] and table["goals"].tolist() == [3, 3]
    assert table["mean_end_error_mm"].tolist() == [4.0, 1.0]
    assert table["max_end_error_mm"].tolist() == [9.0, 2.0]
    # goal 2 is reached by the lookahead alone: left out of both means of cycles to the goal
    assert table["mean_cycles_to_goal"].tolist() == [2.0, 2.0]
    with pytest.raises(ValueError, match=r"summary must hold drive's"):
        compare_controllers(summary.drop(columns="cycles_fired"))
