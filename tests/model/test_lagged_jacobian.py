"""The lagged Jacobian (SolverConfig(jacobian="lagged")): a factorisation kept across steps
reaches each step's solution to newton_tol, is reused exactly when its integrator weights
match and it is young enough, is never taken from another call, another instance or a failed
solve, and a Simulator that puts back some instances leaves the others' bits alone."""

import numpy as np
import pytest
import taichi as ti

import taichi_star as ts
from taichi_star.engine import FACTORISATION_PREFIX, LAGGED_KEEP_MAX_UPDATES, LAGGED_MAX_AGE
from taichi_star.runtime import prepare_engine
from taichi_star.state import STATUS_NEWTON_FAILED, STATUS_OK

LAGGED = ts.SolverConfig(jacobian="lagged")


def _final_shapes(params, n_steps, solver):
    result = ts.simulate(params, n_steps * solver.dt, solver=solver,
                         record_interval_s=n_steps * solver.dt, record_shapes=True)
    assert (result.summary.status == "ok").all()
    return result.shapes[-1]


def test_lagged_jacobian_reaches_the_same_solution():
    """As the chord: another path to each step's solution, which both modes reach within
    newton_tol = 1e-10 m (every step stops on an update within newton_tol, which left the
    lagged Jacobian's steps at most 0.93·newton_tol off: docs/reliability.md), hence within
    300 × 1e-10 m after 300 steps (the steps' errors add at worst). A mode that converged to
    another point would be off by the step's motion, micrometres."""
    params = [ts.StarParams(gait="A1+A2"), ts.StarParams(gait="A1+A3+A5", alpha=1.2)]
    newton = _final_shapes(params, 300, ts.SolverConfig())
    lagged = _final_shapes(params, 300, LAGGED)
    assert np.abs(lagged - newton).max() < 300 * 1e-10


def _factorisations(params, n_steps, solver):
    summary = ts.simulate(params, n_steps * solver.dt, solver).summary
    assert (summary["newton_iterations_max"] == 1).all()  # at rest: every solve one update
    assert (summary["steps"] == n_steps).all()  # no retries: a solve per step
    return (summary["factorisations_mean"] * n_steps).round().astype(int).tolist()


def test_a_kept_factorisation_is_reused_for_its_age_limit_and_then_refactored():
    """A robot at rest (gait "none") solves every step with one update, so only the age rule
    refactors: the first step factors, the next LAGGED_MAX_AGE steps reuse it (the last of
    them at age LAGGED_MAX_AGE − 1 < LAGGED_MAX_AGE), and the step after them factors again."""
    rest = [ts.StarParams(gait="none")]
    assert _factorisations(rest, 1 + LAGGED_MAX_AGE, LAGGED) == [1]
    assert _factorisations(rest, 2 + LAGGED_MAX_AGE, LAGGED) == [2]


def test_a_factorisation_is_reused_only_with_the_same_integrator_weights():
    """BDF2's first step is implicit Euler's (inertia scale 1/h²), its second BDF2's (9/(4h²)):
    the weights differ, so the second step factors again, and the steps after it (the same
    weights) reuse that factorisation. Implicit Euler factors once."""
    rest = [ts.StarParams(gait="none")]
    assert _factorisations(rest, 50, LAGGED.replace(integrator="bdf2")) == [2]
    assert _factorisations(rest, 50, LAGGED) == [1]


def test_runs_do_not_see_each_others_factorisations():
    """The engine is reused from call to call: a call starts with nothing kept, so a run
    repeated after another batch's run gives the same bits, and an instance's bits do not
    depend on its neighbours (the batch reversed)."""
    batch = [ts.StarParams(gait="A1+A2"), ts.StarParams(gait="A1+A3", alpha=1.2)]
    first = ts.simulate(batch, 0.3, LAGGED).summary
    ts.simulate([ts.StarParams(gait="A1+A4", youngs_modulus=8e6)] * 2, 0.3, LAGGED)
    again = ts.simulate(batch, 0.3, LAGGED).summary
    reversed_batch = ts.simulate(batch[::-1], 0.3, LAGGED).summary.iloc[::-1]
    for column in ("displacement_x_mm", "displacement_y_mm", "factorisations_mean"):
        np.testing.assert_array_equal(again[column].to_numpy(), first[column].to_numpy())
        np.testing.assert_array_equal(reversed_batch[column].to_numpy(), first[column].to_numpy())


