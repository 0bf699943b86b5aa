"""The entrained water (`physics.wake`): off by default and compiled out, validated, per
instance; the NumPy reference's own water against an exact invariant and its analytic limit;
its sensitivities against finite differences. Elsewhere: the term assembled alone
(tests/unit/test_assembly.py) and the engine against the reference with it on
(tests/model/test_engine.py, `test_engine_matches_reference_with_damping_joints_ends_closure_and_extensions`).
"""

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
from taichi_star.model import build_model
from taichi_star.reference import ReferenceSimulator
from taichi_star.sensitivity_check import check_sensitivities

COARSE = dict(n_arc=6, n_limb=2)
"""A coarse mesh (65 nodes): the water acts on the hub whatever the mesh, and the reference's
cost grows with it."""


def test_the_wake_is_off_by_default_and_compiled_out():
    for preset in ("paper", "accurate", "identified"):
        assert ts.StarParams.preset(preset).wake_coupling == 0.0
    names = [cls.name for cls, _ in build_model([ts.StarParams.preset("paper")]).terms_used]
    assert "wake" not in names
    names = [cls.name for cls, _ in build_model(
        [ts.StarParams(), ts.StarParams(wake_coupling=1.0)]).terms_used]
    assert "wake" in names


@pytest.mark.parametrize("changes,message", [
    ({"wake_coupling": -1e-9}, r"wake_coupling must be a real number in \[0, 1000\]"),
    ({"wake_coupling": 1000.5}, r"wake_coupling must be a real number in \[0, 1000\]"),
    ({"wake_time": 0.0}, r"wake_time must be a real number in \[1e-09, 1000\]"),
    ({"wake_time": 1000.5}, r"wake_time must be a real number in \[1e-09, 1000\]"),
    # a subnormal τ_w had been accepted, and 1/τ_w = inf made every such run non_finite
    ({"wake_time": 5e-324}, r"wake_time must be a real number in \[1e-09, 1000\]"),
    ({"wake_time": 0.999e-9}, r"wake_time must be a real number in \[1e-09, 1000\]"),
    ({"wake_time": float("nan")}, r"wake_time must be a real number"),
])
def test_wake_fields_refuse_values_out_of_range(changes, message):
    with pytest.raises(ValueError, match=message):
        ts.StarParams(**changes)


def test_wake_fields_accept_their_bounds():
    params = ts.StarParams(wake_coupling=1000.0, wake_time=1e-9)
    assert (params.wake_coupling, params.wake_time) == (1000.0, 1e-9)
    assert ts.StarParams(wake_coupling=0.0, wake_time=1000.0).wake_time == 1000.0


def test_an_instance_with_water_leaves_its_neighbours_bitwise_unchanged():
    """One thread per instance, its water in its own fields: the instances without it run as
    they would alone, to the bit (their whole summary rows: motion, steps, Newton counts); the
    water slows the robot's swimming. The water starts at rest and, through the 0.2-s stroke
    from rest, lags the hub, so its force on the hub opposes the motion: a shorter displacement
    (measured 0.32 against 0.42 mm, 23 % shorter; 10 % leaves room, and a water that did not act
    would be bitwise the plain run). It pulls along the hub's own velocity, so it cannot turn
    A1+A2's travel off the gait's mirror axis, 22.5°, which both keep to round-off."""
    plain = [ts.StarParams(gait="A1+A2"), ts.StarParams(gait="A1+A3")]
    watered = plain[:1] + [plain[0].replace(wake_coupling=20.0, wake_time=0.05)] + plain[1:]
    alone = ts.simulate(plain, 0.2).summary
    together = ts.simulate(watered, 0.2).summary
    pd.testing.assert_frame_equal(alone.loc[[0, 1]].reset_index(drop=True),
                                  together.loc[[0, 2]].reset_index(drop=True),
                                  check_exact=True)
    length = np.hypot(together.displacement_x_mm, together.displacement_y_mm)
    assert length[1] < 0.9 * length[0]
    np.testing.assert_allclose(together.travel_direction_deg[[0, 1]], 22.5, rtol=0, atol=1e-9)


