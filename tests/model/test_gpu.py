"""The GPU path: its instance-minor field layout (checked on the CPU, where it must give the same
bits as the CPU's own layout) and, where a GPU is present, GPU results against the CPU's."""

import numpy as np
import pytest

import taichi_star as ts
from taichi_star.engine import BatchEngine
from taichi_star.integrators import INTEGRATORS
from taichi_star.model import build_model
from taichi_star.runtime import Runtime, available_archs, prepare_engine
from taichi_star.sensitivities import SUMMARY_OUTPUTS

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


@pytest.mark.skipif("gpu" not in available_archs(), reason="no GPU on this machine")
def test_gpu_sensitivities_match_cpu(record_property):
    """The sensitivities of the five paper gaits over the pulse and into the coast (0.4 s) on
    the GPU and the CPU. Each derivative is a linear solve with the Jacobian at the converged
    state, whose GPU and CPU values differ by the states' Newton-tolerance difference (≤ 1e-9
    relative, above); a replica pair's residual difference divided by its offset (1e-4 of the
    value) amplifies round-off to about 1e-12. 1e-6 relative: measured 7.6e-9 on an H100. The
    largest difference, relative to its output's scale, is recorded as a property
    (`--junitxml` writes it)."""
    directions = ("alpha", "drag_perpendicular", "actuator_gains[0]")
    params = [ts.StarParams(gait=gait) for gait in PAPER_GAITS]
    cpu, gpu = (ts.simulate(params, 0.4, arch=arch, sensitivities=directions)
                for arch in ("cpu", "gpu"))
    largest = 0.0
    for output in SUMMARY_OUTPUTS:
        expected, actual = (np.stack([r.sensitivity(output, name) for name in directions])
                            for r in (cpu, gpu))
        finite = np.isfinite(expected)  # the steady-cycle outputs need a whole cycle
        np.testing.assert_array_equal(np.isfinite(actual), finite, err_msg=output)
        if finite.any():
            # the output's largest derivative sets the scale: a direction that a symmetric
            # gait does not turn (d heading / d alpha) is round-off about zero
            scale = np.abs(expected[finite]).max()
            largest = max(largest, np.abs(actual[finite] - expected[finite]).max() / scale)
            np.testing.assert_allclose(actual[finite], expected[finite], rtol=1e-6,
                                       atol=1e-6 * scale, err_msg=output)
    record_property("largest_relative_difference", f"{largest:.3e}")
    assert np.nanmax(np.abs(cpu.sensitivities.to_numpy())) > 0  # the runs did respond


@pytest.mark.skipif("gpu" not in available_archs(), reason="no GPU on this machine")
def test_gpu_lagged_jacobian_matches_cpu(record_property):
    """The opt-in lagged Jacobian on the GPU against the CPU's, the five paper gaits over the
    pulse and into the coast (0.4 s). Where both devices take the same reuse decisions the
    difference is round-off, as for Newton's (≤ 1e-9 relative, above); a decision that flips
    on round-off still converges both to 1e-10 m a step, and two such solves differ by what
    the lagged and Newton's Jacobians differ by on the CPU: 4.0e-7 of the shape's scale
    (measured), so 1e-6 holds for any two solves to the tolerance. The largest relative
    difference of the shapes is recorded as a property (`--junitxml` writes it)."""
    params = [ts.StarParams(gait=gait) for gait in PAPER_GAITS]
    solver = ts.SolverConfig(jacobian="lagged")
    cpu, gpu = (ts.simulate(params, 0.4, solver=solver, arch=arch, record_interval_s=0.1,
                            record_shapes=True) for arch in ("cpu", "gpu"))
    assert (gpu.summary["status"] == "ok").all()
    scale = np.abs(cpu.shapes[-1]).max()
    largest = np.abs(gpu.shapes - cpu.shapes).max() / scale
    record_property("largest_relative_difference", f"{largest:.3e}")
    assert largest <= 1e-6
    # the factorisations were reused: fewer than one a Newton update
    assert (gpu.summary["factorisations_mean"] < gpu.summary["newton_iterations_mean"]).all()
