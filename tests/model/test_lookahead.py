"""The full model's lookahead controller (`taichi_star.lookahead`): what it reports is what a
robot firing its choices alone does, bit for bit; each choice is the candidate that comes to
rest nearest the goal, as candidates simulated one by one from the same present say; a run
killed after a decision continues from its checkpoint bit for bit, and a checkpoint of another
run is refused; its arguments are refused before compute; `compare_controllers` counts and
averages as stated."""

import shutil

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
import taichi_star.lookahead as lookahead_module
from taichi_star.lookahead import (CONTROLLER_COLUMNS, LOOKAHEAD_CYCLE_COLUMNS,
                                   compare_controllers, every_gait, lookahead_drive)
from taichi_star.planner import PLAN_COLUMNS

PARAMS = ts.StarParams.preset("paper")
SOLVER = ts.SolverConfig(dt=5e-3)
SINGLES = [f"A{m}" for m in range(1, 9)]
GOALS = np.array([[-8.0, -3.0], [6.0, 0.5]])
SETTLE = 1


ARGUMENTS = {"tolerance_mm": 1.0, "max_cycles": 3, "settle_cycles": SETTLE, "gaits": SINGLES,
             "frames_per_cycle": 3}
"""`driven`'s run: 3 decisions (2 advances each: the period, the coast), then a settling one."""


@pytest.fixture(scope="module")
def driven():
    return lookahead_drive(GOALS, PARAMS, SOLVER, **ARGUMENTS)


def counted_run(checkpoint, monkeypatch, stop_at=None):
    """(`driven`'s run with `checkpoint`, how many advances its Simulator made); with
    `stop_at`, stopped by a KeyboardInterrupt at the start of that advance (a kill: nothing
    after it runs)."""
    real = ts.Simulator.advance
    calls = []

    def advance(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == stop_at:
            raise KeyboardInterrupt
        return real(self, *args, **kwargs)

    with monkeypatch.context() as patch:
        patch.setattr(ts.Simulator, "advance", advance)
        return lookahead_drive(GOALS, PARAMS, SOLVER, checkpoint=checkpoint, **ARGUMENTS), \
            len(calls)


def killed_run(checkpoint, monkeypatch, advances: int):
    with pytest.raises(KeyboardInterrupt):
        counted_run(checkpoint, monkeypatch, stop_at=advances)


@pytest.fixture(scope="module")
def checkpoint_after_one_decision(tmp_path_factory):
    folder = tmp_path_factory.mktemp("checkpoint")
    with pytest.MonkeyPatch.context() as patch:
        killed_run(folder / "run.npz", patch, advances=3)
    return folder / "run.npz"


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


# killed in the second decision, and in the coast after the last (its checkpoint's decision
# fires nothing: every controller stopped at max_cycles)
@pytest.mark.parametrize("advances, next_cycle", [(3, 1), (7, 3)])
def test_a_killed_run_continues_from_its_checkpoint_bit_for_bit(driven, tmp_path, monkeypatch,
                                                                advances, next_cycle):
    checkpoint = tmp_path / "run.npz"
    killed_run(checkpoint, monkeypatch, advances)
    with np.load(checkpoint) as archive:
        assert f'"next_cycle": {next_cycle},' in str(archive["__lookahead__"])
    continued, advanced = counted_run(checkpoint, monkeypatch)
    for table, expected in zip(continued, driven):
        pd.testing.assert_frame_equal(table, expected)
    # the decisions before the checkpoint are not made again (7 advances in the whole run)
    assert advanced == 7 - 2 * next_cycle


def test_a_finished_runs_checkpoint_stays_and_gives_the_same_run_again(driven, tmp_path,
                                                                       monkeypatch):
    checkpoint = tmp_path / "run.npz"
    _, advanced = counted_run(checkpoint, monkeypatch)
    assert advanced == 7
    with np.load(checkpoint) as archive:  # the last decision's, where every controller stopped
        assert '"next_cycle": 3,' in str(archive["__lookahead__"])
    again, advanced = counted_run(checkpoint, monkeypatch)
    for table, expected in zip(again, driven):
        pd.testing.assert_frame_equal(table, expected)
    assert advanced == 1  # the settling coast alone


def test_a_checkpoint_of_another_code_version_goes_on_with_a_warning(
        driven, checkpoint_after_one_decision, tmp_path, monkeypatch):
    checkpoint = shutil.copy(checkpoint_after_one_decision, tmp_path / "run.npz")
    monkeypatch.setattr(lookahead_module, "code_version", lambda: {"version": "other"})
    with pytest.warns(RuntimeWarning, match=r"another version of the code .*'commit'.* goes on "
                                            r"under this one \({'version': 'other'}\)"):
        continued = lookahead_drive(GOALS, PARAMS, SOLVER, checkpoint=checkpoint, **ARGUMENTS)
    for table, expected in zip(continued, driven):
        pd.testing.assert_frame_equal(table, expected)


def without_entry(path, entry, tmp_path):
    """A copy of the checkpoint whose archive lacks `entry` (the rest as it was)."""
    with np.load(path) as archive:
        arrays = {name: archive[name] for name in archive.files if name != entry}
    copy = tmp_path / f"without_{entry.replace(':', '_')}.npz"
    np.savez(copy, **arrays)
    return copy


@pytest.mark.parametrize("damage, message", [
    ("cut", r"not a lookahead's checkpoint \(BadZipFile; a damaged file"),
    ("fired", r"a damaged file \(next cycle 1 of at most 3, fired missing or misshapen\)"),
    ("paths:t_s", r"paths:t_s missing"),
    ("__lookahead__", r"not a lookahead's checkpoint \(KeyError"),
])
def test_a_damaged_checkpoint_is_refused_before_compute(checkpoint_after_one_decision, tmp_path,
                                                        monkeypatch, damage, message):
    if damage == "cut":  # the archive's directory, at its end, lost
        checkpoint = tmp_path / "cut.npz"
        checkpoint.write_bytes(checkpoint_after_one_decision.read_bytes()[:-100])
    else:
        checkpoint = without_entry(checkpoint_after_one_decision, damage, tmp_path)
    monkeypatch.setattr(lookahead_module, "Simulator", forbidden_simulator)
    with pytest.raises(ValueError, match=message):
        lookahead_drive(GOALS, PARAMS, SOLVER, checkpoint=checkpoint, **ARGUMENTS)


@pytest.mark.parametrize("kwargs, message", [
    ({"tolerance_mm": 1.5}, r"belongs to another lookahead: tolerance_mm is 1.0 there, 1.5 here"),
    ({"gaits": SINGLES[:-1]}, r"belongs to another lookahead: gaits is \['none', 'A1', .*'A8'\] "
                              r"there, \['none', .*'A7'\] here"),
    ({"params": PARAMS.replace(alpha=PARAMS.alpha * (1 + 1e-16) + 1e-16)},
     r"belongs to another lookahead: params is"),
    ({"goals_mm": GOALS[::-1]}, r"belongs to another lookahead: goals_mm is"),
])
def test_a_checkpoint_of_another_run_is_refused_and_left_as_it_was(
        checkpoint_after_one_decision, monkeypatch, kwargs, message):
    before = checkpoint_after_one_decision.read_bytes()
    monkeypatch.setattr(lookahead_module, "Simulator", forbidden_simulator)
    arguments = {"goals_mm": GOALS, "params": PARAMS, "solver": SOLVER, **ARGUMENTS, **kwargs}
    with pytest.raises(ValueError, match=message):
        lookahead_drive(checkpoint=checkpoint_after_one_decision, **arguments)
    assert checkpoint_after_one_decision.read_bytes() == before


def forbidden_simulator(*args, **kwargs):
    raise AssertionError("a Simulator was built")


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
    ({"checkpoint": 3}, r"path must be the path of the lookahead's checkpoint file"),
    ({"checkpoint": "{tmp}"}, r"checkpoint '.*' is a folder: give the checkpoint's file"),
    ({"checkpoint": "{tmp}/no/run.npz"}, r"its folder '.*/no' does not exist"),
    ({"checkpoint": "{tmp}/text.npz"}, r"not a lookahead's checkpoint \(ValueError; a damaged "),
])
def test_arguments_are_refused_before_compute(monkeypatch, tmp_path, kwargs, message):
    monkeypatch.setattr(lookahead_module, "Simulator", forbidden_simulator)
    (tmp_path / "text.npz").write_text("not an archive")
    if isinstance(kwargs.get("checkpoint"), str):
        kwargs = {"checkpoint": kwargs["checkpoint"].format(tmp=tmp_path)}
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


