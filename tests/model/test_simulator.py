"""The stateful Simulator: commands, piecewise advance, save/load and reset are bitwise
consistent with each other and with `simulate`; bad commands leave the state unchanged; the
step_batch example runs."""

import dataclasses
import gc
import math
import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
from taichi_star.simulator import SimulatorSnapshot
from taichi_star.state import LATER_COUNTERS

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


def test_simulate_and_simulators_share_engines_but_never_one_in_use():
    """A Simulator made after a `simulate` of the same topology, terms and integrator takes that
    call's engine (no compilation); a call made while the Simulator lives takes another and
    leaves the Simulator's state alone; the shared engine gives the same bits as the call."""
    from taichi_star.model import build_model
    from taichi_star.runtime import Runtime

    reference = ts.simulate(PARAMS, 3 * PERIOD, record_interval_s=3 * PERIOD, record_shapes=True)
    runtime = Runtime.current()
    slots = runtime.engines[runtime.engine_key(build_model(PARAMS), ts.SolverConfig())]
    free = [slot.engine for slot in slots if not slot.held()]
    sim = commanded()
    assert any(sim.engine is engine for engine in free)
    sim.fire(GAITS)
    sim.fire(GAITS, at_s=PERIOD)
    sim.advance(PERIOD)
    halfway = sim.shapes()
    again = ts.simulate(PARAMS, PERIOD)  # while sim lives: another engine (free or new)
    assert any(slot.engine is sim.engine and slot.held() for slot in slots)
    np.testing.assert_array_equal(sim.shapes(), halfway)
    for k in (2, 3):
        sim.fire(GAITS, at_s=k * PERIOD)
        sim.advance(PERIOD)
    np.testing.assert_array_equal(sim.shapes(), reference.shapes[-1])
    assert (again.summary["status"] == "ok").all()
    engine = sim.engine
    del sim  # gone: its engine is free for the next call or Simulator
    assert not any(slot.engine is engine and slot.held() for slot in slots)


@pytest.mark.parametrize("in_a_cycle", [False, True])
def test_a_simulator_let_go_hands_its_engine_on_without_a_build(monkeypatch, in_a_cycle):
    """A Simulator dropped while a reference cycle still held it (a caught exception's
    traceback keeps the frame that made it) held its engine until the collector ran, and the
    next Simulator of its batch built another, seconds of compilation: the runtime collects
    before it builds. Dropped plainly, it goes at once. The batch's engines are this one alone
    (the file's other engines of its key, free, would take the next Simulator either way)."""
    from taichi_star.model import build_model
    from taichi_star.runtime import Runtime

    runtime = Runtime.current()
    first = commanded()
    engine = first.engine
    key = runtime.engine_key(build_model(PARAMS), ts.SolverConfig())
    (slot,) = (slot for slot in runtime.engines[key] if slot.engine is engine)
    monkeypatch.setattr(runtime, "engines", {key: [slot]})
    built = []
    new_engine = runtime.new_engine
    monkeypatch.setattr(runtime, "new_engine",
                        lambda *args: built.append(args) or new_engine(*args))
    gc.disable()
    try:
        if in_a_cycle:
            first.own_cycle = [first]
        del first
        assert slot.held() is in_a_cycle  # the collector has not run
        second = commanded()
    finally:
        gc.enable()
    assert second.engine is engine and built == []


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
    del pieces  # its engine goes on to `fresh` (not a build: the suite's time)
    fresh = commanded()
    fresh.load(snapshot)
    fresh.advance(2 * PERIOD)
    np.testing.assert_array_equal(fresh.shapes(), whole.shapes())
    pd.testing.assert_frame_equal(fresh.state(), whole.state(), check_exact=True)


def test_save_to_file_and_load_and_a_failed_overwrite_keeps_the_file(tmp_path, full_disk):
    """A snapshot file continues bitwise; writing another over it that fails at the disk (fsync
    reports it full, before the rename) leaves it byte for byte as it was, and nothing beside
    it."""
    sim = commanded()
    sim.fire(GAITS)
    sim.advance(0.1)
    path = sim.save(tmp_path / "state")
    written = path.read_bytes()
    later = sim.shapes()
    sim.advance(0.1)
    after = sim.shapes()
    with full_disk():
        with pytest.raises(OSError, match="No space left"):
            sim.save(path)
    assert path.read_bytes() == written
    assert [p.name for p in tmp_path.iterdir()] == ["state.npz"]
    sim.load(path)
    np.testing.assert_array_equal(sim.shapes(), later)
    sim.advance(0.1)
    np.testing.assert_array_equal(sim.shapes(), after)


def test_a_state_saved_before_the_factorisations_were_counted_loads_and_counts_from_zero(
        tmp_path):
    """A snapshot written without the `factorisations` counter (an earlier version's) loads,
    continues bitwise as the current one does, and counts the factorisations from the load
    on; any other missing field is still refused by name."""
    sim = commanded()
    sim.fire(GAITS)
    sim.advance(0.05)
    current = sim.save()
    counted = current.fields["factorisations"][:sim.n_instances]
    assert (counted > 0).all()
    earlier = dataclasses.replace(current, fields={
        name: values for name, values in current.fields.items() if name != "factorisations"})
    sim.advance(0.05)
    after = sim.shapes()
    total = sim.save().fields["factorisations"][:sim.n_instances]
    sim.load(earlier.write(tmp_path / "earlier"))
    sim.advance(0.05)
    np.testing.assert_array_equal(sim.shapes(), after)
    np.testing.assert_array_equal(sim.save().fields["factorisations"][:sim.n_instances],
                                  total - counted)
    # a state saved before any of the later counters (steps_over_tolerance too) loads and
    # continues the same way
    earliest = dataclasses.replace(current, fields={
        name: values for name, values in current.fields.items() if name not in LATER_COUNTERS})
    assert set(current.fields) - set(earliest.fields) == {"factorisations",
                                                          "steps_over_tolerance"}
    sim.load(earliest.write(tmp_path / "earliest"))
    sim.advance(0.05)
    np.testing.assert_array_equal(sim.shapes(), after)
    broken = dataclasses.replace(current, fields={
        name: values for name, values in current.fields.items() if name != "newton_total"})
    with pytest.raises(ValueError, match="saved state has fields"):
        sim.load(broken)


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


def test_reset_drops_the_firings_pending_for_the_robots_it_resets():
    """A firing commanded with at_s for a robot that is then reset never comes (reset: nothing
    fired, nothing pending); the same firing of a robot not reset comes at its time."""
    sim = commanded()
    sim.fire(GAITS, at_s=0.05)
    sim.reset([1])
    sim.advance(0.1)
    fired = sim.state()[list(ts.simulator.ACTUATOR_COLUMNS)]
    assert fired.iloc[1].isna().all()
    for robot in (0, 2):
        since = fired.iloc[robot].dropna()
        # 0.05 s to the rounding of step counts × dt (1e-12 s: far below a step)
        assert len(since) > 0 and np.allclose(since, 0.05, rtol=0.0, atol=1e-12)