@pytest.mark.parametrize("integrator", ["euler", "bdf2"])
def test_the_robot_and_its_water_conserve_their_momentum(integrator):
    """With every other fluid force off (no drag, no jet, no added mass) and nothing fired, a
    robot launched at v0 hands momentum to the water at rest: the robot's momentum plus the
    water's, Σ m_i·v_i + m_w·u, stays M·v0 at every step (both integrators apply the same
    linear rate to both momentum balances, so the sum is exact up to what Newton leaves
    unsolved: measured ≤ 3e-12 of it over 300 steps; 1e-10 leaves room, while a hub that did
    not feel the water's reaction would miss by the water's whole share, ~50 %), and after
    many exchange times both move at the common velocity M·v0/(M + m_w)."""
    params = ts.StarParams(gait="none", drag_parallel=0.0, drag_perpendicular=0.0,
                           cylinder_drag=0.0, alpha=0.0, added_mass_coeff=0.0,
                           wake_coupling=300.0, wake_time=0.01, **COARSE)
    solver = ts.SolverConfig(integrator=integrator, dt=1e-3, newton_tol=1e-13)
    sim = ReferenceSimulator(params, solver)
    mass, water_mass = sim.mass.sum(), params.wake_coupling * params.wake_time
    launch = np.array([1e-3, -4e-4])
    q = sim.topology.rest_positions.copy()
    v = np.tile(launch, (len(q), 1))
    water, previous = (np.zeros(2), np.zeros(2)), None
    momenta = []
    # m_w = 3 kg/m against M = 3.25 kg/m: the water takes about half; the gap between their
    # velocities closes at c_w·(1/m_w + 1/M) ≈ 190 /s, 0.3 s = 57 of its decay times
    for k in range(300):
        q_new, v_new, _, u_new = sim.step(q, v, k * solver.dt, solver.dt, previous, water)
        previous, q, v, water = (q, v), q_new, v_new, (u_new, water[0])
        momenta.append(sim.mass @ v + water_mass * u_new)
    np.testing.assert_allclose(np.array(momenta), np.tile(mass * launch, (300, 1)),
                               rtol=0, atol=1e-10 * np.abs(mass * launch).max())
    common = mass * launch / (mass + water_mass)
    assert np.abs(water[0] - launch).max() > 0.1 * np.abs(launch).max()  # the water took a share
    # the gap has decayed by far more than 1e-3; what is left is the robot's own elastic
    # ringing, which nothing here damps but the integrator (BDF2 little): the hub's velocity
    # rings about the robot's mean, measured 3e-4 of v0. A water of the wrong mass misses by O(1).
    np.testing.assert_allclose(water[0], common, rtol=0, atol=1e-3 * np.abs(launch).max())
    np.testing.assert_allclose(sim.mass @ v / mass, common, rtol=0,
                               atol=1e-3 * np.abs(launch).max())


def test_a_step_with_water_needs_the_water():
    sim = ReferenceSimulator(ts.StarParams(wake_coupling=1.0, **COARSE))
    rest = sim.topology.rest_positions
    with pytest.raises(ValueError, match="wake_coupling > 0 needs water"):
        sim.step(rest, np.zeros_like(rest), 0.0)


WATERED = (ts.StarParams(gait="A1+A2", wake_coupling=30.0, wake_time=0.05),)
"""An A1+A2 robot with 1.5 kg/m of water exchanging momentum with it over 50 ms: over the 0.1-s
checks the water takes 30 % off the displacement, so the differences are well conditioned (with
a water a sixth as heavy, d/dτ_w moved the displacement by only ~1e-11 m per difference step
and the differences' round-off reached 2e-5)."""
TIGHT = dict(newton_tol=1e-12)


def test_wake_sensitivities_equal_finite_differences(matches_differences):
    """d(displacement)/d(c_w, τ_w, α) through the water: the replicas carry their own water,
    committed with each accepted step, so its tangent follows the implicit function theorem like
    the positions'. 2e-8: 10 × the relative error measured here (≤ 1.9e-9 over the three
    directions; the extrapolated differences' own spread reaches 4.5e-9, so that error is
    theirs), far inside the sensitivities' general target 1e-5: a tangent off by more than
    ~1e-8 of the total fails."""
    table = check_sensitivities(WATERED, 0.1, ts.SolverConfig(**TIGHT),
                                ("wake_coupling", "wake_time", "alpha"))
    matches_differences(table, tolerance=2e-8)


