"""`actuation_origin`: a fired arc's natural curvature measured from the profile (Eq. 5 as
written, the default) or from the rest arc's own discrete curvature ("rest"). The rest arc is a
circle of curvature K̄(0) whose discrete curvature exceeds K̄(0) at second order in the edge;
"rest" removes the step that difference makes at the first firing."""

import numpy as np
import pytest

from taichi_star import SolverConfig, StarParams, simulate
from taichi_star.geometry import build_topology
from taichi_star.reference import ReferenceSimulator
from taichi_star.sensitivity_check import check_sensitivities

REST = dict(actuation_origin="rest")
OFF = dict(actuator_gains=(0.0,) * 8)
"""Every actuator at gain 0: fired, it follows K̄(0) (or nothing, from its rest)."""


def test_the_presets_keep_the_papers_equation():
    for name in ("paper", "accurate", "identified"):
        assert StarParams.preset(name).actuation_origin == "profile"
    with pytest.raises(ValueError, match="actuation_origin must be one of"):
        StarParams(actuation_origin="tip")


def test_the_rest_arcs_discrete_curvature_exceeds_the_profiles_start_at_second_order():
    """The premise: |κ⁰_rest| − K̄(0) on an arc, at n_arc 12, 24, 48, falls by 4 per halving
    (within 1 %: the next term of the expansion, (Δθ)⁴, is 1e-4 of it here)."""
    excess = []
    for n_arc in (12, 24, 48):
        params = StarParams(n_arc=n_arc)
        topology = build_topology(params)
        arc = topology.triplet_actuator >= 0
        kappa = np.abs(topology.rest_curvature[arc])
        # every interior triplet of every arc: the same circle, the same discrete curvature
        assert np.ptp(kappa) < 1e-9 * kappa.max()
        excess.append(kappa.max() - params.actuator_profile.rest_curvature)
    assert excess[0] > 0.5  # 1/m: 0.95 at n_arc 12
    assert excess[0] / excess[1] == pytest.approx(4.0, rel=1e-2)
    assert excess[1] / excess[2] == pytest.approx(4.0, rel=1e-2)


def test_an_actuator_at_gain_zero_moves_nothing_measured_from_rest(taichi_cpu):
    """Fired at gain 0, an actuator measured from rest keeps its arc at rest: the run is the
    unfired robot's bit for bit. Measured from the profile it steps to K̄(0) and the robot
    moves: the engine's motion is the NumPy reference's (on a coarse mesh, whose rest arcs are
    2.14 1/m above K̄(0)), and far above round-off."""
    coarse = dict(n_arc=6, n_limb=2)
    batch = [StarParams(gait="none", **coarse), StarParams(gait="A1", **OFF, **REST, **coarse),
             StarParams(gait="A1", **OFF, **coarse)]
    solver = SolverConfig(newton_tol=1e-12)
    steps = 40
    result = simulate(batch, steps * solver.dt, solver, record_interval_s=steps * solver.dt,
                      record_shapes=True)
    np.testing.assert_array_equal(result.shapes[:, 1], result.shapes[:, 0])
    reference = ReferenceSimulator(batch[2], solver).run(steps)
    motion = np.abs(reference[-1] - reference[0]).max()
    # both sides converge Newton to 1e-12 m and agree to round-off: measured 6e-17 m against a
    # motion of 3.3e-4 m (1.8e-13 of it); 1e-10 leaves room for another machine's rounding
    assert np.abs(result.shapes[-1, 2] - reference[-1]).max() <= 1e-10 * motion
    assert motion > 1e-5  # m: the step moves the arc (3.3e-4 m), not the solver's noise


def test_the_natural_curvature_from_rest_follows_the_profiles_change():
    """The NumPy reference: during a delay (K̄_k = K̄(0)) an arc measured from rest holds its
    rest κ⁰ exactly, the profile's arc K̄(0); later both differ from their own start by the
    same ±(K̄_k(τ) − K̄(0))."""
    delays = (0.05,) + (0.0,) * 7
    rest = ReferenceSimulator(StarParams(gait="A1", actuator_delays=delays, **REST))
    profile = ReferenceSimulator(StarParams(gait="A1", actuator_delays=delays))
    topology = rest.topology
    arc = topology.triplet_actuator == 0
    start = rest.params.actuator_profile.rest_curvature
    waiting = 0.03  # s, inside A1's 50-ms delay
    np.testing.assert_array_equal(rest.natural_curvature(waiting)[arc],
                                  topology.rest_curvature[arc])
    np.testing.assert_array_equal(np.abs(profile.natural_curvature(waiting)[arc]), start)
    bending = 0.1  # s: 50 ms into the profile
    change_rest = rest.natural_curvature(bending)[arc] - topology.rest_curvature[arc]
    change_profile = np.abs(profile.natural_curvature(bending)[arc]) - start
    assert np.abs(change_profile).min() > 10.0  # 1/m: well into the pulse
    # the same change, of the arc's sign (the rest arcs bend one way: κ⁰ < 0)
    np.testing.assert_allclose(-change_rest, change_profile, rtol=1e-12)


def test_the_sensitivities_measured_from_rest_equal_finite_differences(taichi_cpu):
    # 1e-5: the sensitivities' target (tests/model/test_sensitivities.py), a gain and α
    table = check_sensitivities([StarParams(gait="A1+A2", **REST)], 0.1,
                                SolverConfig(newton_tol=1e-12),
                                ("alpha", "actuator_gains[1]"))
    assert len(table) and (table["relative_error"] <= 1e-5).all(), table