def test_a_firing_on_a_failed_step_never_happened_in_the_state():
    """A firing due at the end of a step that fails is recorded by the schedule but never
    drove the robot: state() reads the time since the firing before, as the bending term does
    (since_A1_s was time − the failed firing's time, < 0, until a fuzz audit, 2026-12). Fixed
    20-ms steps of 6 Newton iterations (5 until Newton stopped only on an update within
    newton_tol, 2026-12), no substeps: A1 fired at 0.02 s runs; fired again at
    0.2 s (τ = 0.18 s, the profile's trough, back to K̄(0)) the step fails, and the frozen state
    at 0.18 s is 0.16 s after the first firing. A robot whose first firing fails (one
    iteration) has fired nothing: NaN, on fixed steps and adaptive ones alike."""
    robot = [ts.StarParams(n_arc=6, n_limb=2)]
    a1 = [[True] + [False] * 7]
    simulator = ts.Simulator(robot, ts.SolverConfig(dt=0.02, max_newton=6,
                                                    max_substep_halvings=0))
    simulator.fire(a1, at_s=0.02)
    simulator.advance(0.18)
    simulator.fire(a1, at_s=0.2)
    simulator.advance(0.1)
    state = simulator.state().iloc[0]
    assert (state.status, state.failure_time_s, state.t_s) == ("newton_failed", 0.2, 0.18)
    assert state.since_A1_s == 0.18 - 0.02
    for solver in (ts.SolverConfig(dt=0.02, max_newton=1, max_substep_halvings=0),
                   ts.SolverConfig(adaptive=True, dt=0.02, dt_max=0.02, dt_min=5e-3,
                                   max_newton=1, error_tol=1e-3)):
        simulator = ts.Simulator(robot, solver)
        simulator.advance(0.04)
        simulator.fire([[True] * 8], at_s=0.1)
        simulator.advance(0.2)
        state = simulator.state().iloc[0]
        assert state.status == "newton_failed" and state.failure_time_s == 0.1
        assert state.t_s < 0.1
        assert np.isnan(simulator.state().filter(like="since_").to_numpy()).all()


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


def run_two_firings(solver, params, queued_ahead, pieces):
    """A1 fired at 0.05 s and at 0.2 s: both queued at the start (`queued_ahead`) or the second
    once 0.1 s is reached; advanced by `pieces` (s). Returns the final shapes and state."""
    sim = ts.Simulator([params.replace(gait="none")], solver)
    sim.fire(["A1"], at_s=0.05)
    if queued_ahead:
        sim.fire(["A1"], at_s=0.2)
    for piece in pieces:
        if not queued_ahead and sim.time_s[0] == pytest.approx(0.1):
            sim.fire(["A1"], at_s=0.2)
        sim.advance(piece)
    return sim.shapes(), sim.state()


@pytest.mark.parametrize("preset", ["paper", "accurate"])
def test_an_actuator_holds_several_pending_firings_and_fires_each(preset):
    """fire(A1, at_s=0.05); fire(A1, at_s=0.2) fires both: the same bits as scheduling 0.2 s
    once 0.05 s has fired (it used to keep only the last firing, which equals firing at 0.2 s
    alone). With fixed steps every firing ends the same step whatever the pieces, so the
    queued run advances at once; adaptive steps end on every stop (0.1 s here) as well as on
    the firings, so both runs advance by the same pieces and take the same steps."""
    solver = ts.SolverConfig.preset(preset)
    params = PARAMS[0] if preset == "paper" else PARAMS[0].replace(n_arc=18)
    queued_pieces = [0.3] if preset == "paper" else [0.1, 0.2]
    shapes, state = run_two_firings(solver, params, True, queued_pieces)
    expected_shapes, expected_state = run_two_firings(solver, params, False, [0.1, 0.2])
    np.testing.assert_array_equal(shapes, expected_shapes)
    pd.testing.assert_frame_equal(state, expected_state, check_exact=True)
    assert state.since_A1_s.iloc[0] == pytest.approx(0.1, abs=1e-12)
    late_only = ts.Simulator([params.replace(gait="none")], solver)
    late_only.fire(["A1"], at_s=0.2)
    late_only.advance(0.3)
    assert np.abs(late_only.shapes() - shapes).max() > 1e-6


def test_pending_firings_up_to_the_capacity_then_refused_until_one_has_fired():
    """An instance holds PENDING_CAPACITY pending times: one more is a ValueError naming the
    capacity (state unchanged), the same time again only adds actuators, and once a firing has
    happened its place is free. Every firing happens at its step (since = 0 there)."""
    capacity = ts.actuation.PENDING_CAPACITY
    sim = commanded(PARAMS[:1])
    for step in range(1, capacity + 1):
        sim.fire(["A1"], at_s=step * 1e-3)
    sim.fire(["A2"], at_s=5e-3)
    before = sim.save().fields
    with pytest.raises(ValueError, match=rf"at_s = 0.017 s: instance 0 already has {capacity} "
                                         rf"firings pending, the most it holds "
                                         rf"\(PENDING_CAPACITY\)"):
        sim.fire(["A1"], at_s=(capacity + 1) * 1e-3)
    after = sim.save().fields
    assert all(np.array_equal(after[name], before[name]) for name in before)
    first = sim.advance(1e-3, record_interval_s=1e-3)
    sim.fire(["A1"], at_s=(capacity + 1) * 1e-3)
    rest = sim.advance(0.02 - 1e-3, record_interval_s=1e-3)
    since_a1 = np.concatenate([first.since_A1_s, rest.since_A1_s])
    steps = np.arange(1, 21)
    np.testing.assert_allclose(since_a1, np.where(steps <= capacity + 1, 0.0,
                                                  (steps - capacity - 1) * 1e-3), atol=1e-12)
    since_a2 = np.concatenate([first.since_A2_s, rest.since_A2_s])
    assert np.isnan(since_a2[:4]).all()
    np.testing.assert_allclose(since_a2[4:], (steps[4:] - 5) * 1e-3, atol=1e-12)


def test_pending_firings_travel_with_save_and_load(tmp_path):
    """A snapshot holds the firings still pending: loaded (from memory or a file), the run goes
    on to fire them, bitwise as the run that was saved."""
    sim = commanded(PARAMS[:1])
    sim.fire(["A1"], at_s=0.05)
    sim.fire(["A1+A2"], at_s=0.2)
    sim.advance(0.1)
    snapshot = sim.save()
    path = sim.save(tmp_path / "pending")
    sim.advance(0.2)
    expected_shapes, expected_state = sim.shapes(), sim.state()
    assert expected_state.since_A2_s.iloc[0] == pytest.approx(0.1, abs=1e-12)
    for source in (snapshot, path):
        sim.load(source)
        sim.advance(0.2)
        np.testing.assert_array_equal(sim.shapes(), expected_shapes)
        pd.testing.assert_frame_equal(sim.state(), expected_state, check_exact=True)


def test_velocities_are_the_backward_differences_of_every_step():
    """An asymmetric gait turns the body, recorded every 1-ms step from rest. Implicit Euler's
    velocity is its step's backward difference, (q_n − q_{n−1})/h, and the centroid is linear
    in the nodes: the centroid velocity is the centroid's backward difference to round-off. The
    angular velocity (the mean of the hub-to-joint arms' rates) follows the heading's backward
    difference (the rate of the arms' circular mean) within 5 % of its largest value, with the
    sign of the turn wherever it turns at more than 5 % of that."""
    dt = 1e-3
    sim = commanded(PARAMS[:1])
    sim.fire(["A1+A2+A4"])  # no mirror symmetry: it turns
    records = sim.advance(0.3, record_interval_s=dt)
    assert len(records) == 300

    def backward_difference(column):
        return np.diff(np.concatenate([[0.0], records[column].to_numpy()])) / dt  # 0 at rest

    assert np.abs(records.heading_deg).max() > 1e-3
    # ~5-cm positions round at 7e-18 m: two roundings over 1 ms are 1.4e-11 mm/s per node
    # (measured 7e-12 mm/s on the centroid, against speeds of a few mm/s)
    for axis in ("x", "y"):
        np.testing.assert_allclose(records[f"velocity_{axis}_mm_s"],
                                   backward_difference(f"centroid_{axis}_mm"), rtol=0, atol=1e-10)
    spin = records.angular_velocity_deg_s.to_numpy()
    turn = backward_difference("heading_deg")
    # the two means differ while the heating spreads the arms' turns: 2.4 % of the largest rate
    # at h = 1 ms and 2.5 % at 0.25 ms (measured), a difference of definitions, not of the step
    largest = np.abs(spin).max()
    np.testing.assert_allclose(spin, turn, rtol=0, atol=0.05 * largest)
    turning = np.abs(spin) > 0.05 * largest
    assert turning.sum() > 100
    np.testing.assert_array_equal(np.sign(spin[turning]), np.sign(turn[turning]))