def test_progress_is_one_bar_over_the_runs_periods(driven, capsys):
    """`driven`'s run: 3 decisions of 2 periods, then 1 of coasting: 7 periods, the bar's
    total shrunk to them where the run stops before max_cycles would allow more (none here)."""
    lookahead_drive(GOALS, PARAMS, SOLVER, progress=True, **ARGUMENTS)
    error = capsys.readouterr().err
    assert "lookahead, 2 goals x 9 candidates" in error
    assert "7/7 periods" in error and "decision 3, driving 2 of 2" in error
    assert "coasting to rest" in error and "robots" not in error  # no bar of each advance


def test_without_progress_no_bar_shows_however_long_its_advances(monkeypatch, capsys):
    """A Simulator.advance left to decide shows a bar when it is estimated long (the batch of
    every goal's candidates over a period, ~35 s with every gait): here every advance counts
    as long, and the lookahead asked for no bar shows none."""
    monkeypatch.setattr("taichi_star.driver.AUTO_PROGRESS_S", 0.0)
    lookahead_drive(GOALS[:1], PARAMS, SOLVER, tolerance_mm=1.0, max_cycles=1,
                    settle_cycles=SETTLE, gaits=["A1+A3"], frames_per_cycle=3)
    assert capsys.readouterr().err == ""


def test_a_run_that_stops_early_ends_its_bar_at_the_periods_it_ran(capsys):
    """The 15.5-mm tolerance case above with max_cycles 4 (a schedule of 9 periods): two
    decisions of 2 periods, the second choosing the glide, then 1 of coasting."""
    boundaries, _ = replay(["A1+A3"], SETTLE + 1)
    rest = boundaries[1 + SETTLE]
    goal = rest + 15.0 * rest / np.hypot(*rest)
    lookahead_drive([goal], PARAMS, SOLVER, tolerance_mm=15.5, max_cycles=4,
                    settle_cycles=SETTLE, gaits=["A1+A3", "A5"], frames_per_cycle=3,
                    progress=True)
    error = capsys.readouterr().err
    assert "5/5 periods" in error and "/9 periods" in error
    assert "decision 2, driving 1 of 1" in error and "decision 3" not in error
