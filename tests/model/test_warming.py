"""The stroke's warming (`stroke_warming`, `cooling_time`; `physics.bending`): off by default
without a bit changed, the heat each firing leaves against its closed form, commanded
firings against the periodic gait to the bit, a saved Simulator resuming its heat, and the
sensitivities of both fields against finite differences. Elsewhere: the engine against the
NumPy reference with it on (tests/model/test_engine.py,
`test_engine_matches_reference_with_damping_joints_ends_closure_and_extensions`)."""

import math

import numpy as np

import taichi_star as ts
from taichi_star.sensitivity_check import check_sensitivities

PERIOD = 0.2
"""Short cycles (the profile's heating ends at 0.163 s): three firings within 0.5 s."""
COARSE = dict(n_arc=6, n_limb=2, period=PERIOD)
"""A coarse mesh (65 nodes): the warming scales the actuators' stroke whatever the mesh."""
WARM = ts.StarParams(gait="A1+A2", stroke_warming=0.8, cooling_time=0.3, **COARSE)
SOLVER = ts.SolverConfig(dt=2e-3)


def heat_after(firings: int, cooling_time: float, period: float = PERIOD) -> float:
    """θ of the `firings`-th firing of a periodic gait, from its closed form: the sum of
    exp(−(k·T)/τ_c) over the firings before it, k = 1 .. firings − 1."""
    return sum(math.exp(-k * period / cooling_time) for k in range(1, firings))


def test_warming_is_off_in_every_preset():
    """(The fields' ranges, both ends and beyond, are checked with every declared range:
    tests/unit/test_params.py, `test_every_declared_range_is_the_validated_range_at_both_ends`.)"""
    for preset in ("paper", "accurate", "identified"):
        assert ts.StarParams.preset(preset).stroke_warming == 0.0


def test_without_warming_the_cooling_time_changes_no_bit_and_with_it_the_stroke_grows():
    """At w = 0 the heat is counted but never read: any τ_c gives the run's bits. With w = 0.8
    the second and third pulses (θ = 0.51, 0.78) bend the arcs further, and the robot swims
    further than without."""
    cold = WARM.replace(stroke_warming=0.0)
    runs = ts.simulate([cold, cold.replace(cooling_time=3.0), WARM], 2.5 * PERIOD, SOLVER,
                       record_interval_s=2.5 * PERIOD, record_shapes=True)
    np.testing.assert_array_equal(runs.shapes[-1][0], runs.shapes[-1][1])
    moved = runs.summary["speed_mm_s"].to_numpy()
    # 1.05: the warmed pulses are 1.41 and 1.62 times the first; the speed over the 2.5
    # periods measured 1.3 times the cold robot's
    assert moved[2] > 1.05 * moved[0], moved


def test_each_firing_leaves_the_heat_of_its_closed_form(taichi_cpu):
    """θ of the first firing 0, then θ' = (θ + 1)·exp(−T/τ_c): after the firings at 0, T and
    2T the actuators the gait fires hold the sum of exp(−kT/τ_c) over k = 1, 2, and the one
    before it for the times before 2T; A3, never fired, no heat."""
    sim = ts.Simulator([WARM.replace(gait="none")], SOLVER)
    sim.fire(["A1+A2"])
    for k in (1, 2):
        sim.fire(["A1+A2"], at_s=k * PERIOD)
        sim.advance(PERIOD)
    sim.advance(0.01)  # the heat is counted at the start of the step after the firing
    bending = sim.engine.term("bending")
    heat = bending.fire_heat.to_numpy()[0]
    previous = bending.previous_fire_heat.to_numpy()[0]
    # 1e-15: the recursion's two roundings against the sum's
    np.testing.assert_allclose(heat[:2], heat_after(3, WARM.cooling_time), rtol=1e-15)
    np.testing.assert_allclose(previous[:2], heat_after(2, WARM.cooling_time), rtol=1e-15)
    assert heat[2:].tolist() == [0.0] * 6


def test_commanded_firings_warm_the_stroke_as_the_periodic_gait_does():
    """The heat counts firings however they come: the gait's schedule given as commands gives
    the bits of `simulate` with the warming on (as without it, tests/model/test_simulator.py)."""
    reference = ts.simulate([WARM], 3 * PERIOD, SOLVER, record_interval_s=3 * PERIOD,
                            record_shapes=True)
    sim = ts.Simulator([WARM.replace(gait="none")], SOLVER)
    sim.fire(["A1+A2"])
    for k in (1, 2, 3):
        sim.fire(["A1+A2"], at_s=k * PERIOD)
        sim.advance(PERIOD)
    np.testing.assert_array_equal(sim.shapes(), reference.shapes[-1])


def test_a_saved_simulator_resumes_with_its_heat(tmp_path):
    """The heat is part of the saved state: advancing on from a loaded snapshot gives the bits
    of advancing on without saving (the third pulse's stroke depends on the first two's)."""
    sim = ts.Simulator([WARM.replace(gait="none")], SOLVER)
    sim.fire(["A1+A2"])
    sim.fire(["A1+A2"], at_s=PERIOD)
    sim.advance(1.5 * PERIOD)
    snapshot = sim.save(tmp_path / "warm.npz")
    sim.fire(["A1+A2"], at_s=2 * PERIOD)
    sim.advance(PERIOD)
    straight = sim.shapes()
    sim.load(snapshot)
    sim.fire(["A1+A2"], at_s=2 * PERIOD)
    sim.advance(PERIOD)
    np.testing.assert_array_equal(sim.shapes(), straight)


def test_warming_sensitivities_equal_finite_differences(taichi_cpu):
    """Both fields through the implicit steps and the heat's recursion (each replica counts
    the firings with its own τ_c), over the first two firings and 0.1 s of the second pulse."""
    table = check_sensitivities([WARM], 0.3, ts.SolverConfig(dt=2e-3, newton_tol=1e-12),
                                ("stroke_warming", "cooling_time"))
    # measured 1.6e-9 (w) and 2.4e-9 (τ_c): 2.5e-8, 10× (the docs' target, 1e-5, would pass
    # a sensitivity off by a few parts in a million)
    assert (table["relative_error"] <= 2.5e-8).all(), table
    assert table["taylor_ratio"].between(3.0, 5.0).all(), table
