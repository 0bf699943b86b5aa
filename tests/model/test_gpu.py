"""The GPU path: its instance-minor field layout (checked on the CPU, where it must give the same
bits as the CPU's own layout) and, where a GPU is present, GPU results against the CPU's."""

import numpy as np
import pytest

import taichi_star as ts
from taichi_star.engine import BatchEngine
from taichi_star.integrators import INTEGRATORS
from taichi_star.model import build_model
from taichi_star.runtime import Runtime, available_archs, prepare_engine

PAPER_GAITS = ["A1", "A1+A2", "A1+A3", "A1+A4", "A1+A3+A5"]


def test_instance_minor_layout_gives_the_same_bits_as_instance_major(taichi_cpu):
    """The layout changes addresses only, never the arithmetic: 60 steps (through the heating
    pulse, Newton at work) of a mixed batch in both layouts are bitwise equal."""
    params = [ts.StarParams(gait=gait, alpha=1.0 + 0.1 * index)
              for index, gait in enumerate(PAPER_GAITS)]
    solver = ts.SolverConfig()
    major = prepare_engine(params, solver)
    model = build_model(params)
    minor = BatchEngine(model, major.capacity, INTEGRATORS[solver.integrator](),
                        loop_spread=Runtime.current().loop_spread(major.capacity),
                        instance_minor=True)
    minor.load(model, solver)
    for engine in (major, minor):
        engine.advance(60)
    for name, field in major.state.save().items():
        np.testing.assert_array_equal(minor.state.save()[name], field, err_msg=name)
    assert np.abs(major.state.positions.to_numpy()[:5]
                  - model.rest_positions).max() > 1e-4  # the robots did move


@pytest.mark.skipif("gpu" not in available_archs(), reason="no GPU on this machine")
@pytest.mark.parametrize("preset", ["paper", "accurate"])
def test_gpu_matches_cpu(preset):
    """The five paper gaits over the heating pulse and into the coast (0.4 s) on the GPU and
    the CPU, f64: the same algorithm in a different compiler, so the bits may differ (FMA
    contraction, libm), but Newton converges both to 1e-10 m and the difference must stay at
    round-off level: ≤ 1e-9 relative on displacements and speeds."""
    params = [ts.StarParams.preset(preset, gait=gait) for gait in PAPER_GAITS]
    solver = ts.SolverConfig.preset(preset)
    cpu, gpu = (ts.simulate(params, 0.4, solver=solver, arch=arch, record_interval_s=0.1,
                            record_shapes=True) for arch in ("cpu", "gpu"))
    assert (gpu.summary["status"] == "ok").all()
    scale = np.abs(cpu.shapes[-1]).max()
    assert np.abs(gpu.shapes - cpu.shapes).max() <= 1e-9 * scale
    for column in ("displacement_x_mm", "displacement_y_mm", "speed_mm_s"):
        np.testing.assert_allclose(gpu.summary[column], cpu.summary[column], rtol=1e-9,
                                   atol=1e-9 * np.abs(cpu.summary[column]).max(), err_msg=column)