def test_a_failed_solve_leaves_nothing_to_reuse():
    """An instance whose only attempt fails (one Newton update allowed, no substeps, the
    firing's first step) is frozen with no kept factorisation; one at rest converges and keeps
    the factorisation of its step's weights (1/h² for implicit Euler)."""
    solver = LAGGED.replace(max_newton=1, max_substep_halvings=0)
    engine = prepare_engine([ts.StarParams(gait="A1+A2"), ts.StarParams(gait="none")], solver)
    engine.advance(1)
    status = engine.state.status.to_numpy()[:2]
    kept = engine.kept_inertia_scale.to_numpy()[:2]
    assert status.tolist() == [STATUS_NEWTON_FAILED, STATUS_OK]
    assert kept[0] == 0.0
    assert kept[1] == 1.0 / solver.dt ** 2


def test_putting_back_some_instances_leaves_the_others_bitwise_alone(tmp_path):
    """Simulator.reset restores the whole state with some rows changed: only those refactor;
    the other robot goes on with its kept factorisation, exactly as in a Simulator where
    nothing was reset. A lagged snapshot holds the kept factorisations: loaded (from memory or
    its file) the continuation is the uninterrupted run's bit for bit. Without them (a
    snapshot of a Newton simulator, say) every changed row refactors and the continuation
    agrees with the uninterrupted run to newton_tol per step (not bitwise; 100 steps)."""
    params = [ts.StarParams(gait="none"), ts.StarParams(gait="none", alpha=1.1)]

    def driven(reset_first: bool):
        simulator = ts.Simulator(params, LAGGED)
        simulator.fire(["A1+A3", "A1+A3"])
        simulator.advance(0.2)
        snapshot = simulator.save()
        if reset_first:
            simulator.reset([0])
            kept = simulator.engine.kept_inertia_scale.to_numpy()[:2]
            assert kept[0] == 0.0 and kept[1] == 1.0 / LAGGED.dt ** 2  # robot 0 refactors
        simulator.advance(0.1)
        return simulator, snapshot

    # shapes kept, simulators dropped: one alive at a time, each takes the engine the last one
    # left instead of compiling its own
    reset = driven(True)[0].shapes()
    untouched, snapshot = driven(False)
    untouched = untouched.shapes()
    np.testing.assert_array_equal(reset[1], untouched[1])
    assert np.abs(reset[0] - untouched[0]).max() > 1e-3  # it was reset
    for source in (snapshot, snapshot.write(tmp_path / "lagged")):
        restored = ts.Simulator(params, LAGGED)
        restored.load(source)
        restored.advance(0.1)
        np.testing.assert_array_equal(restored.shapes(), untouched)
        del restored
    without = ts.SimulatorSnapshot(
        fields={name: values for name, values in snapshot.fields.items()
                if not name.startswith(FACTORISATION_PREFIX)},
        engine_key=snapshot.engine_key, n_instances=snapshot.n_instances, dt=snapshot.dt)
    restored = ts.Simulator(params, LAGGED)
    restored.load(without)
    restored.advance(0.1)
    difference = np.abs(restored.shapes() - untouched).max()
    assert 0.0 < difference < 100 * 1e-10  # refactored: within 100 steps x newton_tol


def test_a_snapshot_with_a_damaged_factorisation_is_refused_and_changes_nothing():
    """Blocks of another shape, of another type (f32 blocks loaded rounded, the state no
    longer the snapshot's: an audit) and a missing factorisation field are refused."""
    simulator = ts.Simulator([ts.StarParams(gait="none")], LAGGED)
    simulator.fire(["A1"])
    simulator.advance(0.01)
    snapshot = simulator.save()
    before = simulator.save()
    blocks, age = FACTORISATION_PREFIX + "blocks", FACTORISATION_PREFIX + "age"
    damages = (({blocks: snapshot.fields[blocks][:, :-1]}, "'factorisation.blocks' has shape"),
               ({blocks: snapshot.fields[blocks].astype(np.float32)},
                "'factorisation.blocks' has type float32, this engine float64"),
               ({age: None}, "saved state has no field 'factorisation.age'"))
    for damage, message in damages:
        fields = {name: values for name, values in {**snapshot.fields, **damage}.items()
                  if values is not None}
        damaged = ts.SimulatorSnapshot(fields=fields, engine_key=snapshot.engine_key,
                                       n_instances=snapshot.n_instances, dt=snapshot.dt)
        with pytest.raises(ValueError, match=message):
            simulator.load(damaged)
        after = simulator.save()
        for field, values in before.fields.items():
            np.testing.assert_array_equal(after.fields[field], values)


