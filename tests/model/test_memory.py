"""The memory guard: an engine's size is known before it is allocated, and a batch too large for
the machine is refused with the way to run it (chunks) instead of exhausting memory."""

import pytest

import taichi_star as ts
from taichi_star import runtime
from taichi_star.model import build_model
from taichi_star.runtime import engine_bytes, prepare_engine


@pytest.mark.parametrize("preset", ["paper", "accurate"])
def test_engine_size_estimate_matches_the_fields_allocated(preset, taichi_cpu):
    """The estimate counts the per-instance fields; the engine's shared index tables (a few
    hundred kB, independent of the batch) are what it leaves out: within 2 % at capacity 64."""
    params = [ts.StarParams.preset(preset, gait="A1+A3")] * 3
    engine = prepare_engine(params, ts.SolverConfig.preset(preset))
    estimate = engine_bytes(build_model(params), "f64")
    assert abs(estimate / engine.arena.nbytes - 1.0) <= 0.02, (estimate, engine.arena.nbytes)


def test_a_batch_too_large_for_the_memory_is_refused_before_compute(monkeypatch):
    """With 100 MiB available, 5,000 instances (~0.5 GB of engine) are refused with a message
    naming run_batch; nothing is allocated (no engine of that capacity is cached)."""
    monkeypatch.setattr(runtime, "available_memory_bytes", lambda: 100 * 2**20)
    with pytest.raises(ValueError, match=r"params: a batch of 5000 .*run_batch"):
        ts.simulate([ts.StarParams()] * 5000, 0.001)
    assert not any(key[2] == 8192 for key in runtime.Runtime.current().engines)
