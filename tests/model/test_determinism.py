"""Determinism: the same inputs give bitwise-identical states and summaries, from one process to
another, whatever the instance's position in the batch and the batch size (on the CPU, and on a
GPU with --arch gpu)."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd

import taichi_star as ts
from taichi_star import runtime
from taichi_star.runtime import prepare_engine

PARAMS = [ts.StarParams(gait="A1+A2", alpha=0.5), ts.StarParams(gait="A1+A3+A5"),
          ts.StarParams(gait="A2", youngs_modulus=7e6), ts.StarParams(gait="A1+A4", period=0.4)]
PADDED = PARAMS + [ts.StarParams(gait="A5")] * 95 + [ts.StarParams(gait="A5", damping_time=1e-3)]
DURATION = 0.08
REPO = Path(__file__).resolve().parents[2]


def _summary(params, arch):
    return ts.simulate(params, DURATION, arch=arch).summary


def write_run(path, arch):
    """Write the summary of PARAMS run for DURATION (`simulate`: numbers and texts) and the
    engine's whole state (every device field) after the same run to `path` (.npz)."""
    summary = _summary(PARAMS, arch).drop(columns="actuator_profile")
    engine = prepare_engine(PARAMS, ts.SolverConfig(), arch)
    engine.advance(round(DURATION / ts.SolverConfig().dt))
    np.savez(path, **{f"state.{name}": values for name, values in engine.save_state().items()},
             **{f"summary.{name}": summary[name].to_numpy() for name in summary.columns})


def test_another_process_gives_the_same_bits(arch, tmp_path):
    """The same run in a fresh process (its own Taichi runtime, its own compilation) and in
    this one: every state field and every summary column bitwise equal."""
    child = tmp_path / "child.npz"
    subprocess.run([sys.executable, __file__, str(child), arch], check=True, cwd=REPO,
                   env=dict(os.environ, PYTHONPATH=str(REPO)), timeout=600)
    here = tmp_path / "here.npz"
    write_run(here, arch)
    with np.load(child, allow_pickle=True) as theirs, np.load(here, allow_pickle=True) as ours:
        assert sorted(theirs.files) == sorted(ours.files)
        assert any(name.startswith("state.") for name in ours.files)
        for name in ours.files:
            if ours[name].dtype == object:  # texts
                assert ours[name].tolist() == theirs[name].tolist(), name
            else:
                assert ours[name].dtype == theirs[name].dtype, name
                assert ours[name].tobytes() == theirs[name].tobytes(), name


def test_batch_position_and_size_do_not_matter(arch):
    reference = _summary(PARAMS, arch)
    shuffled = [PARAMS[i] for i in (2, 0, 3, 1)]
    reordered = _summary(shuffled, arch).iloc[[1, 3, 0, 2]].reset_index(drop=True)
    pd.testing.assert_frame_equal(reordered, reference, check_exact=True)
    # a 100-instance batch lands in a larger engine (capacity 128), and its damped instance
    # compiles the damping term in: same bits for the same rows
    padded = _summary(PADDED, arch).iloc[:4].reset_index(drop=True)
    pd.testing.assert_frame_equal(padded, reference, check_exact=True)


def test_an_instance_keeps_its_bits_beside_any_options_of_another():
    """Another instance's options compile terms and switches into the engine (here the jet
    spread over the corners, which couples more nodes, damping and the entrained water): the
    instance's own rows stay bitwise those it has alone. Until the elimination order was
    fixed per topology, the spread's own order moved them by ~1e-13."""
    robot = ts.StarParams(gait="A1+A3")
    other = ts.StarParams(gait="A2", jet_application="spread", damping_time=1e-3,
                          wake_coupling=1.0, joint_stiffness="series", joint_radius=0.022)
    alone = ts.simulate([robot], DURATION).summary
    beside = ts.simulate([other, robot], DURATION).summary.iloc[[1]].reset_index(drop=True)
    pd.testing.assert_frame_equal(beside, alone, check_exact=True)


def test_a_batch_streamed_in_chunks_equals_one_engine_bitwise(monkeypatch, simulated_chunks):
    """A batch over the CPU engine budget runs as equal chunks through one engine: with a budget
    of one byte the 100 instances run as two chunks of 50 (the smallest engine holds 64), the
    second one alone compiling the damping term in; summary, trajectory (instances numbered in
    the whole batch) and shapes are those of one engine, bit for bit."""
    def run():
        return ts.simulate(PADDED, DURATION, record_interval_s=0.02, record_shapes=True)

    whole = run()
    monkeypatch.setattr(runtime, "CPU_ENGINE_BUDGET_BYTES", 1)
    assert runtime.stream_chunk_size(PADDED, "f64", "cpu") == 50
    simulated_chunks.clear()  # the whole run's
    streamed = run()
    assert simulated_chunks == [PADDED[:50], PADDED[50:]]
    assert [[p.damping_time > 0 for p in params].count(True)
            for params in simulated_chunks] == [0, 1]
    pd.testing.assert_frame_equal(streamed.summary, whole.summary, check_exact=True)
    pd.testing.assert_frame_equal(streamed.trajectory, whole.trajectory, check_exact=True)
    np.testing.assert_array_equal(streamed.shapes, whole.shapes)
    # the chunks' timings are summed: every instance's steps counted once
    assert streamed.timing.robot_steps == whole.timing.robot_steps == whole.summary["steps"].sum()


if __name__ == "__main__":  # the other process of test_another_process_gives_the_same_bits
    from taichi_star.runtime import KERNEL_OPTIMISATION_ENV
    os.environ.setdefault(KERNEL_OPTIMISATION_ENV, "0")  # as the test session (conftest)
    write_run(sys.argv[1], sys.argv[2])
