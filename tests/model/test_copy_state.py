"""`Simulator.copy_state`: one robot's present given to others of the batch. The copies then
go on as the source does, bit for bit (a robot's results do not depend on its neighbours), and
under other commands as a robot with the source's history would: checked against robots that
lived that history themselves, with Newton's, the lagged (its kept factorisation) and the
adaptive accurate solver, a firing pending across the copy, sensitivities and failed robots."""

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts

PARAMS = ts.StarParams.preset("paper")


def states(sim):
    """state() without the instance column, one row per robot."""
    return sim.state().drop(columns="instance").reset_index(drop=True)


def history(sim, first):
    """The history every robot of these tests shares up to the copy: `first` fired at 0,
    A2+A4 pending at 0.4 s."""
    sim.fire(first)
    sim.advance(0.2)
    sim.fire([[0, 1, 0, 1, 0, 0, 0, 0]] * sim.n_instances, at_s=0.4)


@pytest.mark.parametrize("solver", [ts.SolverConfig(dt=2e-3),
                                    ts.SolverConfig(dt=2e-3, jacobian="lagged"),
                                    ts.SolverConfig.preset("accurate")],
                         ids=["newton", "lagged", "accurate"])
def test_copies_go_on_as_robots_that_lived_the_sources_history(solver):
    """Robots 3 and 4 live robot 0's history themselves (in the same batch, which changes no
    robot's bits: test_determinism), as references for the copies 1 and 2."""
    sim = ts.Simulator([PARAMS] * 5, solver)
    # the targets' own pasts differ from the source's (another firing, another time)
    history(sim, ["A1+A3", "A2", "none", "A1+A3", "A1+A3"])
    sim.copy_state(0, to=[1, 2])
    copied = states(sim)
    for target in (1, 2, 3):
        pd.testing.assert_series_equal(copied.iloc[target], copied.iloc[0], check_names=False)
    if solver.jacobian == "lagged":  # the kept factorisation too (its refactor would agree
        # with it to round-off, which the states above cannot tell apart)
        kept = sim.engine.save_state(factorisations=True)
        for name in ("factorisation.blocks", "factorisation.age"):
            for target in (1, 2):
                np.testing.assert_array_equal(kept[name][target], kept[name][0])
    # under the same commands as the source, and under another (a lookahead's candidate)
    sim.fire(["none", "none", "A5", "none", "A5"], at_s=0.6)
    sim.advance(0.5)
    after = states(sim)
    for copy, reference in ((1, 0), (0, 3), (2, 4)):
        pd.testing.assert_series_equal(after.iloc[copy], after.iloc[reference],
                                       check_names=False)
    assert after["centroid_x_mm"].iloc[2] != after["centroid_x_mm"].iloc[0]


def test_the_tangents_are_copied_with_the_state():
    """Robot 2 lives robot 0's history itself, robot 1 is its copy."""
    sim = ts.Simulator([PARAMS] * 3, ts.SolverConfig(dt=2e-3), sensitivities=("alpha",))
    history(sim, ["A1+A3", "A1+A2", "A1+A3"])
    sim.copy_state(0, to=1)
    sim.advance(0.3)
    for column in ("centroid_x_mm", "heading_deg", "velocity_y_mm_s"):
        derivatives = sim.sensitivity(column, "alpha")
        assert derivatives[1] == derivatives[0] == derivatives[2] != 0.0


def test_a_failed_robots_state_fails_its_copies_and_a_running_one_revives_it():
    """A1 fails at 0.15 s with these steps (test_simulator's failed robot); a copy of it is
    failed too (fire ignores it), and one of a running robot runs again."""
    solver = ts.SolverConfig(dt=0.05, max_newton=7, max_substep_halvings=0)
    sim = ts.Simulator([PARAMS] * 3, solver)
    sim.fire(["A1", "A1+A2", "none"])
    sim.advance(1.0)
    assert sim.ok.tolist() == [False, True, True]
    sim.copy_state(0, to=2)
    assert sim.ok.tolist() == [False, True, False]
    sim.fire(["none", "none", "A3"])            # ignored by the failed copy, as by its source
    records = sim.advance(0.1, record_interval_s=0.05)
    after = states(sim)
    pd.testing.assert_series_equal(after.iloc[2], after.iloc[0], check_names=False)
    # its records at the times its clock would show, as its source's (NaN measured columns)
    by_robot = [records[records["instance"] == b].drop(columns="instance").reset_index(drop=True)
                for b in (0, 2)]
    pd.testing.assert_frame_equal(by_robot[1], by_robot[0])
    assert by_robot[0]["t_s"].tolist() == pytest.approx([1.05, 1.1])
    sim.copy_state(1, to=[0])
    assert sim.ok.tolist() == [True, True, False]
    sim.fire(["A3", "A3", "none"])
    sim.advance(0.1)
    after = states(sim)
    pd.testing.assert_series_equal(after.iloc[0], after.iloc[1], check_names=False)
    assert after["since_A3_s"].iloc[0] == pytest.approx(0.1)


