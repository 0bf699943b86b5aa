"""The engine's host code (`BatchEngine`): what `load` refuses, what a snapshot holds, a term
asked for by name, and BDF2's history after a step retried in substeps. Kernels are pinned
against the NumPy reference elsewhere (test_engine.py); these pin the Python around them.
Found by a mutation audit (2026-12-07): each test kills a change of the code that the suite
let live."""

import pytest

import taichi_star as ts
from taichi_star.model import build_model
from taichi_star.runtime import prepare_engine

COARSE = dict(n_arc=6, n_limb=2)


def test_load_refuses_a_batch_past_capacity_tangents_without_sensitivity_and_a_ragged_batch(
        taichi_cpu):
    """`BatchEngine.load`'s three refusals, each with its own message."""
    params = [ts.StarParams(gait="A1", **COARSE)]
    engine = prepare_engine(params)
    solver = ts.SolverConfig()
    with pytest.raises(ValueError, match="exceeds the engine capacity"):
        engine.load(build_model(params * (engine.capacity + 1)), solver)
    with pytest.raises(ValueError, match="tangents need an engine built sensitive"):
        engine.load(build_model(params * 3), solver, tangents=1)
    assert not engine.sensitive
    engine.sensitive = True  # past the first refusal: the batch's shape is checked next
    try:
        with pytest.raises(ValueError, match=r"is not B instances and their"):
            engine.load(build_model(params * 2), solver, tangents=1)
    finally:
        engine.sensitive = False


def test_a_plain_snapshot_holds_no_factorisations(taichi_cpu):
    """`save_state()` without `factorisations` is the state alone (the factorisations'
    arrays, capacity × slots blocks, are many times its size)."""
    engine = prepare_engine([ts.StarParams(gait="A1", **COARSE)])
    plain = engine.save_state()
    assert not any(name.startswith("factorisation.") for name in plain)
    assert any(name.startswith("factorisation.") for name in engine.save_state(True))


def test_a_term_the_engine_does_not_use_is_a_key_error(taichi_cpu):
    """`BatchEngine.term` of a name not among the engine's terms raises KeyError (the
    damping term is compiled out of an undamped batch), not None."""
    engine = prepare_engine([ts.StarParams(gait="A1", **COARSE)])
    assert engine.term("bending").name == "bending"
    with pytest.raises(KeyError, match="damping"):
        engine.term("damping")


def test_a_substepped_bdf2_step_leaves_no_history_for_the_next(taichi_cpu):
    """After a fixed step that needed substeps the next step starts without BDF2's
    history (its previous state is a substep's, h/2^n back, not h: a BDF2 step on it is
    wrong), and a step taken whole restores it. Stepped one step per launch until the pulse
    forces a retry (h = 50 ms, at most 3 Newton updates, as
    test_substep_retry_rescues_a_step_and_leaves_neighbours_bitwise_equal)."""
    solver = ts.SolverConfig(integrator="bdf2", dt=0.05, max_newton=3, max_substep_halvings=6)
    engine = prepare_engine([ts.StarParams(gait="A1+A2", **COARSE)], solver)
    state = engine.state
    seen = []
    for _ in range(20):
        before = state.substep_retries.to_numpy()[0]
        engine.advance(1)
        assert state.status.to_numpy()[0] == 0
        retried = state.substep_retries.to_numpy()[0] > before
        seen.append((retried, int(state.history_valid.to_numpy()[0])))
    assert any(retried for retried, _ in seen) and not all(retried for retried, _ in seen)
    for retried, history in seen:
        assert history == (0 if retried else 1), seen
