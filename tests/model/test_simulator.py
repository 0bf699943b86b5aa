"""The stateful Simulator: commands, piecewise advance, save/load and reset are bitwise
consistent with each other and with `simulate`; bad commands leave the state unchanged; the
step_batch example runs."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts

REPO = Path(__file__).resolve().parents[2]
PERIOD = 0.4
PARAMS = [ts.StarParams(gait=g, period=PERIOD) for g in ("A1+A2", "A3", "A1+A3+A5")]
GAITS = [p.gait for p in PARAMS]


def commanded(params=PARAMS, **solver):
    return ts.Simulator([p.replace(gait="none") for p in params], ts.SolverConfig(**solver))


def test_scheduled_periodic_firing_reproduces_simulate_bitwise():
    """simulate fires the gait at t = 0 and at every k·T (the step ending at k·T already sees
    K̄(0)); the same schedule given as commands must give the same bits."""
    reference = ts.simulate(PARAMS, 3 * PERIOD, record_interval_s=3 * PERIOD, record_shapes=True)
    sim = commanded()
    sim.fire(GAITS)
    for k in (1, 2, 3):
        sim.fire(GAITS, at_s=k * PERIOD)
        sim.advance(PERIOD)
    np.testing.assert_array_equal(sim.shapes(), reference.shapes[-1])
    state = sim.state()
    np.testing.assert_array_equal(state.centroid_x_mm, reference.summary.displacement_x_mm)
    np.testing.assert_allclose(state.t_s, 3 * PERIOD)
    # the scheduled firing at 3T has just happened: 0 s since A1 for the gaits that hold it
    assert state.since_A1_s.iloc[0] == 0.0 and np.isnan(state.since_A1_s.iloc[1])


def test_one_advance_equals_pieces_equals_save_and_load():
    def run(pieces, snapshot_at=None):
        sim = commanded()
        sim.fire(GAITS)
        snapshot = None
        for index, piece in enumerate(pieces):
            sim.advance(piece)
            if index == snapshot_at:
                snapshot = sim.save()
        return sim, snapshot

    whole, _ = run([3 * PERIOD])
    pieces, snapshot = run([PERIOD, PERIOD, PERIOD], snapshot_at=0)
    np.testing.assert_array_equal(whole.shapes(), pieces.shapes())
    fresh = commanded()
    fresh.load(snapshot)
    fresh.advance(2 * PERIOD)
    np.testing.assert_array_equal(fresh.shapes(), whole.shapes())
    pd.testing.assert_frame_equal(fresh.state(), whole.state(), check_exact=True)


def test_save_to_file_and_load(tmp_path):
    sim = commanded()
    sim.fire(GAITS)
    sim.advance(0.1)
    path = sim.save(tmp_path / "state")
    later = sim.shapes()
    sim.advance(0.1)
    after = sim.shapes()
    sim.load(path)
    np.testing.assert_array_equal(sim.shapes(), later)
    sim.advance(0.1)
    np.testing.assert_array_equal(sim.shapes(), after)


def test_different_command_sequences_in_one_batch_equal_each_alone():
    """Instance b's sequence of commands gives the same bits alone and next to others."""
    sequences = [["A1", "A2+A3", "none"], ["A5+A6", "none", "A1+A5"], ["none", "A8", "A4"]]
    batch = commanded()
    for step in range(3):
        batch.fire([sequence[step] for sequence in sequences])
        batch.advance(0.15)
    for b, sequence in enumerate(sequences):
        alone = commanded(PARAMS[b:b + 1])
        for step in range(3):
            alone.fire([sequence[step]])
            alone.advance(0.15)
        np.testing.assert_array_equal(alone.shapes()[0], batch.shapes()[b])


def test_reset_puts_instances_back_at_rest_and_leaves_others():
    sim = commanded()
    sim.fire(GAITS)
    sim.advance(0.1)
    before = sim.shapes()
    sim.reset([1])
    state = sim.state()
    assert state.t_s.tolist() == [pytest.approx(0.1), 0.0, pytest.approx(0.1)]
    np.testing.assert_array_equal(sim.shapes()[[0, 2]], before[[0, 2]])
    np.testing.assert_array_equal(sim.shapes()[1], commanded().shapes()[1])
    assert state.iloc[1][list(ts.simulator.ACTUATOR_COLUMNS)].isna().all()