@pytest.mark.slow      # suite time; the rules it rests on are unit-tested in the default tier
@pytest.mark.parametrize("integrator", ["euler", "bdf2"])
def test_a_short_exchange_times_sensitivity_is_not_lost_to_rounding(matches_differences,
                                                                     integrator):
    """τ_w of 1e-9, 1e-6 and 1e-3 s with ε = 1e-4·τ_w moved the replicas by a few roundings of
    their positions or less: d/dτ_w came out 0 at 1e-9 s, 4.7e-3 (Euler) and 1.6e-2 (BDF2) off
    at 1e-6 s, 2e-5 (BDF2) at 1e-3 s (an audit, 2026-12). Now ε ≥ 1e-6 s, the replicas on both
    sides of a tiny τ_w (expanded about their instance's: `Wake.exchange_share`), and the
    Taylor test moves τ_w by 30 such steps at least. Measured at most 2.2e-6 (BDF2 at 1e-9 s;
    the differences spread 2.4e-8), the Taylor ratios 3.99 to 4.01: 1e-5, the target. Not
    here: c_w at τ_w ≪ h, whose derivative (~1e-10 mm per Pa·s at 1e-9 s) is below the
    positions' rounding, reported as 0 (the differences spread by 10 % and more)."""
    water = [WATERED[0].replace(wake_time=exchange_time) for exchange_time in (1e-9, 1e-6)]
    solver = ts.SolverConfig(integrator=integrator, **TIGHT)
    matches_differences(check_sensitivities(water, 0.1, solver, ("wake_time",)), 1e-5)
    matches_differences(check_sensitivities([WATERED[0].replace(wake_time=1e-3)], 0.1, solver,
                                            ("wake_time", "wake_coupling")), 1e-5)


@pytest.mark.slow
def test_wake_sensitivities_with_bdf2_and_adaptive_steps(matches_differences):
    """BDF2 (the water's rate from its last two values) with adaptive steps held at 1 ms, so
    that every run takes the same 100 steps (the frozen step sequence the differences see).
    2e-6: about 10 × the relative error measured here (1.5e-7 for τ_w, 8.6e-9 for c_w)."""
    adaptive = dict(integrator="bdf2", adaptive=True, error_tol=1e-3, dt_max=1e-3, **TIGHT)
    table = check_sensitivities(WATERED, 0.1, ts.SolverConfig(**adaptive),
                                ("wake_coupling", "wake_time"))
    assert (ts.simulate(list(WATERED), 0.1, ts.SolverConfig(**adaptive)).summary["steps"]
            == 100).all()
    matches_differences(table, tolerance=2e-6)


def test_steps_redone_in_substeps_restore_the_water(matches_differences):
    """20-ms steps with at most 4 Newton iterations: the pulse's steps fail and are redone in
    substeps from the saved start, the water with the positions (a water advanced by a failed
    attempt's substeps would be advanced twice). Held to the sensitivities' finite differences,
    whose moved runs redo the same steps, and to the same run with 5-ms steps, which need no
    substeps: the two differ by the time step's own error only (measured 3e-3 relative; a water
    advanced twice over the redone steps moves the result by ~5e-2). The differences within
    5e-8: about 10 × the relative error measured here (5.3e-9)."""
    solver = ts.SolverConfig(dt=0.02, max_newton=4, **TIGHT)
    result = ts.simulate(list(WATERED), 0.2, solver)
    assert result.summary["substep_retries"].iloc[0] > 0
    matches_differences(check_sensitivities(WATERED, 0.2, solver, ("wake_coupling",)),
                        tolerance=5e-8)


def test_a_simulator_saves_loads_and_resets_the_water():
    """The water is state: a snapshot holds it (a fresh Simulator loaded at 0.1 s goes on to
    the same bits as one run of 0.3 s; with the water left at rest it would not), and a reset
    puts it back at rest with the robot (instance 0 run again from t = 0 ends as before)."""
    params = [WATERED[0], WATERED[0].replace(gait="A1+A3")]
    # one Simulator alive at a time (its results kept, then dropped): the next one takes over
    # its compiled engine instead of compiling another (the suite's time); each starts at rest
    whole = ts.Simulator(params)
    whole.advance(0.3)
    whole_shapes = whole.shapes()
    del whole
    sim = ts.Simulator(params)
    sim.advance(0.1)
    snapshot = sim.save()
    sim.advance(0.2)
    np.testing.assert_array_equal(sim.shapes(), whole_shapes)
    sim.reset([0])
    sim.advance(0.3)
    np.testing.assert_array_equal(sim.shapes()[0], whole_shapes[0])
    del sim
    fresh = ts.Simulator(params)
    fresh.load(snapshot)
    fresh.advance(0.2)
    np.testing.assert_array_equal(fresh.shapes(), whole_shapes)