@pytest.mark.parametrize("source, to, message", [
    (3, None, r"source must be an instance of the batch, an integer in \[0, 3\), got 3"),
    (-1, None, r"source must be .* got -1"),
    (True, None, r"source must be .* got True"),
    (1.0, None, r"source must be .* got 1.0"),
    (0, [1, 3], r"to must be an integer or a sequence of integers in \[0, 3\), got \[1, 3\]"),
    (0, [1, 1], r"to names instance 1 more than once"),
    (0, [2, 0], r"to names the source, instance 0, among its targets"),
    (0, 0, r"to names the source, instance 0"),
])
def test_what_is_not_a_copy_between_robots_of_the_batch_is_refused(source, to, message):
    sim = ts.Simulator([PARAMS] * 3, ts.SolverConfig(dt=2e-3))
    sim.fire(["A1+A3", "none", "none"])
    sim.advance(0.1)
    before = states(sim)
    with pytest.raises(ValueError, match=message):
        sim.copy_state(source, to)
    pd.testing.assert_frame_equal(states(sim), before)


def test_targets_of_other_parameters_need_other_params_and_keep_their_own():
    """Another α: the same masses and rest shape, so the same present shows the source's
    displacement and velocity to the bit, and another stroke follows."""
    other = PARAMS.replace(alpha=0.5)
    sim = ts.Simulator([PARAMS, other, PARAMS], ts.SolverConfig(dt=2e-3))
    sim.fire(["A1+A3", "none", "none"])
    sim.advance(0.1)
    before = states(sim)
    with pytest.raises(ValueError, match=r"instance 1's alpha is 0.5, the source's \(instance "
                                         r"0\) 0.8 \(1 field\(s\) differ\): copy_state\(\.\.\., "
                                         r"other_params=True\)"):
        sim.copy_state(0)
    pd.testing.assert_frame_equal(states(sim), before)
    sim.copy_state(0, other_params=True)
    copied = states(sim)
    for column in ("centroid_x_mm", "centroid_y_mm", "velocity_x_mm_s", "since_A1_s"):
        assert copied[column].iloc[1] == copied[column].iloc[0]
    sim.advance(0.2)
    after = states(sim)
    pd.testing.assert_series_equal(after.iloc[2], after.iloc[0], check_names=False)
    # the same present under α = 0.5: a stroke of its own
    assert after["centroid_x_mm"].iloc[1] != after["centroid_x_mm"].iloc[0]
    assert after["t_s"].iloc[1] == after["t_s"].iloc[0]


def test_with_sensitivities_a_copy_between_other_parameters_is_refused_even_when_asked():
    sim = ts.Simulator([PARAMS, PARAMS.replace(drag_perpendicular=2.0)],
                       ts.SolverConfig(dt=2e-3), sensitivities=("alpha",))
    with pytest.raises(ValueError, match=r"drag_perpendicular .* a Simulator with "
                                         r"sensitivities copies a state only between instances "
                                         r"of the same parameters"):
        sim.copy_state(0, other_params=True)


def test_no_targets_is_nothing_and_other_params_must_be_a_flag():
    sim = ts.Simulator([PARAMS] * 2, ts.SolverConfig(dt=2e-3))
    sim.fire(["A1+A3", "none"])
    sim.advance(0.1)
    before = states(sim)
    sim.copy_state(0, to=[])
    pd.testing.assert_frame_equal(states(sim), before)
    with pytest.raises(ValueError, match=r"other_params must be True or False, got 'yes'"):
        sim.copy_state(0, other_params="yes")
    assert not np.isnan(before["since_A1_s"].iloc[0]) and np.isnan(before["since_A1_s"].iloc[1])


def test_a_target_of_another_shape_goes_on_as_a_load_of_the_sources_state_would():
    """With another tip radius the target's masses and rest shape are its own: its centroid,
    heading and displacement are measured as `load(snapshot, other_params=True)` of the
    source's state into a robot of its parameters measures them, to the bit, then and after."""
    other = PARAMS.replace(alpha=0.5, tip_radius=0.06)
    solver = ts.SolverConfig(dt=2e-3)
    sim = ts.Simulator([PARAMS, other], solver)
    sim.fire(["A1+A3", "A2"])
    sim.advance(0.1)
    sim.copy_state(0, other_params=True)
    source = ts.Simulator([PARAMS], solver)
    source.fire(["A1+A3"])
    source.advance(0.1)
    loaded = ts.Simulator([other], solver)
    loaded.load(source.save(), other_params=True)
    for _ in range(2):
        pd.testing.assert_series_equal(states(sim).iloc[1], states(loaded).iloc[0],
                                       check_names=False)
        sim.advance(0.1)
        loaded.advance(0.1)