def test_firing_a_hot_actuator_restarts_its_profile():
    """Firing again at 50 ms (inside the heating pulse) restarts τ at 0, and the arc's natural
    curvature jumps back towards K̄(0): the robot's motion differs from a single firing."""
    sim = commanded(PARAMS[:1])
    sim.fire(["A1"])
    sim.advance(0.05)
    sim.fire(["A1"])
    assert sim.state().since_A1_s.iloc[0] == 0.0
    sim.advance(0.05)
    assert sim.state().since_A1_s.iloc[0] == pytest.approx(0.05)
    once = commanded(PARAMS[:1])
    once.fire(["A1"])
    once.advance(0.1)
    assert np.abs(once.shapes() - sim.shapes()).max() > 1e-6


def test_heading_and_angular_velocity_of_a_turning_gait():
    """An asymmetric gait turns the body: heading changes and its rate has the sign of the turn
    (checked against the heading's finite difference over the last record)."""
    sim = commanded(PARAMS[:1])
    sim.fire(["A1+A2+A4"])  # no mirror symmetry: it turns
    records = sim.advance(0.3, record_interval_s=0.01)
    heading = records.heading_deg.to_numpy()
    assert np.abs(heading).max() > 1e-3
    rate = np.gradient(heading, 0.01)
    np.testing.assert_allclose(records.angular_velocity_deg_s.iloc[-5], rate[-5],
                               rtol=0.1, atol=1e-3)


@pytest.mark.parametrize("commands,match", [
    (np.zeros((3, 7), dtype=bool), "shape"),
    (np.full((3, 8), 0.5), "dtype"),
    (["A1", "A2"], "one gait per instance"),
    (["A1", "A9", "none"], "unknown actuator"),
])
def test_bad_commands_are_refused_and_leave_the_state_unchanged(commands, match):
    sim = commanded()
    sim.fire(GAITS)
    sim.advance(0.02)
    before = sim.save()
    with pytest.raises(ValueError, match=match):
        sim.fire(commands)
    for name, values in sim.save().fields.items():
        np.testing.assert_array_equal(values, before.fields[name])


def test_bad_durations_times_and_foreign_states_are_refused():
    sim = commanded()
    sim.advance(0.01)
    for duration in (-1.0, 0.0, float("nan")):
        with pytest.raises(ValueError, match="duration_s"):
            sim.advance(duration)
    with pytest.raises(ValueError, match="at_s"):
        sim.fire(GAITS, at_s=0.005)
    with pytest.raises(ValueError, match="at_s"):
        sim.fire(GAITS, at_s=0.0105)
    # now itself is refused (a firing at now is `fire` without at_s); one step later is accepted
    with pytest.raises(ValueError, match=r"at_s = 0.01 s is not after the current time"):
        sim.fire(GAITS, at_s=0.01)
    sim.fire(["A1"] * 3, at_s=0.011)
    assert (sim.engine.state.scheduled_fire_step.to_numpy()[:3, 0] == 11).all()
    # one pending firing per actuator: the same time again is a no-op, another time is refused
    # (it used to replace the first silently), another actuator is free, and once the first
    # has fired the next may be scheduled
    sim.fire(["A1"] * 3, at_s=0.011)
    with pytest.raises(ValueError, match=r"actuator A1 of instance 0 already has a firing "
                                         r"pending at 0.011 s"):
        sim.fire(["A1"] * 3, at_s=0.02)
    sim.fire(["A2"] * 3, at_s=0.02)
    sim.advance(0.001)  # the step ending at 0.011 s fires A1
    assert (sim.engine.state.scheduled_fire_step.to_numpy()[:3, 0] == -1).all()
    sim.fire(["A1"] * 3, at_s=0.02)
    assert (sim.engine.state.scheduled_fire_step.to_numpy()[:3, :2] == 20).all()
    other = ts.Simulator([ts.StarParams(n_arc=12)] * 3)
    with pytest.raises(ValueError, match="another engine"):
        sim.load(other.save())


