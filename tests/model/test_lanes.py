"""The fixed-step kernel with vector lanes (`Runtime.configure_lanes`): groups of instances
iterate Newton in lockstep, their systems factored and solved together in the CPU's vector
units, and every instance gets the bits it gets on its own: through failed attempts, substep
retries and frozen instances, with BDF2's history and damping, and partial groups (a
sensitive engine's lockstep, whose tangent steps follow each instance's converged step as in
`advance_instance`, was checked the same way outside the suite: docs/performance.md). Below `LOCKSTEP_MINIMUM_BATCH` instances, and with the chord Jacobian, the
instances run one at a time."""

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
from taichi_star.engine import LOCKSTEP_MINIMUM_BATCH
from taichi_star.runtime import Runtime, prepare_engine

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


def test_lockstep_retries_and_freezes_as_each_instance_alone():
    """BDF2 with damping at 10 ms and at most 4 Newton iterations: in the heating pulse first
    attempts fail, and those instances retry on their own (without BDF2's history, then in
    two substeps): some are rescued, the heating robots freeze in the end, the resting ones
    (gait none) go on. Each instance gets the bits of its run alone."""
    solver = ts.SolverConfig(integrator="bdf2", dt=0.01, max_newton=4, max_substep_halvings=1)
    params = [p.replace(damping_time=1e-3) for p in BATCH]
    alone = run(1, params, 0.2, solver, record_interval_s=0.05)
    together = run(8, params, 0.2, solver, record_interval_s=0.05)
    assert_same_bits(alone, together)
    summary = together.summary
    frozen = summary["status"] != "ok"
    # the case exercises what it claims: frozen instances beside live ones, and more steps
    # retried than instances frozen (each frozen one retried its last step once: the rest
    # were rescued)
    assert frozen.any() and not frozen.all()
    assert summary["substep_retries"].sum() > frozen.sum()


@pytest.mark.parametrize("count, jacobian, lockstep", [
    (LOCKSTEP_MINIMUM_BATCH - 1, "newton", 0), (LOCKSTEP_MINIMUM_BATCH, "newton", 1),
    (LOCKSTEP_MINIMUM_BATCH, "chord", 0)])
def test_lockstep_from_the_minimum_batch_and_only_with_newtons_jacobian(count, jacobian,
                                                                        lockstep):
    """A batch one short of the minimum runs its instances alone (one group each); from the
    minimum they go in groups of 8; the chord Jacobian, whose instances keep or refactor
    their Jacobians each on its own, always runs them alone."""
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


def test_lanes_are_refused_outside_the_supported_counts():
    with pytest.raises(ValueError, match="lanes must be 1, 2, 4, 8 or 16"):
        Runtime.current().configure_lanes(3)
    with pytest.raises(ValueError, match="lanes"):
        Runtime.current().configure_lanes(True)
