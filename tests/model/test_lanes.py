"""The fixed-step kernel with vector lanes (`Runtime.configure_lanes`): the instances of a
group interleave their Newton solves round by round, their systems factored and solved together
in the CPU's vector units, and every instance gets the bits it gets on its own: through failed
attempts, substep retries and frozen instances, with BDF2's history and damping, and partial
groups (a sensitive engine's lanes, whose tangent steps follow each instance's converged step
as in `advance_instance`, were checked the same way outside the suite: docs/performance.md).
Below `LOCKSTEP_MINIMUM_BATCH` instances, and with the chord Jacobian, each group holds one
instance, which factors and solves its own system."""

import numpy as np
import pandas as pd
import pytest
import taichi as ti

import taichi_star as ts
import taichi_star.runtime as runtime_module
from taichi_star.engine import LOCKSTEP_MINIMUM_BATCH
from taichi_star.profiling import EngineProfile, _profile_phases
from taichi_star.runtime import CPU_LANES, LANES_MINIMUM_WORK, Runtime, prepare_engine

GAITS = ["A1", "A1+A2", "A1+A3", "A1+A4", "A1+A3+A5", "none"]
# 70: eight full groups of 8 lanes and six in a ninth, partly empty (lane l of group g holds
# instance 9·l + g)
BATCH = [ts.StarParams(gait=GAITS[i % 6], alpha=0.6 + 0.005 * i) for i in range(70)]


def run(lanes, params, duration_s, solver, **options):
    Runtime.current().configure_lanes(lanes)
    try:
        return ts.simulate(params, duration_s, solver, **options)
    finally:
        Runtime.current().configure_lanes()


def assert_same_bits(alone, together):
    pd.testing.assert_frame_equal(together.summary, alone.summary, check_exact=True)
    pd.testing.assert_frame_equal(together.trajectory, alone.trajectory, check_exact=True)


@pytest.mark.slow  # the lanes' other bitwise tests stay in the default tier (the suite's time)
def test_lockstep_retries_and_freezes_as_each_instance_alone():
    """BDF2 with damping at 10 ms and at most 4 Newton iterations: in the heating pulse first
    attempts fail, and those instances retry (without BDF2's history, then in substeps) in
    the same rounds as the others' solves. With at most one halving some are rescued, the
    heating robots freeze in the end (their start state restored from the backup), the
    resting ones (gait none) go on; with two halvings every one is rescued, those that froze
    before by four substeps from the restored start state. Each instance gets the bits of its
    run alone."""
    params = [p.replace(damping_time=1e-3) for p in BATCH]
    frozen = {}
    for halvings in (1, 2):
        solver = ts.SolverConfig(integrator="bdf2", dt=0.01, max_newton=4,
                                 max_substep_halvings=halvings)
        alone = run(1, params, 0.2, solver, record_interval_s=0.05)
        together = run(8, params, 0.2, solver, record_interval_s=0.05)
        assert_same_bits(alone, together)
        summary = together.summary
        frozen[halvings] = summary["status"] != "ok"
        # more steps retried than instances frozen (each frozen one retried its last step
        # once: the rest were rescued)
        assert summary["substep_retries"].sum() > frozen[halvings].sum()
    # the case exercises what it claims: frozen instances beside live ones with one halving,
    # and none with two
    assert frozen[1].any() and not frozen[1].all()
    assert not frozen[2].any()


@pytest.mark.parametrize("jacobian", ["chord", "lagged"])
def test_chord_and_lagged_jacobians_in_an_engine_with_lanes_as_each_instance_alone(jacobian):
    """The chord and lagged Jacobians keep or refactor each instance's factorisation as that
    instance's iteration contracts (the lagged one also from step to step); in an engine with
    lanes their groups hold one instance each, and every instance gets the bits of the engine
    without lanes, retries included: at most 4 iterations, the heating robots' solves run out,
    start again with Newton's Jacobian, run out again, and are retried in substeps (some
    rescued, some frozen; at most 3 froze every retried robot once Newton stopped only on an
    update within newton_tol, 2026-12)."""
    solver = ts.SolverConfig(integrator="bdf2", dt=0.01, max_newton=4, max_substep_halvings=2,
                             jacobian=jacobian)
    # the batch of the test above, whose engines this one shares (the chord is a setting)
    params = [p.replace(damping_time=1e-3) for p in BATCH]
    alone = run(1, params, 0.1, solver, record_interval_s=0.05)
    together = run(8, params, 0.1, solver, record_interval_s=0.05)
    assert_same_bits(alone, together)
    summary = together.summary
    frozen = (summary["status"] != "ok").sum()
    assert summary["newton_capped"].any() and summary["substep_retries"].sum() > frozen > 0