class _Accepted(Exception):
    """Raised by a stand-in engine.advance: the call passed every check before compute."""


def test_work_beyond_the_step_counter_is_refused_before_any_compute(monkeypatch):
    """After 10 steps of 1 ms, advance may take MAX_STEPS_PER_INSTANCE − 10 more steps (2³¹ − 1
    in all, the int32 counter), not one more; a firing may be scheduled at step 2³¹ − 1, not
    one later (this used to be an OverflowError writing the int32 table)."""
    sim = commanded()
    sim.advance(0.01)
    limit = ts.MAX_STEPS_PER_INSTANCE

    def accepted(count):
        raise _Accepted
    monkeypatch.setattr(sim.engine, "advance", accepted)
    with pytest.raises(_Accepted):
        sim.advance((limit - 10) * 1e-3)
    with pytest.raises(ValueError, match=rf"duration_s = 2.14748e\+06 s at dt = 0.001 s \(after the "
                                         rf"10 steps taken\) is 2.15e\+09 time steps per instance "
                                         rf"\(6.44e\+09 robot-steps for 3 instances\); the limit "
                                         rf"is {limit}"):
        sim.advance((limit - 9) * 1e-3)
    with pytest.raises(ValueError, match=r"duration_s = 1e\+09 s .* 1e\+12 time steps"):
        sim.advance(1e9)
    before = sim.save().fields
    with pytest.raises(ValueError, match=r"at_s = 3000000.0 s \(at most 2.14748e\+06 s at dt = "
                                         r"0.001 s\) is 3e\+09 time steps"):
        sim.fire(GAITS, at_s=3e6)
    with pytest.raises(ValueError, match=r"at_s = .* is 2.15e\+09 time steps"):
        sim.fire(GAITS, at_s=(limit + 1) * 1e-3)
    after = sim.save().fields
    assert all(np.array_equal(after[name], before[name]) for name in before)
    sim.fire(GAITS, at_s=limit * 1e-3)
    assert (sim.engine.state.scheduled_fire_step.to_numpy()[:3][np.array(
        [ts.Gait.parse(g).mask for g in GAITS], dtype=bool)] == limit).all()


def test_step_batch_example_runs():
    environment = dict(os.environ, STEP_BATCH_QUICK="1", PYTHONPATH=str(REPO))
    result = subprocess.run([sys.executable, str(REPO / "examples" / "step_batch.py")],
                            capture_output=True, text=True, env=environment, cwd=REPO,
                            timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "robots" in result.stdout


def test_adaptive_simulator_lands_on_scheduled_firings_and_matches_simulate():
    """With adaptive steps the scheduled firings become step ends (like simulate's cycle
    starts): the same periodic schedule gives simulate's bits; records land on their times."""
    solver = ts.SolverConfig.preset("accurate")
    params = [p.replace(n_arc=18) for p in PARAMS[:2]]
    reference = ts.simulate(params, 2 * PERIOD, solver, record_interval_s=2 * PERIOD,
                            record_shapes=True)
    sim = ts.Simulator([p.replace(gait="none") for p in params], solver)
    sim.fire(GAITS[:2])
    sim.fire(GAITS[:2], at_s=PERIOD)
    sim.advance(PERIOD)
    sim.fire(GAITS[:2], at_s=2 * PERIOD)
    sim.advance(PERIOD)
    np.testing.assert_array_equal(sim.shapes(), reference.shapes[-1])
    # records are stops too (each one changes the step sequence, so not compared bitwise)
    sim.reset()
    sim.fire(GAITS[:2])
    records = sim.advance(PERIOD, record_interval_s=PERIOD / 4)
    np.testing.assert_allclose(records.t_s.unique(), PERIOD / 4 * np.arange(1, 5), rtol=1e-12)