@ti.kernel
def _finish_solve(engine: ti.template(), iterations: ti.i32, converged: ti.i32):
    """Instance 0's Newton solve ends after `iterations` updates, converged or not, with a
    factorisation of weights (1, 1) kept."""
    engine.kept_inertia_scale[0] = 1.0
    engine.kept_rate_gain[0] = 1.0
    engine.finish_newton(0, 1.0, iterations, converged, 1)


@pytest.mark.parametrize("iterations, converged, kept", [
    (1, 1, True), (LAGGED_KEEP_MAX_UPDATES, 1, True), (LAGGED_KEEP_MAX_UPDATES + 1, 1, False),
    (1, 0, False)])
def test_a_solve_of_many_updates_or_a_failed_one_leaves_nothing_to_reuse(iterations, converged,
                                                                        kept):
    """The rule on its boundary: a converged solve of at most LAGGED_KEEP_MAX_UPDATES (2)
    updates keeps its factorisation, one of three does not, nor does a failed solve."""
    engine = prepare_engine([ts.StarParams(gait="none")], LAGGED)
    _finish_solve(engine, iterations, converged)
    assert bool(engine.kept_inertia_scale.to_numpy()[0] != 0.0) is kept


def test_in_a_run_two_updates_keep_and_three_do_not():
    """The first step of a firing takes two updates at newton_tol 1e-9 m, three at 1e-10 m
    (until 2026-12 the contraction estimate stopped it after two there) and four at 1e-14 m
    (the updates stall at round-off): the factorisation of the first is kept (its weights,
    1/h² for implicit Euler), the others' are not."""
    params = [ts.StarParams(gait="A1+A2")]
    for tol, updates, kept in ((1e-9, 2, 1.0 / LAGGED.dt ** 2), (1e-10, 3, 0.0),
                               (1e-14, 4, 0.0)):
        engine = prepare_engine(params, LAGGED.replace(newton_tol=tol))
        engine.advance(1)
        assert engine.state.newton_max.to_numpy()[0] == updates
        assert engine.kept_inertia_scale.to_numpy()[0] == kept


@pytest.mark.parametrize("jacobian", ["chord", "lagged"])
def test_a_solve_that_runs_out_of_iterations_is_redone_with_newtons_jacobian(jacobian):
    """A damped A1+A3 robot fired again at 0.3 s (BDF2): the chord's and the lagged
    Jacobian's iterations apply an update that fails to contract before they refactor, and
    there it threw the iterate where none converged in 25 iterations (Newton's: 7); the step
    was redone as an implicit Euler step and the shape ended 4.3e-4 m off Newton's (an audit).
    Now such a solve starts again from the step's start with Newton's Jacobian: the shape
    within the steps' tolerances of Newton's, and `newton_capped` says a solve ran out."""
    params = [ts.StarParams(gait="A1+A3", alpha=1.2, period=0.3, damping_time=0.94e-3)]
    steps = 350
    newton = _final_shapes(params, steps, ts.SolverConfig(integrator="bdf2"))
    solver = ts.SolverConfig(jacobian=jacobian, integrator="bdf2")
    result = ts.simulate(params, steps * solver.dt, solver=solver,
                         record_interval_s=steps * solver.dt, record_shapes=True)
    summary = result.summary.iloc[0]
    assert summary["status"] == "ok" and summary["substep_retries"] == 0
    assert summary["newton_capped"]  # the case exercises the retry
    # each step converged to newton_tol = 1e-10 m in both modes, and their errors add up at
    # worst over the 350 steps (the lagged Jacobian's per-step bound is not guaranteed with
    # BDF2, docs/numerics.md: measured 6.9e-9 m here, chord 5.6e-9 m; before the retry 4.3e-4)
    assert np.abs(result.shapes[-1] - newton).max() < steps * 1e-10


def test_a_chord_solve_that_converges_on_its_last_iteration_is_not_redone():
    """The retry's boundary: a robot at rest converges after one update, and with
    max_newton = 1 on its last allowed one; that solve stands (one solve per step, not two)."""
    solver = ts.SolverConfig(jacobian="chord", max_newton=1)
    engine = prepare_engine([ts.StarParams(gait="none")], solver)
    engine.advance(3)
    assert engine.state.status.to_numpy()[0] == STATUS_OK
    assert engine.state.newton_solves.to_numpy()[0] == 3
    assert engine.state.newton_total.to_numpy()[0] == 3