@pytest.mark.parametrize("count, jacobian, lockstep", [
    (LOCKSTEP_MINIMUM_BATCH - 1, "newton", 0), (LOCKSTEP_MINIMUM_BATCH, "newton", 1),
    (LOCKSTEP_MINIMUM_BATCH, "chord", 0), (LOCKSTEP_MINIMUM_BATCH, "lagged", 0)])
def test_lockstep_from_the_minimum_batch_and_only_with_newtons_jacobian(count, jacobian,
                                                                        lockstep):
    """A batch one short of the minimum runs its instances alone (one group each); from the
    minimum they go in groups of 8; the chord and lagged Jacobians, whose instances keep or
    refactor their Jacobians each on its own, always run them alone."""
    Runtime.current().configure_lanes(8)
    try:
        engine = prepare_engine(BATCH[:count], ts.SolverConfig(jacobian=jacobian))
    finally:
        Runtime.current().configure_lanes()
    assert engine.lockstep[None] == lockstep
    assert engine.group_count[None] == (-(-count // 8) if lockstep else count)
    saved = engine.save_state()
    engine.advance(20)
    steps = engine.state.steps_done.to_numpy()[:count]
    assert (steps == 20).all() and (engine.state.status.to_numpy()[:count] == 0).all()
    # every instance of the batch advanced once per step, padding never
    assert (engine.state.steps_done.to_numpy()[count:] == saved["steps_done"][count:]).all()


@ti.kernel
def _slot_groups(engine: ti.template(), groups: ti.types.ndarray(dtype=ti.i32, ndim=1)):
    for slot in range(engine.capacity * engine.loop_spread):
        groups[slot] = engine.slot_group(slot)


def test_the_lockstep_groups_are_spread_evenly_over_the_loop(taichi_cpu):
    """The groups of an engine with lanes sit `group_stride` = iterations // groups apart
    (as `slot_instance` places instances), not packed at the start of the loop (where
    Taichi's CPU backend would give them all to one thread)."""
    params = BATCH[:LOCKSTEP_MINIMUM_BATCH]  # the engine of the test above
    Runtime.current().configure_lanes(8)
    try:
        engine = prepare_engine(params, ts.SolverConfig())
    finally:
        Runtime.current().configure_lanes()
    assert engine.lockstep[None] == 1
    count = engine.group_count[None]
    groups = np.empty(engine.capacity * engine.loop_spread, dtype=np.int32)
    _slot_groups(engine, groups)
    slots = np.flatnonzero(groups >= 0)
    np.testing.assert_array_equal(groups[slots], np.arange(count))
    np.testing.assert_array_equal(slots, np.arange(count) * (len(groups) // count))


def test_the_phase_profile_of_an_engine_with_lanes_runs_its_groups_as_its_steps_do():
    """`EngineProfile.phase_split` of an engine with lanes assembles each instance's system,
    then factors and solves the group's systems in its lanes (`advance_group`'s lockstep):
    the Newton updates the profile leaves in every instance's right-hand side are those of the
    engine without lanes, bit for bit (a profile that skipped the lanes' solve or the copy
    back would leave each instance's residual there)."""
    # the batch and integrator of the first test, whose engines this one shares
    params = [p.replace(damping_time=1e-3) for p in BATCH]
    solver = ts.SolverConfig(integrator="bdf2", dt=0.01)
    updates = {}
    for lanes in (1, 8):
        Runtime.current().configure_lanes(lanes)
        try:
            profile = EngineProfile(params, solver)
        finally:
            Runtime.current().configure_lanes()
        assert profile.lanes == lanes
        # one repetition per launch: every launch assembles, factors and solves at rest
        profile.phase_split(solver.dt, iteration_s=1.0, profile_seconds=1e-9)
        updates[lanes] = profile.engine.system.rhs.to_numpy()[:len(params)]
    assert profile.engine.lockstep[None] == 1
    np.testing.assert_array_equal(updates[8], updates[1])
    # the lanes' copy reads only the pattern's slots: every slot a term may write is one of them
    plan = profile.engine.plan
    assert set(profile.engine.assembly.slots.values()) == set(range(plan.n_structural))
    # not trivially equal: every instance has an update
    assert (np.abs(updates[1]).max(axis=(1, 2)) > 0).all()


@pytest.mark.parametrize("lanes", [1, 8])
def test_the_residual_phase_assembles_the_residual_alone(lanes):
    """The profile's residual phase (`phase_split`'s "residual") assembles what an iteration
    that keeps its factorisation does: the residual, bit for bit that of the full assembly,
    and no Jacobian (the blocks keep what was there, a marker); the full assembly then
    overwrites them."""
    params = [p.replace(damping_time=1e-3) for p in BATCH]  # the engines of the tests above
    solver = ts.SolverConfig(integrator="bdf2", dt=0.01)
    Runtime.current().configure_lanes(lanes)
    try:
        engine = EngineProfile(params, solver).engine
    finally:
        Runtime.current().configure_lanes()
    system = engine.system

    def launch(phases):
        _profile_phases(engine, phases, 1, solver.dt)
        return system.rhs.to_numpy()[:len(params)], system.blocks.to_numpy()[:len(params)]

    marker = np.full(system.blocks.shape + (2, 2), 7.0)
    system.blocks.from_numpy(marker)
    residual, blocks = launch(0)
    np.testing.assert_array_equal(blocks, marker[:len(params)])
    assembled_residual, assembled = launch(1)
    np.testing.assert_array_equal(residual, assembled_residual)
    assert (np.abs(residual).max(axis=(1, 2)) > 0).all()  # every instance has a residual
    assert (assembled != 7.0).any(axis=(1, 2, 3)).all()  # and a Jacobian, once assembled


WORK = LANES_MINIMUM_WORK


@pytest.mark.parametrize("batch_size, solver, sensitive, robot_steps, lanes", [
    # the work of the call and the batch at, and one short of, their minimums
    (LOCKSTEP_MINIMUM_BATCH, ts.SolverConfig(), False, WORK, CPU_LANES),
    (LOCKSTEP_MINIMUM_BATCH, ts.SolverConfig(), False, WORK - 1, 1),
    (LOCKSTEP_MINIMUM_BATCH - 1, ts.SolverConfig(), False, WORK, 1),
    # a Simulator's work is not known ahead
    (4096, ts.SolverConfig(), False, None, 1),
    # what the lanes do not speed up runs one instance at a time
    (4096, ts.SolverConfig(jacobian="chord"), False, WORK, 1),
    (4096, ts.SolverConfig(adaptive=True), False, WORK, 1),
    (4096, ts.SolverConfig(), True, WORK, 1)])
def test_engines_have_lanes_by_default_where_they_pay(batch_size, solver, sensitive,
                                                      robot_steps, lanes):
    runtime = Runtime.current()
    runtime.ensure("cpu", "f64")
    assert runtime.engine_lanes(batch_size, solver, sensitive, robot_steps) == lanes
    # a configured number holds for every CPU engine, until the default is configured again
    runtime.configure_lanes(2)
    try:
        assert runtime.engine_lanes(batch_size, solver, sensitive, robot_steps) == 2
    finally:
        runtime.configure_lanes()
    assert runtime.engine_lanes(batch_size, solver, sensitive, robot_steps) == lanes


def test_a_call_gets_the_lanes_by_its_work_and_the_bits_of_one_at_a_time(monkeypatch):
    """`simulate` asks for the engine with lanes for a call of LANES_MINIMUM_WORK robot-steps,
    not for one step fewer (the minimum lowered here to 70 instances × 20 steps, so that the
    calls are short; `engine_lanes` is checked at the real minimum above). The call with lanes
    gets the bits of the engine without them."""
    steps = 20
    # the batch and integrator of the first test, whose engines this one shares
    params = [p.replace(damping_time=1e-3) for p in BATCH]
    monkeypatch.setattr(runtime_module, "LANES_MINIMUM_WORK", steps * len(params))
    solver = ts.SolverConfig(integrator="bdf2")
    runtime = Runtime.current()
    used = []
    engine_for = runtime.engine_for

    def recording(*args, **kwargs):
        engine = engine_for(*args, **kwargs)
        used.append(engine.lanes)
        return engine

    monkeypatch.setattr(runtime, "engine_for", recording)
    shorter = ts.simulate(params, (steps - 1) * solver.dt, solver)
    together = ts.simulate(params, steps * solver.dt, solver)
    alone = run(1, params, steps * solver.dt, solver)
    assert used == [1, CPU_LANES, 1]
    assert_same_bits(alone, together)
    assert (shorter.summary["steps"] == steps - 1).all()
    assert (together.summary["steps"] == steps).all()
    assert (together.summary["status"] == "ok").all()


def test_lanes_are_refused_outside_the_supported_counts():
    with pytest.raises(ValueError, match="lanes must be 1, 2, 4, 8 or 16"):
        Runtime.current().configure_lanes(3)
    with pytest.raises(ValueError, match="lanes"):
        Runtime.current().configure_lanes(True)
