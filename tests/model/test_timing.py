"""A `simulate` call's timing (`RunTiming`): compilation reported apart from the run, each
phase measured inside the call, every accepted step of every instance counted once."""

import dataclasses
import math
import time

import numpy as np
import pytest

import taichi_star as ts
from taichi_star.runtime import prepare_engine

PARAMS = [ts.StarParams(gait="A1"), ts.StarParams(gait="A1+A3")]
SOLVER = ts.SolverConfig(dt=2e-3)
DURATION_S = 0.05


def test_the_phases_lie_within_the_call_and_count_every_accepted_step():
    start = time.perf_counter()
    result = ts.simulate(PARAMS, DURATION_S, SOLVER, record_interval_s=0.01)
    wall = time.perf_counter() - start
    timing = result.timing
    phases = [timing.setup_s, timing.compile_s, timing.run_s, timing.collect_s]
    assert min(phases) >= 0.0
    # each phase is an interval inside the call: together at most its wall time
    assert timing.total_s == sum(phases) <= wall
    # fixed steps: every instance takes duration / dt steps, and all of them are counted
    assert timing.robot_steps == result.summary["steps"].sum() == len(PARAMS) * 25
    assert timing.robot_steps_per_s == timing.robot_steps / timing.run_s
    assert "compile" in repr(result) and "robot-steps/s" in repr(result)


def test_compiling_the_stepping_kernel_takes_no_step_and_changes_no_state(taichi_cpu):
    """`compile_stepping` launches the fixed-step kernel for no step: mid-run, every state
    field of every instance keeps every bit (the adaptive kernel: tests/model/test_adaptive.py)."""
    engine = prepare_engine(PARAMS, SOLVER)
    engine.advance(3)
    before = engine.state.save()
    engine.compile_stepping(adaptive=False)
    after = engine.state.save()
    assert before.keys() == after.keys()
    for name in before:
        np.testing.assert_array_equal(after[name], before[name], err_msg=name)
    assert (before["steps_done"][:len(PARAMS)] == 3).all()


def test_timings_add_field_by_field_and_a_run_of_no_time_has_no_rate():
    first = ts.RunTiming(setup_s=1.0, compile_s=2.0, run_s=0.5, collect_s=0.25, robot_steps=100)
    second = ts.RunTiming(setup_s=0.5, compile_s=0.0, run_s=0.0, collect_s=0.0, robot_steps=7)
    total = first + second
    assert total == ts.RunTiming(setup_s=1.5, compile_s=2.0, run_s=0.5, collect_s=0.25,
                                 robot_steps=107)
    assert total.total_s == 4.25
    assert first.robot_steps_per_s == 200.0
    # run_s = 0 (nothing ran, or below the clock's resolution): no rate, not a division error
    assert math.isnan(second.robot_steps_per_s)
    assert "robot-steps/s" in str(first)
    with pytest.raises(dataclasses.FrozenInstanceError):
        first.run_s = 1.0  # frozen: a result's timing is a record


def test_a_simulator_times_its_setup_once_its_compilation_once_and_sums_its_advances():
    sim = ts.Simulator(PARAMS, SOLVER)
    set_up = sim.timing
    assert set_up.setup_s > 0.0
    assert (set_up.compile_s, set_up.run_s, set_up.collect_s, set_up.robot_steps) == (0, 0, 0, 0)
    sim.fire(["A1", "A1+A3"])
    sim.advance(0.02)
    first = sim.timing
    assert first.robot_steps == len(PARAMS) * 10  # 0.02 s at 2 ms, every instance
    assert first.setup_s == set_up.setup_s and first.run_s > 0.0
    sim.advance(0.01)
    second = sim.timing
    # compiled at the first advance only; the steps of both advances counted
    assert second.compile_s == first.compile_s
    assert second.robot_steps == len(PARAMS) * 15
    np.testing.assert_allclose(sim.time_s, 15 * SOLVER.dt, rtol=1e-12)  # 15 steps each
    assert second.run_s > first.run_s and second.collect_s == 0.0