def test_commands_of_zeros_and_ones_of_any_number_type_or_gaits_in_any_sequence_fire_alike():
    """NumPy's own arrays are floats (np.ones((B, 8))): they were refused, though the
    environments take float 0./1. actions (an audit, 2026-12); each fires as its booleans.
    The gaits of a table's column (a pandas Series) or an array of texts were refused for
    their shape, (B,), which was right (an audit, 2026-12): each fires as the list."""
    masks = np.array([[1, 0, 1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0, 0, 0],
                      [1, 0, 1, 0, 1, 0, 0, 0]])
    gaits = ["A1+A3", "A2", "A1+A3+A5"]
    shapes = []
    for commands in (masks.astype(bool), masks.astype(np.float64), masks.astype(np.int8),
                     gaits, pd.Series(gaits, index=[7, 8, 9]), np.array(gaits),
                     np.array(gaits, dtype=object)):
        sim = commanded()
        sim.fire(commands)
        sim.advance(0.01)
        shapes.append(sim.shapes())
        del sim
    for fired in shapes[1:]:
        np.testing.assert_array_equal(fired, shapes[0])


@pytest.mark.parametrize("commands,match", [
    (np.zeros((3, 7), dtype=bool), "shape"),
    (np.full((3, 8), 0.5), "dtype"),
    (["A1", "A2"], "one gait per instance"),
    (pd.Series(["A1", "A2"]), "one gait per instance"),
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
    for interval in (float("inf"), -0.01, float("nan")):
        with pytest.raises(ValueError, match=r"^record_interval_s must be a finite number > 0 s"):
            sim.advance(0.01, record_interval_s=interval)
    before = sim.save().fields
    sim.reset([])   # no instance: a plain empty list (float to NumPy) is accepted, nothing reset
    sim.reset(np.array([], dtype=int))
    assert all(np.array_equal(sim.save().fields[name], before[name]) for name in before)
    with pytest.raises(ValueError, match=r"instances must be an integer or a sequence of integers in \[0, 3\), got \[0.5\]"):
        sim.reset([0.5])
    # a bool among the integers (NumPy reads [0, True] as [0, 1]) and an instance named twice
    # (both accepted: an audit, 2026-12); refused before anything is reset
    with pytest.raises(ValueError, match=r"instances must be an integer or a sequence of "
                                         r"integers in \[0, 3\), got \[0, True\]"):
        sim.reset([0, True])
    with pytest.raises(ValueError, match=r"^instances names instance 0 more than once, got "
                                         r"\[0, 0, 1\]$"):
        sim.reset([0, 0, 1])
    with pytest.raises(ValueError, match=r"at_s = 0.005 s is not after the current time of "
                                         r"instance 0 \(0.01 s\)"):
        sim.fire(GAITS, at_s=0.005)
    with pytest.raises(ValueError, match="at_s must be a whole number of steps"):
        sim.fire(GAITS, at_s=0.0105)
    # now itself is refused (a firing at now is `fire` without at_s); one step later is accepted
    with pytest.raises(ValueError, match=r"at_s = 0.01 s is not after the current time"):
        sim.fire(GAITS, at_s=0.01)
    after = sim.save().fields
    assert all(np.array_equal(after[name], before[name]) for name in before)
    sim.fire(["A1"] * 3, at_s=0.011)
    assert (sim.engine.state.schedule.pending_due.to_numpy()[:3, 0] == 11).all()
    # another topology: the coarse robot of this file's other tests, whose engine is built
    # already (a topology of its own compiled one for this line alone: the suite's time)
    other = ts.Simulator([ts.StarParams(n_arc=6, n_limb=2)] * 3)
    with pytest.raises(ValueError, match="another engine"):
        sim.load(other.save())
    # pending firings are step numbers with fixed steps, times with adaptive ones: a state of
    # one stepping is refused by the other
    adaptive = commanded(adaptive=True)
    with pytest.raises(ValueError, match=r"another engine .*'fixed'\) vs .*'adaptive'\)"):
        adaptive.load(sim.save())


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
    schedule = sim.engine.state.schedule
    assert (schedule.pending_count.to_numpy()[:3] == 1).all()
    assert (schedule.pending_due.to_numpy()[:3, 0] == limit).all()
    np.testing.assert_array_equal(schedule.pending_actuators.to_numpy()[:3, 0],
                                  [ts.Gait.parse(g).bits for g in GAITS])


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
    # the boundaries of "after now" with adaptive steps: now and before it are refused
    for late in (PERIOD, PERIOD - 0.01):
        with pytest.raises(ValueError, match=rf"at_s = {late:g} s is not after the current "
                                             rf"time of instance 0 \(0.4 s\)"):
            sim.fire(GAITS[:2], at_s=late)
    # a firing is a step end: closer than dt_min after now would force a shorter step (dt_min
    # itself, the shortest allowed, is fired at the end: the same bits below need the schedule
    # as simulate's); past the step counter at dt_max, a firing is never reached
    now, dt_min = sim.time_s[0], solver.dt_min
    with pytest.raises(ValueError, match=rf"^at_s = {now + dt_min / 2:.9g} s is less than dt_min "
                                         rf"= {dt_min:g} s after the current time of instance 0"):
        sim.fire(GAITS[:2], at_s=now + dt_min / 2)
    with pytest.raises(ValueError, match=r"^at_s = 1e\+300 s \(at most .* s at dt_max"):
        sim.fire(GAITS[:2], at_s=1e300)
    sim.fire(GAITS[:2], at_s=2 * PERIOD)
    sim.advance(PERIOD)
    np.testing.assert_array_equal(sim.shapes(), reference.shapes[-1])
    # records are stops too (each one changes the step sequence, so not compared bitwise)
    sim.reset()
    sim.fire(GAITS[:2])
    records = sim.advance(PERIOD, record_interval_s=PERIOD / 4)
    np.testing.assert_allclose(records.t_s.unique(), PERIOD / 4 * np.arange(1, 5), rtol=1e-12)
    sim.fire(GAITS[:2], at_s=sim.time_s[0] + dt_min)


def test_a_state_of_other_parameters_is_refused_naming_them_unless_asked_for(tmp_path):
    """A snapshot records its instances' parameters: loaded into instances of other ones, the
    positions would go on under other coefficients, rest shape and start centroids, as no run
    did (measured: every status "ok", x −0.285 mm where the saved run has 0.023 mm). The gait,
    which a Simulator does not use, may differ; `other_params=True` loads on purpose."""
    # one simulator alive at a time: each takes the engine the last one left (no compilation)
    saved = commanded()
    saved.fire(GAITS)
    saved.advance(0.01)
    path = saved.save(tmp_path / "state")
    snapshot = saved.save()
    saved.advance(0.01)
    later = saved.shapes()
    params = saved.params
    del saved
    same = ts.Simulator(PARAMS)
    same.load(path)  # only the gait differs ("none" there)
    same.advance(0.01)
    np.testing.assert_array_equal(same.shapes(), later)
    del same
    other = ts.Simulator([params[0], params[1].replace(alpha=1.7), params[2]])
    before = other.save().fields
    for source in (path, snapshot):
        with pytest.raises(ValueError, match=r"^the saved state belongs to instances of other "
                                             r"parameters: instance 1's alpha is 0.8 there, "
                                             r"1.7 here \(1 field\(s\) differ\); "):
            other.load(source)
    # a damaged header recording the first instance alone: zip compared it alone and loaded
    # the state of instance 1's alpha 0.8 under 1.7 (an audit)
    short = dataclasses.replace(snapshot, params=snapshot.params[:1])
    with pytest.raises(ValueError, match=r"^the saved state records the parameters of 1 "
                                         r"instances for its 3 \(a damaged snapshot\)$"):
        other.load(short)
    after = other.save().fields
    assert all(np.array_equal(after[name], before[name]) for name in before)
    # a header without parameters skipped the comparison without a word (an audit): loaded
    # with a warning that they cannot be compared; silently with other_params=True
    bare = dataclasses.replace(snapshot, params=())
    with pytest.warns(RuntimeWarning, match=r"^the saved state records no parameters, so they "
                                            r"cannot be compared"):
        other.load(bare)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        other.load(bare, other_params=True)
    other.load(path, other_params=True)
    np.testing.assert_array_equal(other.time_s, [0.01] * 3)


def test_a_snapshot_of_a_version_without_a_field_holds_its_default(tmp_path):
    """A snapshot saved before a field was added (no record of it) was refused as of other
    parameters ("is not recorded there") even where this simulator's value is the field's
    default, which the saved run had (an audit, 2026-12): it loads, without a warning, and goes
    on bit for bit; where this side's value is not the default, it is refused naming the
    default. The same for the solver's settings (a warning then)."""
    saved = commanded()
    saved.fire(GAITS)
    saved.advance(0.01)
    snapshot = saved.save()
    saved.advance(0.01)
    later = saved.shapes()
    params = saved.params
    del saved
    older = dataclasses.replace(
        snapshot, params=tuple({k: v for k, v in texts.items() if k != "cylinder_drag"}
                               for texts in snapshot.params),
        solver={k: v for k, v in snapshot.solver.items() if k != "max_newton"})
    same = ts.Simulator(PARAMS)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        same.load(older)
    same.advance(0.01)
    np.testing.assert_array_equal(same.shapes(), later)
    del same
    default = ts.StarParams().cylinder_drag
    other = ts.Simulator([params[0], params[1].replace(cylinder_drag=2 * default), params[2]])
    with pytest.raises(ValueError, match=re.escape(
            f"instance 1's cylinder_drag is not recorded: {default!r} there, "
            f"{2 * default!r} here (1 field(s) differ)")):
        other.load(older)
    del other
    stepped = ts.Simulator(PARAMS, ts.SolverConfig(max_newton=30))
    with pytest.warns(RuntimeWarning, match=r"^the saved state was stepped with max_newton = "
                                            r"not recorded: 25, this simulator's is 30"):
        stepped.load(older)


def test_a_state_stepped_under_other_solver_settings_loads_with_a_warning_naming_them(tmp_path):
    """Settings outside the engine's key (Newton's tolerance and iteration cap, the Jacobian
    mode, ...) do not stop a load, but the continuation is not the saved run's bit for bit:
    a warning names the first that differs and counts them; the same settings load silently,
    and so does a snapshot that records none (written before they were)."""
    saved = commanded(newton_tol=1e-9, max_newton=30)
    saved.fire(GAITS)
    saved.advance(0.01)
    snapshot, times = saved.save(), saved.time_s
    path = saved.save(tmp_path / "state")
    assert snapshot.solver["newton_tol"] == "1e-09" and snapshot.solver["max_newton"] == "30"
    del saved  # its engine goes to the next simulator
    other = commanded()
    for source in (path, snapshot):
        with pytest.warns(RuntimeWarning, match=r"^the saved state was stepped with newton_tol "
                                                r"= 1e-09, this simulator's is 1e-10 \(2 "
                                                r"setting\(s\) differ\): it goes on under "):
            other.load(source)
        np.testing.assert_array_equal(other.time_s, times)
    unrecorded = dataclasses.replace(snapshot, solver={})
    own = other.save()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        other.load(own)
        other.load(unrecorded)


def test_a_snapshot_without_parameters_loads_as_before(tmp_path):
    """Snapshots written before the parameters were recorded hold none: they load with a
    warning that the parameters cannot be compared (the engine, batch size and step are still
    checked)."""
    sim = commanded()
    sim.advance(0.01)
    snapshot, times, params = sim.save(), sim.time_s, sim.params
    del sim  # its engine goes to the next simulator
    earlier = ts.SimulatorSnapshot(fields=snapshot.fields, engine_key=snapshot.engine_key,
                                   n_instances=snapshot.n_instances, dt=snapshot.dt)
    other = ts.Simulator([p.replace(alpha=2.0) for p in params])
    with pytest.warns(RuntimeWarning, match="records no parameters"):
        other.load(earlier.write(tmp_path / "earlier"))
    np.testing.assert_array_equal(other.time_s, times)
    # the name it was saved under, without the ".npz" write added (numpy's "No such file")
    other.load(tmp_path / "earlier", other_params=True)
    with pytest.raises(ValueError, match=r"^snapshot .*missing.npz: cannot read it \(No such"):
        other.load(tmp_path / "missing")
    # a file that is there under a name without the suffix (renamed) is read as named
    (tmp_path / "earlier.npz").rename(tmp_path / "renamed")
    other.advance(0.01)
    other.load(tmp_path / "renamed", other_params=True)
    np.testing.assert_array_equal(other.time_s, times)


def test_an_advance_without_records_returns_a_table_of_the_recorded_types():
    """Its empty table had untyped columns (object), and a concatenation with recorded tables
    turned their numbers into objects (an audit, 2026-12)."""
    sim = commanded()
    recorded = sim.advance(0.01, record_interval_s=0.005)
    empty = sim.advance(0.005)
    assert empty.empty and list(empty.columns) == list(recorded.columns)
    pd.testing.assert_series_equal(empty.dtypes, recorded.dtypes)
    assert pd.concat([recorded, empty]).dtypes.equals(recorded.dtypes)


def test_mixed_commands_and_a_missing_folder_are_named_in_plain_words(tmp_path):
    """A gait beside a mask is neither form of `commands` (NumPy's "inhomogeneous shape" was
    the message); saving into a folder that does not exist names the file asked for, not the
    temporary beside it."""
    sim = commanded()
    before = sim.save().fields
    with pytest.raises(ValueError, match=r"^commands must be a \(3, 8\) boolean array or a list "
                                         r"of 3 gaits, got a mixture that is neither$"):
        sim.fire(["A1", np.zeros(8, dtype=bool), "A3"])
    # a single gait was "got shape ()" (an audit, 2026-12)
    for single in ("A1+A3", ts.Gait.parse("A1+A3")):
        with pytest.raises(ValueError, match=r"^commands must be a list of 3 gaits, one per "
                                             r"instance, got the single gait 'A1\+A3': "
                                             r"\['A1\+A3'\] \* 3 fires it on every instance$"):
            sim.fire(single)
    # None for "no firing", the first one named (it was "got shape (3,)")
    for commands, first in ((["A1", None, None], 1), ([None] * 3, 0)):
        with pytest.raises(ValueError, match=rf"^commands\[{first}\] is None: give every "
                                             rf"instance a gait, 'none' for no firing"):
            sim.fire(commands)
    assert all(np.array_equal(sim.save().fields[name], before[name]) for name in before)
    with pytest.raises(OSError, match=r"^cannot write state.npz: its folder .*missing does not "
                                      r"exist$"):
        sim.save(tmp_path / "missing" / "state")
    assert not (tmp_path / "missing").exists()


def _capped_warnings(caught):
    return [str(w.message) for w in caught if "newton_capped" in str(w.message)]


def test_advance_names_ok_robots_whose_newton_solves_were_capped_once_until_reset():
    """simulate warned about "ok" instances whose Newton solves used all max_newton iterations
    (a result that can be far off: docs/numerics.md, "What ok promises"); the Simulator, the
    environments and the planner said nothing, and state() could not tell (an audit,
    2026-12: limbs of 2e-5 m, allowed, came out 9 % off a run at newton_tol 1e-13 with status
    ok). Now state() has newton_capped and advance warns once per robot, again after a
    reset."""
    paper = ts.StarParams(gait="A1+A3")
    tiny_limbs = paper.replace(tip_radius=paper.joint_radius + 2e-5)
    sim = ts.Simulator([paper, tiny_limbs])
    sim.fire(["A1+A3", "A1+A3"])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sim.advance(0.01)
        first = _capped_warnings(caught)
        sim.advance(0.01)  # the same robot again: already named
        second = _capped_warnings(caught)[len(first):]
    assert len(first) == 1 and first[0].startswith(
        "1 of 2 f64 instances (the first: instance 1) are 'ok' only after a Newton solve used "
        "all its 25 iterations (newton_capped)"), first
    assert second == []
    state = sim.state()
    assert state["status"].tolist() == ["ok", "ok"]
    assert state["newton_capped"].tolist() == [False, True]
    # a loaded run's capped solves are its history (state() shows them), not news: a new
    # Simulator that loads it names them no more than the one that ran it
    resumed = ts.Simulator([paper, tiny_limbs])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        resumed.load(sim.save())
        resumed.advance(0.01)
    assert _capped_warnings(caught) == []
    assert resumed.state()["newton_capped"].tolist() == [False, True]
    del resumed
    sim.reset(1)  # a single index resets one robot (it said "must be integers ..., got 1")
    assert sim.state()["newton_capped"].tolist() == [False, False]
    sim.fire(["none", "A1+A3"])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sim.advance(0.01)
    assert len(_capped_warnings(caught)) == 1


def test_a_failed_robot_shows_its_failure_time_ignores_commands_and_has_no_derivative():
    """A robot whose solve fails beside one that goes on (50-ms steps, Newton capped at 7
    iterations, no substeps: A1 fails at 0.15 s; 5 iterations and one halving did it until
    Newton stopped only on an update within newton_tol, 2026-12): state() had no failure time
    (t_s is the last good state's), sensitivity() gave the frozen state's finite derivative
    where simulate gives NaN, and a fire() it is documented to ignore showed in since_A3_s (an
    audit, 2026-12). Each now as simulate has it."""
    params = ts.StarParams.preset("paper")
    solver = ts.SolverConfig(dt=0.05, max_newton=7, max_substep_halvings=0)
    reference = ts.simulate([params.replace(gait="A1"), params.replace(gait="A1+A2")], 1.0,
                            solver, sensitivities=["alpha"], progress=False)
    assert reference.summary["status"].tolist()[1] == "ok"
    assert reference.summary["status"].tolist()[0] != "ok"
    sim = ts.Simulator([params, params], solver, sensitivities=["alpha"])
    sim.fire(["A1", "A1+A2"])
    sim.advance(1.0)
    state = sim.state()
    assert state["status"].tolist() == reference.summary["status"].tolist()
    assert state["failure_time_s"].iloc[0] == reference.summary["failure_time_s"].iloc[0]
    assert state["t_s"].iloc[0] < state["failure_time_s"].iloc[0]  # the last good state's
    assert np.isnan(state["failure_time_s"].iloc[1])
    derivative = sim.sensitivity("centroid_x_mm", "alpha")
    assert np.isnan(derivative[0]) and np.isfinite(derivative[1])
    assert np.isnan(reference.sensitivity("displacement_x_mm", "alpha")[0])
    since_before = sim.state()["since_A3_s"].tolist()
    failed = sim.save()
    sim.fire(["A3", "A3"])
    since_after = sim.state()["since_A3_s"].tolist()
    assert np.isnan(since_before[0]) and np.isnan(since_after[0])  # the failed one: ignored
    assert since_after[1] == 0.0  # the running one fired now
    sim.reset(0)  # running again: it takes commands
    sim.fire(["A3", "none"])
    assert sim.state()["since_A3_s"].iloc[0] == 0.0
    sim.load(failed)  # failed again, as saved: ignores them
    sim.fire(["A2", "none"])
    assert np.isnan(sim.state()["since_A2_s"].iloc[0])
    # a heading's derivative goes the short way round ±180° (state() wraps headings there,
    # and without the column's name the difference took the long way: a mutation audit,
    # 2026-12): the replicas of the running robot read 179.9° and -179.9°
    headings = np.array([0.0, 0.0, 179.9, 179.9, -179.9, -179.9])  # robots, +ε, −ε replicas
    sim._state_of = lambda count: pd.DataFrame({"heading_deg": headings[:count]})
    derivative = sim.sensitivity("heading_deg", "alpha")
    assert np.isnan(derivative[0])
    assert derivative[1] == pytest.approx(-0.2 / (2 * sim._steps_of_directions[0, 1]),
                                          rel=1e-9)


def test_a_failed_robots_records_are_at_the_record_times_with_nan_as_in_simulate():
    """advance's records of a robot failed by then: the record's time, like its neighbour's,
    and NaN where simulate's trajectory has NaN (they repeated its frozen state and frozen
    time, so a table pivoted on t_s had duplicate entries: an audit, 2026-12); its status and
    failure time stay, also in a later advance (its clock stopped at the failure) and until a
    reset starts its clock again. The same robots and solver as the test above."""
    params = ts.StarParams.preset("paper")
    solver = ts.SolverConfig(dt=0.05, max_newton=7, max_substep_halvings=0)
    reference = ts.simulate([params.replace(gait="A1"), params.replace(gait="A1+A2")], 1.0,
                            solver, record_interval_s=0.2, progress=False)
    sim = ts.Simulator([params, params], solver)
    sim.fire(["A1", "A1+A2"])
    records = pd.concat([sim.advance(0.4, record_interval_s=0.2),
                         sim.advance(0.6, record_interval_s=0.2)], ignore_index=True)
    failed, running = records[records.instance == 0], records[records.instance == 1]
    assert (failed["status"] == "newton_failed").all() and (running["status"] == "ok").all()
    np.testing.assert_array_equal(failed["t_s"], running["t_s"])
    expected = reference.trajectory[reference.trajectory.t_s > 0]
    np.testing.assert_array_equal(running["t_s"], expected[expected.instance == 0]["t_s"])
    measured = ["centroid_x_mm", "centroid_y_mm", "heading_deg", "velocity_x_mm_s",
                "velocity_y_mm_s", "angular_velocity_deg_s", "since_A1_s"]
    assert failed[measured].isna().all().all()
    assert expected[expected.instance == 0][["x_mm", "y_mm"]].isna().all().all()
    np.testing.assert_array_equal(running["centroid_x_mm"],
                                  expected[expected.instance == 1]["x_mm"])
    assert (failed["failure_time_s"] == reference.summary["failure_time_s"].iloc[0]).all()
    assert records.pivot(index="t_s", columns="instance", values="centroid_x_mm").shape == (5, 2)
    sim.reset(0)  # its clock starts again at 0, the other's goes on
    assert sim.advance(0.1, record_interval_s=0.05)["t_s"].tolist() == [0.05, 1.05, 0.1, 1.1]


def test_a_failed_robots_clock_goes_through_a_save_and_a_load(tmp_path):
    """A snapshot records how far each failed robot's clock lags (its records' times): loaded,
    into the same Simulator or another, from memory or a file, the next records are at the
    uninterrupted run's times (they fell back to the frozen clock: an audit, 2026-12); a
    snapshot whose lags do not fit its instances is refused as damaged. The robots of the
    tests above."""
    import json as json_module

    params = ts.StarParams.preset("paper")
    solver = ts.SolverConfig(dt=0.05, max_newton=7, max_substep_halvings=0)

    def started():
        sim = ts.Simulator([params, params], solver)
        sim.fire(["A1", "A1+A2"])
        sim.advance(0.4)
        return sim

    sim = started()
    assert sim.state()["status"].tolist() == ["newton_failed", "ok"]
    saved, path = sim.save(), sim.save(tmp_path / "state.npz")
    expected = sim.advance(0.6, record_interval_s=0.2)
    np.testing.assert_allclose(expected["t_s"], [0.6, 0.6, 0.8, 0.8, 1.0, 1.0])
    for snapshot in (saved, path):
        for target in (sim, started()):
            target.load(snapshot)
            pd.testing.assert_frame_equal(target.advance(0.6, record_interval_s=0.2), expected)
    header = SimulatorSnapshot.read(path)
    damaged = dataclasses.replace(header, behind=header.behind[:1])
    with pytest.raises(ValueError, match=r"^the saved state records 1 clock lags for its 2 "
                                         r"instances"):
        sim.load(damaged)
    assert json_module.loads(str(np.load(path)["__header__"]))["behind"] == list(header.behind)


def test_an_adaptive_failed_robots_records_fall_on_its_neighbours_times(tmp_path):
    """With adaptive steps a failed robot's clock was its frozen time plus a lag, summed in
    another order than a running robot's start + stop: two advances after its failure its
    record fell an ulp or two off (0.43000000000000005 against 0.42999999999999994), and a
    table pivoted on t_s split the time (an audit, 2026-12). Its clock is now kept as a running
    robot's is, also through a save and a load, from memory and from a file."""
    params = ts.StarParams.preset("paper")
    solver = ts.SolverConfig(adaptive=True, integrator="bdf2", dt=0.01, dt_min=0.01,
                             dt_max=0.05, max_newton=5, max_substep_halvings=0, error_tol=1e-4)
    sim = ts.Simulator([params, params], solver)
    sim.fire(["A1", "none"])
    sim.advance(0.03)
    sim.advance(0.3)
    assert sim.state()["status"].tolist() == ["newton_failed", "ok"]
    saved, path = sim.save(), sim.save(tmp_path / "state.npz")
    records = sim.advance(0.1, record_interval_s=0.1)
    assert records["t_s"].iloc[0] == records["t_s"].iloc[1] == 0.03 + 0.3 + 0.1
    for snapshot in (saved, path):
        sim.load(snapshot)
        pd.testing.assert_frame_equal(sim.advance(0.1, record_interval_s=0.1), records)
    damaged = dataclasses.replace(saved, shown_s=saved.shown_s[:1])
    with pytest.raises(ValueError, match=r"^the saved state records 1 clock times for its 2 "
                                         r"instances"):
        sim.load(damaged)


def test_advances_off_the_step_grid_say_the_time_each_simulates():
    """Ten advance(0.0015) at 1-ms steps advance 0.02 s, not 0.015 (each rounded to 2 steps):
    each call says so, and one on the grid says nothing."""
    sim = ts.Simulator([ts.StarParams()])
    with pytest.warns(RuntimeWarning, match=r"duration_s = 0.0015 s is not a whole number of "
                                            r"steps \(dt = 0.001 s\): 2 steps, 0.002 s"):
        sim.advance(0.0015)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sim.advance(0.003)
    assert sim.time_s.tolist() == [0.005]


def test_an_interrupted_advance_counts_its_steps_and_knows_who_failed(monkeypatch):
    """Ctrl-C in an advance skipped its bookkeeping: the steps taken were not in `timing`,
    and a robot that failed before the interrupt went on taking commands (`fire` reads the
    statuses kept from the last advance: an audit, 2026-12). Both now as after a whole
    advance. The robots of the test above; 20 steps of 50 ms, then the interrupt."""
    from taichi_star import simulator as simulator_module

    params = ts.StarParams.preset("paper")
    solver = ts.SolverConfig(dt=0.05, max_newton=7, max_substep_halvings=0)
    sim = ts.Simulator([params, params], solver)
    sim.fire(["A1", "A1+A2"])

    def interrupted(engine, *args, **kwargs):
        engine.advance(20)
        raise KeyboardInterrupt
    monkeypatch.setattr(simulator_module, "drive", interrupted)
    with pytest.raises(KeyboardInterrupt):
        sim.advance(5.0)
    monkeypatch.undo()
    state = sim.state()
    assert state["status"].tolist()[1] == "ok" and state["status"].tolist()[0] != "ok"
    taken = np.rint(state["t_s"].to_numpy() / solver.dt).astype(int)
    assert taken[1] == 20 and sim.timing.robot_steps == taken.sum()
    sim.fire(["A3", "A3"])
    since = sim.state()["since_A3_s"].tolist()
    assert np.isnan(since[0]) and since[1] == 0.0
    # the failed robot's records go on at the others' clock (its own frozen one, before: an
    # audit, 2026-12)
    times = sim.advance(0.2, record_interval_s=0.1).pivot(index="record", columns="instance",
                                                          values="t_s")
    np.testing.assert_array_equal(times[0], times[1])
    np.testing.assert_allclose(times[1], [1.1, 1.2])


def test_a_simulator_is_not_copied_or_pickled_and_save_refuses_a_folder(tmp_path):
    """copy.deepcopy and pickle failed in Taichi's words ("cannot pickle ... SNode"), and
    save("a folder") wrote "a folder.npz" beside it, which load("a folder") could not read (an
    audit, 2026-12): TypeErrors naming save()/load(), a ValueError naming the folder."""
    import copy
    import pickle

    sim = ts.Simulator([ts.StarParams()])
    for attempt in (copy.copy, copy.deepcopy, pickle.dumps):
        with pytest.raises(TypeError, match=r"a Simulator is not copied or pickled .*save\(\) "
                                            r"its state and load\(\) it"):
            attempt(sim)
    with pytest.raises(ValueError, match=r"is a folder: give the snapshot's file, e.g. "):
        sim.save(tmp_path)
    assert list(tmp_path.parent.glob(f"{tmp_path.name}.npz")) == []
    assert sim.save(tmp_path / "state").name == "state.npz"  # a name that is no folder


# a mutation audit of this module (2026-12): each test below failed a mutant the suite let live
COARSE = ts.StarParams(n_arc=6, n_limb=2)
COARSE_SOLVER = ts.SolverConfig(dt=5e-3)


@pytest.fixture
def coarse_pair():
    return ts.Simulator([COARSE] * 2, COARSE_SOLVER)


def test_commands_with_one_number_other_than_0_or_1_are_refused(coarse_pair):
    """A 2, a 0.5 or a -1 beside 0s is refused (not read as True), the state unchanged."""
    before = coarse_pair.save().fields
    for value in (2, 0.5, -1):
        commands = np.zeros((2, 8))
        commands[1, 3] = value
        with pytest.raises(ValueError, match=r"^commands must be boolean \(or numbers that are "
                                             r"exactly 0 or 1\)"):
            coarse_pair.fire(commands)
    after = coarse_pair.save().fields
    for name, values in before.items():
        np.testing.assert_array_equal(after[name], values, err_msg=name)


def test_an_advance_past_its_last_record_reaches_its_end_and_counts_records_from_1(
        coarse_pair):
    """25 ms with records every 10 ms ends at 25 ms, past its last record at 20 ms, and the
    `record` column counts the records from 1."""
    table = coarse_pair.advance(0.025, record_interval_s=0.01)
    np.testing.assert_allclose(coarse_pair.time_s, [0.025, 0.025], rtol=0, atol=1e-12)
    assert table["record"].tolist() == [1, 1, 2, 2]
    np.testing.assert_allclose(table["t_s"], [0.01, 0.01, 0.02, 0.02], rtol=0, atol=1e-12)


def test_a_failed_robots_records_keep_the_batchs_times_over_several_advances():
    """Robot 0 fails in its first 50-ms step (five Newton iterations), robot 1 runs on; two
    advances later robot 0's records still carry robot 1's times (its clock's lag adds up
    over the advances)."""
    sim = ts.Simulator([COARSE] * 2, ts.SolverConfig(dt=0.05, max_newton=5,
                                                     max_substep_halvings=1))
    sim.fire(["A1", "none"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        sim.advance(0.1)
        assert sim.ok.tolist() == [False, True]
        sim.advance(0.1)
        table = sim.advance(0.1, record_interval_s=0.05)
    times = table.pivot(index="record", columns="instance", values="t_s")
    np.testing.assert_array_equal(times[0], times[1])
    np.testing.assert_allclose(times[1], [0.25, 0.3], rtol=0, atol=1e-12)


def test_an_adaptive_advance_of_no_time_is_refused():
    """An adaptive advance of 0 s is refused as fixed steps' is ("at least one step"), not
    taken as a silent no-op."""
    sim = ts.Simulator([COARSE], ts.SolverConfig(adaptive=True))
    with pytest.raises(ValueError, match=r"^duration_s must be a finite number > 0 s, got 0.0"):
        sim.advance(0.0)


def test_a_snapshot_with_an_infinite_clock_lag_is_refused(coarse_pair):
    """A damaged header's clock lag of inf is refused as NaN and -1 are, the state
    unchanged."""
    snapshot = coarse_pair.save()
    coarse_pair.advance(0.01)
    before = coarse_pair.save().fields
    for lag in (math.inf, math.nan, -1.0):
        with pytest.raises(ValueError, match=r"^the saved state records 2 clock lags for its 2 "
                                             r"instances, or one not finite and >= 0"):
            coarse_pair.load(dataclasses.replace(snapshot, behind=(0.0, lag)))
    after = coarse_pair.save().fields
    for name, values in before.items():
        np.testing.assert_array_equal(after[name], values, err_msg=name)


def test_a_state_stepped_at_another_dt_is_refused(coarse_pair):
    """A snapshot of 2.5-ms steps (the same engine) is refused by a Simulator of 5-ms steps,
    naming both, the state unchanged."""
    other = ts.Simulator([COARSE] * 2, ts.SolverConfig(dt=2.5e-3))
    before = coarse_pair.save().fields
    with pytest.raises(ValueError, match=r"^the saved state has 2 instances at dt = 0.0025 s; "
                                         r"this simulator 2 at 0.005 s"):
        coarse_pair.load(other.save())
    after = coarse_pair.save().fields
    for name, values in before.items():
        np.testing.assert_array_equal(after[name], values, err_msg=name)


def test_a_robot_that_failed_is_not_warned_about_as_capped():
    """The capped-solve warning names robots still "ok"; a robot that failed (newton_failed,
    its newton_capped True, said by its status) gives none."""
    sim = ts.Simulator([COARSE] * 2, ts.SolverConfig(dt=0.05, max_newton=5,
                                                     max_substep_halvings=1))
    sim.fire(["A1", "none"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sim.advance(0.1)
    state = sim.state()
    assert state["status"].tolist() == ["newton_failed", "ok"]
    assert state["newton_capped"].tolist() == [True, False]


def test_reset_refuses_an_instance_just_outside_the_batch(coarse_pair):
    """Instance B itself is refused with the ValueError naming the range, and -1 is refused,
    not read as the last instance; the state unchanged."""
    coarse_pair.advance(0.01)
    for instances in (2, [0, 2], -1, [-1]):
        with pytest.raises(ValueError, match=r"^instances must be an integer or a sequence of "
                                             r"integers in \[0, 2\)"):
            coarse_pair.reset(instances)
    np.testing.assert_allclose(coarse_pair.time_s, [0.01, 0.01], rtol=0, atol=1e-12)


def test_a_reset_robot_that_fails_again_records_its_own_times():
    """Robot 0 fails, lags two advances, is reset and fails again: its records are at its own
    clock's times (0.05, 0.1 s), not shifted by the lag of its earlier episode."""
    sim = ts.Simulator([COARSE] * 2, ts.SolverConfig(dt=0.05, max_newton=5,
                                                     max_substep_halvings=1))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        sim.fire(["A1", "none"])
        sim.advance(0.1)
        sim.advance(0.1)
        sim.reset([0])
        sim.fire(["A1", "none"])
        table = sim.advance(0.1, record_interval_s=0.05)
    assert sim.ok.tolist() == [False, True]
    times = table.pivot(index="record", columns="instance", values="t_s")
    np.testing.assert_allclose(times[0], [0.05, 0.1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(times[1], [0.25, 0.3], rtol=0, atol=1e-12)


# Found by a mutation audit of the Simulator (2026-12-07): each test below kills a change of
# the code that the suite let live.



def test_the_y_displacement_is_simulates_bit_for_bit():
    """centroid_y_mm is measured from the start centroid's y (not its x: the start
    centroid is ~1e-19 m from the origin, so only the bits tell): the same bits as simulate's
    displacement_y_mm for an asymmetric gait that moves the robot along y."""
    params = [COARSE.replace(gait="A1+A2", period=0.2)]
    reference = ts.simulate(params, 0.02, ts.SolverConfig(dt=5e-3), progress=False)
    sim = ts.Simulator(params, ts.SolverConfig(dt=5e-3))
    sim.fire(["A1+A2"])
    sim.advance(0.02)
    state = sim.state()
    assert reference.summary.displacement_y_mm.iloc[0] != 0.0
    np.testing.assert_array_equal(state.centroid_x_mm, reference.summary.displacement_x_mm)
    np.testing.assert_array_equal(state.centroid_y_mm, reference.summary.displacement_y_mm)


def test_an_adaptive_reset_robot_that_fails_again_records_its_own_times():
    """With adaptive steps a failed robot's records carry the time its clock would show
    (`_shown_s`); a reset must forget it: robot 0 fails, is reset, fails again, and its record
    after the second failure is at its own clock's time (0.04 + 0.1 s), not the lagged clock of
    its first episode (0.24 + 0.1 s)."""
    solver = ts.SolverConfig(adaptive=True, dt=0.02, dt_max=0.02, dt_min=5e-3, max_newton=1,
                             error_tol=1e-3)
    sim = ts.Simulator([COARSE] * 2, solver)
    fire_0 = [[True] * 8, [False] * 8]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        sim.advance(0.04)
        sim.fire(fire_0, at_s=0.1)
        sim.advance(0.2)
        assert sim.ok.tolist() == [False, True]
        sim.reset([0])
        sim.advance(0.04)
        sim.fire(fire_0, at_s=0.1)
        table = sim.advance(0.1, record_interval_s=0.05)
    assert sim.ok.tolist() == [False, True]
    times = table.pivot(index="record", columns="instance", values="t_s")
    np.testing.assert_allclose(times[0], [0.09, 0.14], rtol=0, atol=1e-12)
    np.testing.assert_allclose(times[1], [0.33, 0.38], rtol=0, atol=1e-12)


ADAPTIVE_FAILING = ts.SolverConfig(adaptive=True, dt=0.02, dt_max=0.02, dt_min=5e-3,
                                   max_newton=1, error_tol=1e-3)


def test_an_adaptive_snapshot_with_a_negative_clock_time_is_refused():
    """A damaged header's shown_s of -1 s is refused as inf is (only NaN or a finite
    time >= 0 belongs there), the state unchanged."""
    sim = ts.Simulator([COARSE] * 2, ADAPTIVE_FAILING)
    snapshot = sim.save()
    assert len(snapshot.shown_s) == 2
    before = sim.save().fields
    for time in (-1.0, -1e-300, math.inf):
        with pytest.raises(ValueError, match=r"^the saved state records 2 clock times for its 2 "
                                             r"instances, or one neither NaN nor finite and >= 0"):
            sim.load(dataclasses.replace(snapshot, shown_s=(math.nan, time)))
    for name, values in before.items():
        np.testing.assert_array_equal(sim.save().fields[name], values, err_msg=name)


def adaptive_pair_with_a_failed_robot():
    """Two coarse robots on adaptive steps of one Newton update at most, at 0.24 s: robot 0,
    fired at 0.1 s, failed; robot 1 runs on (the warnings of the failure left out)."""
    sim = ts.Simulator([COARSE] * 2, ADAPTIVE_FAILING)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        sim.advance(0.04)
        sim.fire([[True] * 8, [False] * 8], at_s=0.1)
        sim.advance(0.2)
    assert sim.ok.tolist() == [False, True]
    return sim


def test_an_old_adaptive_snapshot_of_a_failed_robot_keeps_its_lag():
    """An adaptive snapshot written before `shown_s` was recorded holds a failed robot's
    lag in s in `behind`: loaded, the robot's next records are at its frozen time + that lag +
    the stop, the running robot's times (not its frozen time + the stop)."""
    sim = adaptive_pair_with_a_failed_robot()
    snapshot = sim.save()
    frozen = sim.time_s[0]
    assert frozen < 0.1
    old = dataclasses.replace(snapshot, shown_s=(), behind=(0.24 - frozen, 0.0))
    sim.load(old)
    times = sim.advance(0.05, record_interval_s=0.05)["t_s"].to_numpy()
    np.testing.assert_allclose(times, [0.29, 0.29], rtol=0, atol=1e-12)


def test_an_adaptive_failed_robots_records_keep_the_batchs_times_over_several_advances():
    """With adaptive steps the clock a failed robot would show adds up over advances
    from the one it showed (not from its frozen time): two advances after its failure its
    records are at the running robot's times."""
    sim = adaptive_pair_with_a_failed_robot()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        sim.advance(0.05)
        table = sim.advance(0.05, record_interval_s=0.05)
    assert sim.ok.tolist() == [False, True]
    np.testing.assert_allclose(table["t_s"], [0.34, 0.34], rtol=0, atol=1e-12)


def test_saving_to_a_path_ending_in_npz_writes_that_file(tmp_path):
    """save("state.npz") writes state.npz (".npz" is added only to a path without it),
    and load reads it back by the name given."""
    sim = ts.Simulator([COARSE])
    path = sim.save(tmp_path / "state.npz")
    assert path == tmp_path / "state.npz" and path.is_file()
    assert [p.name for p in tmp_path.iterdir()] == ["state.npz"]
    sim.load(tmp_path / "state.npz")


def test_the_repr_shows_one_time_or_the_range_of_times():
    """One time where every instance is at it, min..max where they differ."""
    sim = ts.Simulator([COARSE] * 2, ts.SolverConfig(dt=5e-3))
    sim.advance(0.01)
    assert repr(sim) == "Simulator(2 instances, t = 0.01 s, 2 running)"
    sim.reset(0)
    assert repr(sim) == "Simulator(2 instances, t = 0..0.01 s, 2 running)"


@pytest.mark.parametrize("at_s", [True, "0.01", float("nan"), float("inf")])
def test_a_firing_time_that_is_not_a_finite_number_is_refused(at_s):
    """at_s=True or the text "0.01" is refused naming at_s (without the check True was
    read as 1 s and the text as 0.01 s: a firing scheduled from a slip), as NaN and inf are."""
    sim = ts.Simulator([COARSE] * 2, ts.SolverConfig(dt=5e-3))
    with pytest.raises(ValueError, match=r"^at_s must be a finite time in s, got "):
        sim.fire(["A1", "A1"], at_s=at_s)
    assert (sim.engine.state.schedule.pending_count.to_numpy()[:2] == 0).all()


def test_a_state_of_another_batch_size_is_refused_naming_both():
    """A 2-robot snapshot loaded into a 3-robot Simulator of the same engine is refused
    by its batch size, in those words (without the check the parameters' count refused it as
    "a damaged snapshot", and with other_params=True its clock lags did)."""
    two = ts.Simulator([COARSE] * 2, ts.SolverConfig(dt=5e-3))
    three = ts.Simulator([COARSE] * 3, ts.SolverConfig(dt=5e-3))
    assert two.engine_key == three.engine_key
    for other_params in (False, True):
        with pytest.raises(ValueError, match=r"^the saved state has 2 instances at dt = 0.005 s; "
                                             r"this simulator 3 at 0.005 s"):
            three.load(two.save(), other_params=other_params)


def test_a_firing_need_be_after_the_clocks_of_the_commanded_instances_alone():
    """Robot 0 at 10 ms, robot 1 reset to 0: a firing at 5 ms for robot 1 alone is
    accepted (robot 0, ahead of it, fires nothing) and happens at 5 ms."""
    sim = ts.Simulator([COARSE] * 2, ts.SolverConfig(dt=5e-3))
    sim.advance(0.01)
    sim.reset(1)
    sim.fire(["none", "A1"], at_s=0.005)
    sim.advance(0.01)
    since = sim.state()["since_A1_s"].to_numpy()
    assert np.isnan(since[0])
    np.testing.assert_allclose(since[1], 0.005, rtol=0, atol=1e-12)
