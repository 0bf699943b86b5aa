"""Determinism: the same inputs give bitwise-identical summaries, run to run, whatever the
instance's position in the batch and the batch size (on the CPU, and on a GPU with --arch gpu)."""

import numpy as np
import pandas as pd

import taichi_star as ts
from taichi_star import runtime

PARAMS = [ts.StarParams(gait="A1+A2", alpha=0.5), ts.StarParams(gait="A1+A3+A5"),
          ts.StarParams(gait="A2", youngs_modulus=7e6), ts.StarParams(gait="A1+A4", period=0.4)]
PADDED = PARAMS + [ts.StarParams(gait="A5")] * 95 + [ts.StarParams(gait="A5", damping_time=1e-3)]
DURATION = 0.08


def _summary(params, arch):
    return ts.simulate(params, DURATION, arch=arch).summary


def test_run_to_run_bitwise(arch):
    pd.testing.assert_frame_equal(_summary(PARAMS, arch), _summary(PARAMS, arch), check_exact=True)


def test_batch_position_and_size_do_not_matter(arch):
    reference = _summary(PARAMS, arch)
    shuffled = [PARAMS[i] for i in (2, 0, 3, 1)]
    reordered = _summary(shuffled, arch).iloc[[1, 3, 0, 2]].reset_index(drop=True)
    pd.testing.assert_frame_equal(reordered, reference, check_exact=True)
    # a 100-instance batch lands in a larger engine (capacity 128), and its damped instance
    # compiles the damping term in: same bits for the same rows
    padded = _summary(PADDED, arch).iloc[:4].reset_index(drop=True)
    pd.testing.assert_frame_equal(padded, reference, check_exact=True)


def test_a_batch_streamed_in_chunks_equals_one_engine_bitwise(monkeypatch):
    """A batch over the CPU engine budget runs as equal chunks through one engine: with a budget
    of one byte the 100 instances run as two chunks of 50 (the smallest engine holds 64), the
    second one alone compiling the damping term in; summary, trajectory (instances numbered in
    the whole batch) and shapes are those of one engine, bit for bit."""
    def run():
        return ts.simulate(PADDED, DURATION, record_interval_s=0.02, record_shapes=True)

    whole = run()
    monkeypatch.setattr(runtime, "CPU_ENGINE_BUDGET_BYTES", 1)
    assert runtime.stream_chunk_size(PADDED, "f64", "cpu") == 50
    streamed = run()
    pd.testing.assert_frame_equal(streamed.summary, whole.summary, check_exact=True)
    pd.testing.assert_frame_equal(streamed.trajectory, whole.trajectory, check_exact=True)
    np.testing.assert_array_equal(streamed.shapes, whole.shapes)
